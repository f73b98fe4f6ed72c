"""The figures of a run's last evaluations (metaopt show --recent): failed evaluations, metrics
some evaluations lack, 0/1 metrics."""

from __future__ import annotations

from metaopt.reporting.recent import recent_figures
from tests.conftest import evaluation_record


def test_failures_and_partial_metrics_are_counted_not_mixed_in():
    window = [
        evaluation_record(5, 1.0, fell=0.0, flight=0.02),
        evaluation_record(6, None),
        evaluation_record(7, 3.0, fell=1.0),
        evaluation_record(8, 2.0, fell=1.0, flight=0.04),
    ]
    figures = recent_figures(window)
    assert (figures.first, figures.last, figures.evaluations, figures.succeeded) == (5, 8, 4, 3)
    assert figures.fitness_quartiles == (1.5, 2.0, 2.5)  # the failed one is not a fitness
    by_name = {m.name: m for m in figures.metrics}
    assert by_name["fell"].is_share and by_name["fell"].value == 2 / 3
    assert not by_name["flight"].is_share and by_name["flight"].value == 0.03
    assert by_name["flight"].count == 2


def test_a_window_where_every_evaluation_failed_or_none_at_all():
    figures = recent_figures([evaluation_record(0, None), evaluation_record(1, None)])
    assert figures.succeeded == 0 and figures.fitness_quartiles is None
    assert recent_figures([]) is None
