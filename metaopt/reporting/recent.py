"""Where a run stands, as its last evaluations say: the median fitness of a window of recent
evaluations and each metric's median (a 0/1 metric's share), beside the best. A run's best is
the luckiest of many noisy scores; its recent evaluations show whether the search still climbs,
and how many of its candidates fail the task (e.g. nao-walk's share of falls)."""

from __future__ import annotations

import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from metaopt.storage.run_store import EvaluationRecord

#: evaluations in the window of `metaopt show` unless --recent says otherwise
DEFAULT_WINDOW = 100


@dataclass(frozen=True)
class MetricFigure:
    """A metric over the window: its median, or for a metric that is 0 or 1 in every
    evaluation that reports it (a flag such as nao-walk's ``fell``), the share of 1s."""

    name: str
    value: float
    is_share: bool
    count: int  # evaluations that report the metric


@dataclass(frozen=True)
class RecentFigures:
    """The last ``window`` evaluations of a run (fewer when it has fewer): index range,
    how many succeeded, their fitness quartiles and their metrics. Screened evaluations
    (metaopt run --screen) have no fitness and are counted apart: the figures are the
    completed ones', which ranked above them."""

    first: int
    last: int
    evaluations: int
    succeeded: int
    fitness_quartiles: tuple[float, float, float] | None  # None: none succeeded
    metrics: tuple[MetricFigure, ...]
    screened: int = 0


def recent_figures(evaluations: Iterable[EvaluationRecord]) -> RecentFigures | None:
    """The figures of these evaluations (a run's last window, in index order); None when
    there are none."""
    window = list(evaluations)
    if not window:
        return None
    whole = completed(window)
    fitnesses = [e.fitness for e in whole if e.fitness is not None]
    values: dict[str, list[float]] = {}
    for evaluation in whole:
        for name, value in evaluation.metrics.items():
            values.setdefault(name, []).append(float(value))
    metrics = tuple(_metric(name, found) for name, found in values.items())
    return RecentFigures(
        window[0].index,
        window[-1].index,
        len(window),
        len(fitnesses),
        fitness_quartiles(fitnesses),
        metrics,
        len(window) - len(whole),
    )


def completed(evaluations: Sequence[EvaluationRecord]) -> list[EvaluationRecord]:
    """The evaluations that ran whole: not screened (a screen's metrics are a part's)."""
    return [e for e in evaluations if e.status != "screened"]


def fitness_quartiles(fitnesses: Sequence[float]) -> tuple[float, float, float] | None:
    """Lower quartile, median and upper quartile of these fitnesses (linear interpolation, as
    every other table of metaopt's); None when there are none."""
    if not fitnesses:
        return None
    lower, median, upper = np.percentile(fitnesses, [25, 50, 75])
    return float(lower), float(median), float(upper)


def is_flag(values: Iterable[float]) -> bool:
    """Whether a metric is 0 or 1 in every value given (each evaluation's or run's that reports
    it; a flag such as nao-walk's ``fell``): shown as the share at 1, not as a median."""
    return all(value in (0.0, 1.0) for value in values)


def metric_value(values: Sequence[float], share: bool) -> float:
    """A metric over a window (or over runs, metaopt compare): the share of its values at 1 (a
    flag), or their median; one rule for every table."""
    return sum(values) / len(values) if share else statistics.median(values)


def _metric(name: str, values: list[float]) -> MetricFigure:
    share = is_flag(values)
    return MetricFigure(name, metric_value(values, share), share, len(values))
