"""benchmarks/optimizer_quality.py counts alike for everyone: each run stops at its budget."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from tests.conftest import ROOT, load_script

SCRIPT = ROOT / "benchmarks" / "optimizer_quality.py"


@pytest.fixture(scope="module")
def quality():
    return load_script("benchmarks/optimizer_quality.py")


def test_the_counter_keeps_the_best_of_the_budget_and_refuses_one_call_more(quality):
    counted = quality.Counted(lambda x: float(x.sum()), budget=3)
    assert [counted([v]) for v in (2.0, 1.0, 5.0)] == [2.0, 1.0, 5.0]
    with pytest.raises(quality.BudgetSpent):
        counted([0.0])
    assert counted.calls == 3 and counted.best == 1.0


@pytest.mark.parametrize("label", ["hs", "ga", "hs:pitch_adjust=ghs+hms=7"])
def test_metaopt_runs_use_exactly_the_budget_on_both_suites(quality, label):
    for suite, function in (("classic", "rastrigin"), ("bbob", "15")):
        task = quality.Task(label, suite, function, 10, 333, 1)
        result = quality.run_task(task)
        assert result["evaluations"] == 333 and math.isfinite(result["best"])
        assert result == quality.run_task(task)  # the same seed, the same result


def test_the_report_ranks_medians_and_counts_wins(quality):
    medians = {"1": {"hs": 1e-12, "mealpy-hs": 1e-9}, "2": {"hs": 3.0, "mealpy-hs": 2.0}}
    rows = [
        {"suite": "bbob", "dim": 10, "budget": 100, "function": f, "optimizer": o, "seed": s,
         "best": best, "evaluations": 100}
        for f, values in medians.items()
        for o, best in values.items()
        for s in (1, 2, 3)
    ]  # fmt: skip
    text = quality.report(rows, ["hs", "mealpy-hs"])
    assert "| 1 | 1e-08 | 1e-08 |" in text  # both below 1e-8: a tie at the floor
    assert "| mean rank | 1.75 | 1.25 |" in text
    assert "- hs vs mealpy-hs: better median on 0, worse on 1, of 2" in text
    assert quality.ranks([3.0, 1.0, 3.0]) == [2.5, 1.0, 2.5]


def test_a_worker_given_more_tasks_than_its_pipes_hold_finishes_them_all(tmp_path):
    """2,400 tiny runs: their tasks and results each overflow a pipe's 64 KiB, which deadlocked
    the parent writing tasks against the worker writing results before the tasks were fed from
    a thread of their own."""
    results = tmp_path / "results.jsonl"
    grid = ["--suites", "classic", "--dims", "2", "--budgets", "1,2,3,4", "--seeds", "100"]
    subprocess.run(
        [sys.executable, str(SCRIPT), *grid, "--optimizers", "random", "--jobs", "1",
         "--results", str(results)],
        check=True, capture_output=True, timeout=120,
    )  # fmt: skip
    assert len(results.read_text().splitlines()) == 6 * 4 * 100
