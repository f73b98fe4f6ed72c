"""`metaopt replay RUN --seeds N`: the best candidate re-evaluated with N fresh seeds and
reported as median, interquartile range and fall rate; the same numbers in-process, from the
command, and from two worker processes."""

from __future__ import annotations

import numpy as np
import pytest

from metaopt.assessment.replay import replay_seeds, run_source
from metaopt.assessment.robustness import summarize
from metaopt.executors.base import SerialExecutor
from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt.seeding import EvaluationSeeds
from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.stored_gaits import (
    gait_seed,
    gait_vector,
    load_gait,
    stored_gait_names,
)
from tests.conftest import metaopt_cli, one_error_line

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
        result = replay_seeds(run_source(store, 1), plugins, {"noise": 1.0}, 3, 7, SerialExecutor())
    info = plugins.problem("nao-walk")
    problem = info.factory(**result.problem_params)
    try:
        expected = [problem.evaluate(np.asarray(result.source.x), EvaluationSeeds(7)(i))
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


def test_replay_takes_a_stored_gait_by_name_without_a_store(tmp_path) -> None:
    """`metaopt replay NAME`: a problem's stored candidate, replayed with the parameters and
    seed it was recorded with (changed by --set), where no run store exists; no 'stored'
    column, since the record keeps no fitness for those settings."""
    record = load_gait("hs_walk")
    done = metaopt_cli("replay", "hs_walk", *SHORT, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    title = " ".join(done.stdout.split())  # the title wraps to the table's width
    assert "stored candidate hs_walk replayed (duration=4.0, lock=1.0)" in title
    assert "stored" not in done.stdout.replace("stored candidate", "")
    info = registry().problem("nao-walk")
    params = resolve(info.params, {**record["problem_params"], "duration": 4, "lock": 1}, "nao")
    problem = info.factory(**params)
    try:
        expected = problem.evaluate(gait_vector(record), gait_seed(record))
    finally:
        problem.close()
    fitness_row = next(line for line in done.stdout.splitlines() if "fitness" in line)
    assert f"{expected.fitness:.6g}" in fitness_row
    assert not (tmp_path / "metaopt.db").exists()
    unknown = metaopt_cli("replay", "hs_wlak", cwd=tmp_path)
    first, second = stored_gait_names()[:2]  # the refusal lists them sorted
    assert unknown.returncode == 2
    assert f"neither a stored candidate ({first}, {second}" in unknown.stderr


def test_replay_refuses_a_setting_that_changes_the_candidates_space(tmp_path) -> None:
    """`replay --set` that gives the problem other variables (dim=1, dim=3 of a 2-variable
    sphere) would evaluate the stored vector as a point it is not: refused in one line, for
    one evaluation and for --seeds; a --set that keeps the space replays."""
    done = metaopt_cli("run", "-o", "random", "-p", "sphere", "--budget", "3", "--seed", "1",
                       "--set", "dim=2", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    for target, extra in (("1", ()), ("1:1", ()), ("1", ("--seeds", "2"))):
        for dim, now in (("1", "1 variable (x0)"), ("3", "3 variables (x0, x1, x2)")):
            refused = metaopt_cli("replay", target, *extra, "--set", f"dim={dim}", cwd=tmp_path)
            one_error_line(refused, f"--set dim={dim} changes the space to {now}; the "
                           "candidate has 2 variables (x0, x1)")  # fmt: skip
    same = metaopt_cli("replay", "1", "--set", "dim=2", cwd=tmp_path)
    assert same.returncode == 0, same.stderr


def test_check_space_refuses_other_variables_or_bounds_and_keeps_the_same() -> None:
    """Other names or bounds are another space, named in the refusal; the same space passes."""
    from metaopt import ConfigError
    from metaopt.assessment.replay import check_space
    from metaopt.space import Space

    two = Space.from_bounds([-5, -5], [5, 5])
    check_space({"scale": 1}, two, Space.from_bounds([-5, -5], [5, 5]))
    with pytest.raises(ConfigError, match=r"changes x1's bounds to \[-5, 10\]; the candidate's "
                       r"are \[-5, 5\]"):  # fmt: skip
        check_space({"scale": 2}, two, Space.from_bounds([-5, -5], [5, 10]))
    with pytest.raises(ConfigError, match=r"changes the variables to \(a, b\)"):
        check_space({"kind": "b"}, two, Space.from_bounds([-5, -5], [5, 5], ["a", "b"]))
