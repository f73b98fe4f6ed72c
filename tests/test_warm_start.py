"""Warm starts: a run's first candidates are a given point and points around it, in place of the
optimizer's random ones; deterministic, resumable, and checked against the problem."""

import numpy as np
import pytest

import metaopt
from metaopt import ConfigError, Space, Variable
from metaopt.plugins import registry
from metaopt.running import RunSettings, RunSpec, resume, run
from metaopt.storage.run_store import RunStore
from metaopt.warm_start import fitted_start, start_points
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait
from tests.conftest import metaopt_cli
from tests.test_run_loop import _stopping_sphere

SPACE = Space.from_bounds([-5.0] * 4, [5.0] * 4)


def test_start_points_are_the_point_then_a_box_around_it_inside_the_bounds() -> None:
    point = [4.9, 0.0, -1.0, 2.0]
    points = start_points(SPACE, point, 0.05, 50, seed=3)
    assert points.shape == (50, 4)
    assert points[0].tolist() == point
    assert np.all(np.abs(points - point) <= 0.05 * 10 + 1e-12)
    assert SPACE.contains(points) and points[:, 0].max() == 5.0  # clipped at the bound
    assert len({row.tobytes() for row in points}) == 50
    np.testing.assert_array_equal(points, start_points(SPACE, point, 0.05, 50, seed=3))
    assert not np.array_equal(points, start_points(SPACE, point, 0.05, 50, seed=4))


def test_several_start_points_come_first_then_boxes_around_each_in_turn() -> None:
    points = [[4.0, 4.0, 4.0, 4.0], [-4.0, -4.0, -4.0, -4.0], [0.0, 0.0, 0.0, 0.0]]
    drawn = start_points(SPACE, points, 0.05, 20, seed=3)
    assert drawn.shape == (20, 4) and drawn[:3].tolist() == points
    for index, row in enumerate(drawn[3:]):
        assert np.all(np.abs(row - points[index % 3]) <= 0.5 + 1e-12)  # the box around it
        assert not np.array_equal(row, points[index % 3])
    # One point, given alone or as a list of one, gives the candidates it always gave.
    np.testing.assert_array_equal(
        start_points(SPACE, points[0], 0.05, 9, seed=3), start_points(SPACE, points[:1], 0.05, 9, 3)
    )


def test_a_run_stored_with_one_flat_start_point_reads_as_a_list_of_one() -> None:
    """Runs stored before several start points could be given keep resuming alike."""
    assert RunSettings(**{"start": [1.0, 2.0]}).start == [[1.0, 2.0]]
    assert RunSettings(start=[[1.0, 2.0], [3.0, 4.0]]).start == [[1.0, 2.0], [3.0, 4.0]]


def test_minimize_from_several_points_evaluates_each_first(tmp_path) -> None:
    starts = [[1.0, 1.0], [-2.0, 3.0]]
    result = metaopt.minimize(lambda x: float(np.sum(x**2)), [(-5, 5)] * 2, budget=40, seed=2,
                              start=starts, store=tmp_path / "runs.db")  # fmt: skip
    with RunStore(tmp_path / "runs.db") as store:
        xs = [e.x.tolist() for e in store.evaluations(result.run_id)]
    assert xs[:2] == starts
    with pytest.raises(ConfigError, match="3 points to start from but 2 start points"):
        metaopt.minimize(sum, [(-5, 5)] * 2, budget=30, start=[[0, 0], [1, 1], [2, 2]], hms=2)


def _sphere_run(store, optimizer="hs", seed=1, budget=200, start=None, points=0, **params):
    plugins = registry()
    settings = RunSettings(start=start, start_points=points, start_spread=0.1)
    spec = RunSpec(optimizer, "sphere", budget, seed, params, {"dim": 4}, settings)
    return run(spec, plugins.optimizer(optimizer), plugins.problem("sphere"), store)


@pytest.mark.parametrize(("optimizer", "params", "count"),
                         [("hs", {}, 20), ("ga", {"population": 30}, 30)])  # fmt: skip
def test_the_first_candidates_are_the_start_points_then_the_optimizer_learns_from_them(
    tmp_path, optimizer, params, count
) -> None:
    """With no count given, the optimizer's initial population (hs: hms, ga: a generation)
    starts at the point; the next ones are bred from it, so the search stays near it."""
    start = [3.0, -3.0, 3.0, -3.0]
    with RunStore(tmp_path / "runs.db") as store:
        result = _sphere_run(store, optimizer, start=start, **params)
        record = store.run(result.run_id)
        xs = np.array([e.x for e in store.evaluations(result.run_id)])
    assert record.settings["start_points"] == count  # stored resolved: a resume draws the same
    space = Space.from_bounds([-5.12] * 4, [5.12] * 4)
    np.testing.assert_array_equal(xs[:count], start_points(space, start, 0.1, count, seed=1))
    # The optimizer's own candidates come from the start's neighbourhood, not the whole box:
    # from a random first population about a third of their values would lie this near.
    near = np.abs(xs[count : 3 * count] - start) <= 0.15 * 10.24
    assert near.mean() > 0.85


def test_fewer_start_points_than_the_population_leave_the_rest_random(tmp_path) -> None:
    start = [3.0, -3.0, 3.0, -3.0]
    with RunStore(tmp_path / "runs.db") as store:
        result = _sphere_run(store, "ga", start=start, points=5, population=30)
        xs = np.array([e.x for e in store.evaluations(result.run_id)])
    assert np.all(np.abs(xs[:5] - start) <= 0.1 * 10.24 + 1e-12)
    assert np.any(np.abs(xs[5:30] - start) > 2.0)  # the other 25 are uniform in the box


def test_a_warm_start_is_deterministic_and_leaves_a_run_without_it_unchanged(tmp_path) -> None:
    start = [1.0, 1.0, 1.0, 1.0]
    with RunStore(tmp_path / "runs.db") as store:
        runs = [_sphere_run(store, start=start), _sphere_run(store, start=start)]
        cold = [_sphere_run(store), _sphere_run(store, start=None, points=7)]
        stored = [[e.x.tobytes() for e in store.evaluations(r.run_id)] for r in runs + cold]
    assert stored[0] == stored[1]
    assert stored[2] == stored[3]  # start_points without a start changes nothing
    assert stored[0] != stored[2]


@pytest.mark.parametrize("after", [7, 150])  # within the start points, and after them
def test_a_warm_started_run_resumes_as_if_never_stopped(tmp_path, after) -> None:
    plugins = registry()
    settings = RunSettings(start=[2.0, 2.0, 2.0], start_spread=0.2)
    spec = RunSpec("hs", "sphere", 400, 5, {}, {"dim": 3}, settings)
    with RunStore(tmp_path / "runs.db") as store:
        whole = run(spec, plugins.optimizer("hs"), plugins.problem("sphere"), store)
        with pytest.raises(KeyboardInterrupt):
            run(spec, plugins.optimizer("hs"), _stopping_sphere(after=after), store)
        stopped = store.runs()[-1]
        resumed = resume(stopped.id, store, plugins.optimizer("hs"), plugins.problem("sphere"))
        fitnesses = [[e.fitness for e in store.evaluations(r)] for r in (whole.run_id, stopped.id)]
    assert resumed.best_fitness == whole.best_fitness
    assert fitnesses[0] == fitnesses[1]


def test_minimize_starts_from_a_point_and_refines_it() -> None:
    """The warm start's use: from a point near a far minimum of a multimodal function, 300
    evaluations refine that minimum; from random points they do not find it."""

    def shifted_rastrigin(x):
        z = np.asarray(x) - 3.0
        return float(10 * len(z) + np.sum(z**2 - 10 * np.cos(2 * np.pi * z)))

    bounds = [(-5.12, 5.12)] * 6
    near = [3.02, 2.97, 3.01, 3.03, 2.98, 3.0]
    warm = [metaopt.minimize(shifted_rastrigin, bounds, budget=300, seed=s, start=near).fitness
            for s in range(3)]  # fmt: skip
    cold = [metaopt.minimize(shifted_rastrigin, bounds, budget=300, seed=s).fitness
            for s in range(3)]  # fmt: skip
    assert max(warm) < shifted_rastrigin(near) < min(cold)


def test_a_start_outside_the_bounds_or_of_another_size_is_one_clear_error() -> None:
    with pytest.raises(ConfigError, match="outside the problem's bounds: x1=7 not in"):
        metaopt.minimize(sum, [(-5, 5)] * 2, budget=30, start=[0.0, 7.0])
    with pytest.raises(ConfigError, match="has 3 values but the problem has 2 variables"):
        metaopt.minimize(sum, [(-5, 5)] * 2, budget=30, start=[0.0, 1.0, 2.0])
    with pytest.raises(
        ConfigError, match=r"start spread must be a share of each range in \[0, 1\]"
    ):
        metaopt.minimize(sum, [(-5, 5)] * 2, budget=30, start=[0.0, 1.0], start_spread=2.0)


def test_run_start_from_a_stored_gait_evaluates_it_first(tmp_path) -> None:
    """`metaopt run --start-from NAME`: the gait itself is the first candidate, then points
    around it; `show` says where the run started."""
    db = "runs.db"
    short = ["--set", "duration=5", "--set", "lock=1", "--set", "controller=stride"]
    result = metaopt_cli("run", "-o", "hs", "-p", "nao-walk", "--budget", "3", "--seed", "1",
                         "--start-from", "stride_mujoco", "--start-spread", "0.02",
                         "--set", "hms=2", *short, "--db", db, cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    with RunStore(tmp_path / db) as store:
        record = store.runs()[0]
        xs = [e.x for e in store.evaluations(record.id)]
    gait = gait_vector(load_gait("stride_mujoco"))
    np.testing.assert_array_equal(xs[0], gait)
    assert np.max(np.abs(xs[1] - gait)) > 0 and record.settings["start_from"] == "stride_mujoco"
    shown = metaopt_cli("show", str(record.id), "--db", db, cwd=tmp_path)
    assert "started from stride_mujoco (2 points within 0.02)" in shown.stdout


def test_run_start_from_a_candidate_of_other_variables_is_one_line(tmp_path) -> None:
    result = metaopt_cli("run", "-o", "hs", "-p", "nao-walk", "--budget", "3", "--start-from",
                         "hs_walk", "--set", "controller=stride", cwd=tmp_path)  # fmt: skip
    assert result.returncode == 2 and not result.stdout
    assert result.stderr.strip().splitlines() == [
        "Error: 'hs_walk' has the variables tau1, tau2, alpha, beta, gamma, c, w11, w12, b1, "
        "b2; this run's problem has period, feedback, hip_bias, hip_swing, knee_bias, "
        "knee_lift, ankle_bias, sway, sway_phase, pitch_gain, roll_gain, knee_phase, push, "
        "push_phase (e.g. another controller): start from a candidate of the same variables"
    ]
    other = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "3",
                        "--start-from", "hs_walk", cwd=tmp_path)  # fmt: skip
    assert other.returncode == 2
    assert "is a candidate of 'nao-walk', not of 'sphere'" in other.stderr
    assert not (tmp_path / "metaopt.db").exists()  # nothing written for a refused run


NEUTRAL = Space([Variable("a", -1.0, 1.0), Variable("gain", -2.0, 2.0, neutral=0.5),
                 Variable("b", 0.0, 3.0), Variable("rate", -1.0, 1.0, neutral=0.0)])  # fmt: skip


def test_a_start_that_lacks_variables_with_a_neutral_value_takes_it() -> None:
    assert fitted_start("p", ("b", "a"), [2.0, -0.5], NEUTRAL) == [-0.5, 0.5, 2.0, 0.0]
    assert fitted_start("p", NEUTRAL.names, [0.1, 0.2, 0.3, 0.4], NEUTRAL) == [0.1, 0.2, 0.3, 0.4]
    with pytest.raises(ConfigError) as lacking:
        fitted_start("'p'", ("a", "gain"), [0.0, 0.0], NEUTRAL)
    assert str(lacking.value) == (
        "'p' has the variables a, gain; this run's problem has a, gain, b, rate (e.g. another "
        "controller): start from a candidate of the same variables (it may lack only gain, "
        "rate: they have a neutral value)"
    )
    with pytest.raises(ConfigError, match="'p' has the variables a, b, c; "):
        fitted_start("'p'", ("a", "b", "c"), [0.0, 0.0, 0.0], NEUTRAL)


def test_a_neutral_value_lies_within_its_bounds_and_is_stored_with_the_space() -> None:
    with pytest.raises(ConfigError, match=r"'g' has neutral value 3\.0 outside its bounds"):
        Space([Variable("g", -1.0, 1.0, neutral=3.0)])
    assert Space.from_json(NEUTRAL.to_json()).variables == NEUTRAL.variables
    assert "neutral" not in SPACE.to_json()[0]  # a space without one is stored as before


def test_a_steered_gait_starts_a_balanced_run_where_it_walked(tmp_path) -> None:
    """`run --start-from` a steered run's best into controller=balanced: the first candidate is
    that best with both placement gains at their neutral 0, and it walks the very same episode
    (the same fitness to the last bit), so nothing is lost in the change of controller."""
    db = "runs.db"
    short = ["--set", "duration=2", "--set", "lock=1"]
    steered = metaopt_cli("run", "-o", "hs", "-p", "nao-walk", "--budget", "4", "--seed", "4",
                          "--set", "hms=2", "--set", "controller=steered", *short, "--db", db,
                          cwd=tmp_path)  # fmt: skip
    assert steered.returncode == 0, steered.stderr
    balanced = metaopt_cli("run", "-o", "hs", "-p", "nao-walk", "--budget", "3", "--seed", "5",
                           "--set", "hms=2", "--set", "controller=balanced", *short,
                           "--start-from", "1", "--db", db, cwd=tmp_path)  # fmt: skip
    assert balanced.returncode == 0, balanced.stderr
    with RunStore(tmp_path / db) as store:
        best = store.best_evaluation(store.run(1))
        first = next(store.evaluations(2))
    np.testing.assert_array_equal(first.x, [*best.x, 0.0, 0.0])
    assert first.fitness == best.fitness
    back = metaopt_cli("run", "-o", "hs", "-p", "nao-walk", "--budget", "1", "--set", "hms=2",
                       "--set", "controller=stride", *short, "--start-from", "2", "--db", db,
                       cwd=tmp_path)  # fmt: skip
    assert back.returncode == 2
    assert "this run's problem has period," in back.stderr
    assert "start from a candidate of the same variables" in back.stderr


def test_run_start_from_several_runs_evaluates_each_best_first(tmp_path) -> None:
    """`--start-from A --start-from B`: each run's best is a first candidate, the optimizer's
    initial population is drawn around them in turn, and `show` names both."""
    db = "runs.db"
    for seed in ("1", "2"):
        made = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "30", "--seed", seed,
                           "--db", db, cwd=tmp_path)  # fmt: skip
        assert made.returncode == 0, made.stderr
    result = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "30", "--seed", "3",
                         "--start-from", "1", "--start-from", "2", "--db", db,
                         cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    with RunStore(tmp_path / db) as store:
        bests = [min(store.evaluations(r), key=lambda e: e.fitness).x for r in (1, 2)]
        record = store.runs()[2]
        xs = np.array([e.x for e in store.evaluations(record.id)])
    np.testing.assert_array_equal(xs[:2], bests)
    offsets = [np.abs(x - bests[i % 2]) / 10.24 for i, x in enumerate(xs[2:20])]
    assert max(np.max(offset) for offset in offsets) <= 0.05 + 1e-12
    assert record.settings["start_from"] == "run 1, run 2"
    shown = metaopt_cli("show", str(record.id), "--db", db, cwd=tmp_path)
    assert "started from run 1, run 2 (20 points within 0.05)" in shown.stdout


def test_run_start_from_one_candidate_of_a_run(tmp_path) -> None:
    """`--start-from RUN:CANDIDATE`: that candidate (not the run's best) is the first one."""
    db = "runs.db"
    made = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "30", "--seed", "1",
                       "--db", db, cwd=tmp_path)  # fmt: skip
    assert made.returncode == 0, made.stderr
    with RunStore(tmp_path / db) as store:
        seventh = list(store.evaluations(1))[7]
    result = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "30", "--seed", "2",
                         "--start-from", f"1:{seventh.candidate}", "--db", db,
                         cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    with RunStore(tmp_path / db) as store:
        first = next(store.evaluations(2))
        assert store.run(2).settings["start_from"] == f"run 1 candidate {seventh.candidate}"
    np.testing.assert_array_equal(first.x, seventh.x)
    missing = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "30",
                          "--start-from", "1:999", "--db", db, cwd=tmp_path)  # fmt: skip
    assert missing.returncode == 2 and "run 1 has no candidate 999" in missing.stderr


def test_start_points_far_past_the_budget_are_refused_and_a_stored_population_is_not() -> None:
    """A slip of 10**14 start points is refused before anything runs; a run stored with its
    optimizer's initial population past its budget (random's batch of 100, budget 30) still
    passes, so that it resumes."""
    with pytest.raises(ConfigError, match=r"more than the 10 candidates .* the first 10\)$"):
        RunSettings(start=[[0.0]], start_points=10**14, resample=2).check(20)
    RunSettings(start=[[0.0]], start_points=100).check(30)
    RunSettings(start=[[0.0]], start_points=20).check(20)
