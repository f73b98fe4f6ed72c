"""`metaopt replay RUN --seeds N`: the best candidate re-evaluated with N fresh seeds and
reported as median, interquartile range and fall rate; the same numbers in-process, from the
command, and from two worker processes."""

from __future__ import annotations

import numpy as np
import pytest

from metaopt.assessment.replay import replay_seeds
from metaopt.assessment.robustness import summarize
from metaopt.executors.base import SerialExecutor
from metaopt.plugins import registry
from metaopt.seeding import EvaluationSeeds
from metaopt.storage.run_store import RunStore
from tests.conftest import metaopt_cli

SHORT = ("--set", "duration=4", "--set", "lock=1")


@pytest.fixture(scope="module")
def store_dir(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("replay")
    done = metaopt_cli("run", "-o", "random", "-p", "nao-walk", "--budget", "3", "--seed",
                       "1", *SHORT, cwd=folder)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return folder


def test_replay_seeds_evaluates_the_best_with_n_drawn_seeds(store_dir) -> None:
    plugins = registry()
    with RunStore(store_dir / "metaopt.db") as store:
        result = replay_seeds(store, 1, plugins, {"noise": 1.0}, 3, 7, SerialExecutor())
    info = plugins.problem("nao-walk")
    problem = info.factory(**result.problem_params)
    try:
        expected = [problem.evaluate(np.asarray(result.stored.x), EvaluationSeeds(7)(i))
                    for i in range(3)]  # fmt: skip
    finally:
        problem.close()
    assert [o.metrics for o in result.outcomes] == [e.metrics for e in expected]
    assert len({o.metrics["distance"] for o in result.outcomes}) == 3  # noise: 3 episodes
    # reported as a statistic: the median of the three distances between distinct quartiles
    distances = sorted(o.metrics["distance"] for o in result.outcomes)
    median, low, high = summarize([o.metrics for o in result.outcomes], "distance")
    assert median == distances[1]
    assert distances[0] < low < median < high < distances[2]


@pytest.mark.slow
def test_replay_seeds_command_is_a_statistic_and_deterministic(store_dir) -> None:
    args = ("replay", "1", "--seeds", "3", "--set", "noise=1")
    first = metaopt_cli(*args, cwd=store_dir)
    assert first.returncode == 0, first.stderr
    assert "over 3 seeds (noise=1.0)" in first.stdout
    assert "median" in first.stdout and "IQR" in first.stdout and "fell" in first.stdout
    pooled = metaopt_cli(*args, "--workers", "2", cwd=store_dir)
    assert pooled.returncode == 0, pooled.stderr
    assert pooled.stdout == first.stdout
    bad = metaopt_cli("replay", "1", "--seeds", "2", "--set", "push=1", "--set",
                      "push_time=0.5", cwd=store_dir)  # fmt: skip
    assert bad.returncode == 2 and "push_time" in bad.stderr and "Traceback" not in bad.stderr
