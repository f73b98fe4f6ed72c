"""A run's course window by window (metaopt history): windows, best so far in either sense,
failures, shares and medians, and the command against the run's own exported evaluations."""

from __future__ import annotations

import csv
import io
from dataclasses import replace

import numpy as np
import pytest

from metaopt.errors import ConfigError
from metaopt.reporting.history import candidate_spread, run_history
from metaopt.space import Space
from tests.conftest import evaluation_record, metaopt_cli

RUN = [
    evaluation_record(0, 5.0, fell=1.0, speed=0.1),
    evaluation_record(1, None),
    evaluation_record(2, 1.0, fell=0.0, speed=0.3),
    evaluation_record(3, 7.0, fell=1.0, speed=0.2),
    evaluation_record(4, 3.0, fell=0.0),
    evaluation_record(5, 2.0, fell=0.0, speed=0.5),
    evaluation_record(6, 9.0, fell=1.0),
]


def test_windows_their_quartiles_and_the_best_so_far_in_either_sense():
    up = run_history(RUN, window=3, maximize=True, metrics=None)
    assert [(w.first, w.last, w.evaluations, w.succeeded) for w in up.windows] == [
        (0, 2, 3, 2), (3, 5, 3, 3), (6, 6, 1, 1),
    ]  # fmt: skip
    assert up.windows[0].fitness_quartiles == (2.0, 3.0, 4.0)  # the failed one is left out
    assert [w.best_so_far for w in up.windows] == [5.0, 7.0, 9.0]
    down = run_history(RUN, window=3, maximize=False, metrics=None)
    assert [w.best_so_far for w in down.windows] == [1.0, 1.0, 1.0]
    failed_first = run_history([evaluation_record(0, None), *RUN[2:4]], 1, True, None)
    assert [w.best_so_far for w in failed_first.windows] == [None, 1.0, 7.0]
    assert failed_first.windows[0].fitness_quartiles is None


def test_shares_for_0_1_metrics_medians_for_the_rest_and_none_where_unreported():
    default = run_history(RUN, window=3, maximize=True, metrics=None)
    assert default.metrics == ("fell",) and default.shares == {"fell"}  # flags by default
    assert [w.metrics["fell"] for w in default.windows] == [0.5, 1 / 3, 1.0]
    chosen = run_history(RUN, window=3, maximize=True, metrics=["speed", "fell", "speed"])
    assert chosen.metrics == ("speed", "fell") and chosen.shares == {"fell"}
    assert [w.metrics["speed"] for w in chosen.windows] == [0.2, 0.35, None]


def test_an_unknown_metric_is_refused_with_the_names_the_run_reports():
    with pytest.raises(ConfigError, match=r"no metric 'height'.*fell, speed"):
        run_history(RUN, window=3, maximize=True, metrics=["height"])


def test_the_command_agrees_with_the_exported_evaluations(tmp_path):
    env = {"METAOPT_LOAD_PLUGINS": "random_search,functions"}
    done = metaopt_cli(
        "run", "-o", "random", "-p", "sphere", "--budget", "50", "--seed", "3", "--set",
        "dim=3", cwd=tmp_path, env=env,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    exported = metaopt_cli("export", "1", "--format", "csv", cwd=tmp_path, env=env)
    fitness = [float(row["fitness"]) for row in csv.DictReader(io.StringIO(exported.stdout))]
    shown = metaopt_cli("history", "1", "--window", "20", "--format", "csv", cwd=tmp_path, env=env)
    rows = list(csv.DictReader(io.StringIO(shown.stdout)))
    ranges = [(row["first"], row["last"]) for row in rows]
    assert ranges == [("0", "19"), ("20", "39"), ("40", "49")]
    for row, start in zip(rows, (0, 20, 40), strict=True):
        window = fitness[start : start + 20]
        assert float(row["fitness_median"]) == pytest.approx(np.median(window), rel=1e-12)
        assert float(row["best_so_far"]) == min(fitness[: start + 20])  # sphere is minimized
    table = metaopt_cli("history", "1", "--window", "20", cwd=tmp_path, env=env)
    assert "lower fitness is better" in table.stdout and "40-49" in table.stdout
    refused = metaopt_cli("history", "1", "--metric", "fell", cwd=tmp_path, env=env)
    assert refused.returncode == 2
    assert refused.stderr.strip().splitlines() == [
        "Error: no metric 'fell' in this run's evaluations; they report: none"
    ]


def test_the_spread_is_the_median_over_the_variables_of_the_candidates_sd_per_range():
    """Three candidates, the third evaluated twice (a resample counts once): on a variable of
    range 10 they stand at 0, 2 and 4 (sd 2: 0.2 of the range), on one of range 1 at 0.1, 0.1
    and 0.4 (sd 0.173), on one of range 2 all at 1 (0): the median share is 0.173."""
    points = {0: [0.0, 0.1, 1.0], 1: [2.0, 0.1, 1.0], 2: [4.0, 0.4, 1.0]}
    records = [
        replace(evaluation_record(i, 1.0), candidate=c, x=np.array(points[c]))
        for i, c in enumerate((0, 1, 2, 2))
    ]
    space = Space.from_bounds([0.0, 0.0, 0.0], [10.0, 1.0, 2.0])
    assert candidate_spread(records, space) == pytest.approx(np.std([0.1, 0.1, 0.4], ddof=1))
    assert candidate_spread(records[2:], space) is None  # one candidate: no spread
    history = run_history(records, window=3, maximize=True, space=space)
    assert [w.spread for w in history.windows] == [pytest.approx(np.sqrt(0.03)), None]
    assert run_history(records, window=3, maximize=True).windows[0].spread is None


def test_the_command_shows_cma_es_step_shrinking_on_the_sphere(tmp_path):
    """CMA-ES's first generation is uniform in the box (a spread near 1/sqrt(12) = 0.29 of each
    range); on the sphere its step then shrinks towards the minimum, and with it the spread."""
    env = {"METAOPT_LOAD_PLUGINS": "cma_es,functions"}
    done = metaopt_cli(
        "run", "-o", "cmaes", "-p", "sphere", "--budget", "400", "--seed", "3", "--set",
        "dim=4", "--set", "population=20", cwd=tmp_path, env=env,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    shown = metaopt_cli("history", "1", "--window", "20", "--spread", "--format", "csv",
                        cwd=tmp_path, env=env)  # fmt: skip
    assert shown.returncode == 0, shown.stderr
    spreads = [float(row["spread"]) for row in csv.DictReader(io.StringIO(shown.stdout))]
    assert len(spreads) == 20
    assert 0.2 < spreads[0] < 0.4  # uniform in the box
    assert spreads[-1] < spreads[0] / 20  # the step has shrunk by more than twentyfold
    table = metaopt_cli("history", "1", "--window", "100", "--spread", cwd=tmp_path, env=env)
    assert "spread" in table.stdout
    plain = metaopt_cli("history", "1", "--window", "100", "--format", "csv", cwd=tmp_path,
                        env=env)  # fmt: skip
    assert "spread" not in plain.stdout  # only when asked for


def _run_without_evaluations(db) -> int:
    """A run stopped before its first evaluation (an early Ctrl-C), as the store holds it."""
    from metaopt.storage.run_store import RunStore

    with RunStore(db) as store:
        return store.create_run(
            optimizer="random", optimizer_params={}, problem="sphere",
            problem_params={"dim": 2}, seed=7, budget=10, sense="minimize",
            space=[{"name": f"x{i}", "lower": -5, "upper": 5, "description": ""}
                   for i in range(2)],
            settings={"mode": "sync"}, versions={"python": "3"},
        )  # fmt: skip


def test_history_and_report_of_a_run_without_evaluations_refuse_in_one_line(tmp_path):
    """`history` (every format) and `report` of a run with no evaluation yet: one 'Error:'
    line, exit 2, no traceback and no figure folder; its empty history has no window."""
    run_id = _run_without_evaluations(tmp_path / "metaopt.db")
    other = _run_without_evaluations(tmp_path / "metaopt.db")
    expected = [f"Error: run {run_id} has no evaluations yet; nothing to show"]
    for command in (["history", str(run_id)], ["history", str(run_id), "--format", "json"],
                    ["report", str(run_id)], ["report", str(run_id), str(other)]):  # fmt: skip
        done = metaopt_cli(*command, cwd=tmp_path)
        assert done.returncode == 2, (command, done.stderr)
        assert done.stderr.strip().splitlines() == expected, command
    assert not list(tmp_path.glob("report-*"))
    assert run_history([], 10, maximize=False).windows == ()
