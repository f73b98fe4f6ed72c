"""The walking episode: determinism (in and across processes, restored or fresh), fall
detection, metrics, fitness formulas, and the nao-walk problem end to end."""

from __future__ import annotations

import json
import math
import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from metaopt import ConfigError, EvaluationError, Sense
from metaopt.params import resolve
from metaopt.physics import PhysicsSettings, engine_names
from metaopt.plugins import registry
from metaopt_problems.nao_walk.episode import (
    FALL_PENALTY,
    FLIGHT_ALLOWED,
    Disturbance,
    EpisodeResult,
    EpisodeRunner,
    EpisodeSettings,
    Sensors,
    SineGait,
    fitness,
)
from metaopt_problems.nao_walk.robot import nao
from metaopt_problems.nao_walk.robustness import STANDARD_TABLE
from metaopt_problems.nao_walk.stored_gaits import (
    gait_problem,
    gait_seed,
    gait_vector,
    load_gait,
    stored_gait_names,
)
from metaopt_problems.physics.ode_binding import LIBRARY_ENV
from tests.conftest import load_script, metaopt_cli

BACKENDS = ("mujoco", "pybullet")
SHORT = EpisodeSettings(duration=4.0, lock=1.0)
REPO = Path(__file__).resolve().parents[1]


class SitDown(SineGait):
    """Throws both thighs forward: the robot falls on its back."""

    def act(self, sensors: Sensors) -> tuple[float, ...]:
        return (1.5, 0.0, 0.0, 1.5, 0.0, 0.0)


class Diverging(SineGait):
    def act(self, sensors: Sensors) -> tuple[float, ...]:
        return (math.inf, 0.0, 0.0, 0.0, 0.0, 0.0)


def runner(backend: str, settings: EpisodeSettings = SHORT) -> EpisodeRunner:
    engine = registry().physics_backend(backend).factory(nao(), PhysicsSettings())
    return EpisodeRunner(engine, settings)


def metrics_in_this_process(backend: str) -> dict[str, float]:
    """The sine gait's short episode, run twice on one runner (the second from the restored
    lock phase); the subprocess test compares these numbers across processes."""
    episode = runner(backend)
    first = episode.run(SineGait()).metrics()
    assert episode.run(SineGait()).metrics() == first
    return first


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_metrics_in_another_process(backend: str) -> None:
    here = metrics_in_this_process(backend)
    code = (
        "import json; from tests.test_nao_episode import metrics_in_this_process as m; "
        f"print(json.dumps(m({backend!r})))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True
    )
    assert json.loads(out.stdout.strip().splitlines()[-1]) == here


@pytest.mark.parametrize("backend", BACKENDS)
def test_restored_lock_phase_equals_a_fresh_run_bit_for_bit(backend: str) -> None:
    cached = runner(backend)
    cached.run(SineGait(period=0.4))  # simulates and stores the lock phase
    restored = cached.run(SineGait(), record=True)
    fresh = runner(backend).run(SineGait(), record=True)
    assert restored.metrics() == fresh.metrics()
    for name, column in fresh.trajectory.items():
        assert np.array_equal(restored.trajectory[name], column), name


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_fall_is_detected_and_ends_the_episode(backend: str) -> None:
    result = runner(backend).run(SitDown(), record=True)
    assert result.fell
    assert 0 < result.time_walked < SHORT.duration - SHORT.lock
    assert result.fall_time == pytest.approx(SHORT.lock + result.time_walked)
    assert result.metrics()["time_to_fall"] == result.time_walked  # only where it fell
    assert len(result.trajectory["time"]) == round(result.time_walked / 0.02)
    z, tilt = result.trajectory["z"], result.trajectory["tilt"]
    assert z[-1] < SHORT.fall_height or tilt[-1] > SHORT.fall_tilt  # stopped at the fall ...
    assert np.all((z[:-1] >= SHORT.fall_height) & (tilt[:-1] <= SHORT.fall_tilt))  # ... not before


@pytest.mark.parametrize("backend", BACKENDS)
def test_metrics_are_consistent(backend: str) -> None:
    result = runner(backend).run(SineGait(), record=True)
    assert not result.fell and result.fall_time == SHORT.duration
    assert result.time_walked == pytest.approx(SHORT.duration - SHORT.lock)
    metrics = result.metrics()
    assert "time_to_fall" not in metrics  # it walked the whole episode
    assert metrics["speed"] == pytest.approx(metrics["distance"] / metrics["time_walked"])
    assert metrics["height_range"] == pytest.approx(metrics["height_max"] - metrics["height_min"])
    z = result.trajectory["z"]
    assert metrics["height_min"] <= z.min() and metrics["height_max"] >= z.max()


def test_a_diverging_controller_is_an_evaluation_error() -> None:
    with pytest.raises(EvaluationError, match="not finite"):
        runner("mujoco").run(Diverging())


def _result(distance: float, drift: float, fell: bool, fall_time: float) -> EpisodeResult:
    return EpisodeResult(distance, drift, fall_time - 3.0, fell, fall_time, 0.3, 0.4)


def test_robust_fitness_never_rewards_a_fall() -> None:
    walked = fitness(_result(1.0, -0.2, False, 15.0), "robust", 15.0)
    assert walked == pytest.approx(0.8)
    for progress in (-2.0, 0.0, 1.0):
        scores = [fitness(_result(progress, 0.0, True, t), "robust", 15.0) for t in (4, 10, 14.9)]
        assert scores == sorted(scores)  # a later fall is better
        assert scores[-1] <= progress - FALL_PENALTY  # and always worse than stopping upright


def test_paper_fitness_is_eq_9_as_printed() -> None:
    assert fitness(_result(1.0, 0.5, False, 15.0), "paper", 15.0) == pytest.approx(0.5)
    assert fitness(_result(1.0, 0.0, True, 11.0), "paper", 15.0) == pytest.approx(0.25)
    # its flaw: a fall 0.5 s before the end doubles the score
    assert fitness(_result(1.0, 0.0, True, 14.5), "paper", 15.0) == pytest.approx(2.0)


def test_progress_fitness_scores_a_fall_by_the_walk_it_cut_short() -> None:
    assert fitness(_result(1.0, -0.2, False, 15.0), "progress", 15.0) == pytest.approx(0.8)
    fell = fitness(_result(2.0, 0.3, True, 8.0), "progress", 15.0)
    assert fell == pytest.approx(1.7 - FALL_PENALTY)  # the constant, not the time left ...
    assert fell > 0.0 > fitness(_result(2.0, 0.3, True, 8.0), "robust", 15.0)  # ... so it beats
    # standing still, where the robust fitness puts it below; and a lunge does not pay
    assert fitness(_result(0.33, 0.0, True, 4.0), "progress", 15.0) < 0.0
    # the flight penalty applies as with the other kinds
    flying = EpisodeResult(1.0, 0.0, 12.0, False, 15.0, 0.3, 0.4, flight=0.15)
    assert fitness(flying, "progress", 15.0, flight_penalty=20) == pytest.approx(1.0 - 20 * 0.1)
    # above the share a search allows (flight_allowed), not the goal's 5 %
    stricter = fitness(flying, "progress", 15.0, flight_penalty=20, flight_allowed=0.02)
    assert stricter == pytest.approx(1.0 - 20 * 0.13)


@pytest.mark.parametrize("kind", ["robust", "progress"])
def test_falling_before_the_flight_is_measured_does_not_escape_the_flight_penalty(
    kind: str,
) -> None:
    """Stage 1b of design L's seed 73 learned to fall within 1.5 s of walking (fitness about -1)
    rather than walk on with flight (a median of -10 m at flight_penalty 50): an early fall, whose
    flight is never measured, was charged no penalty. It is now charged flight throughout."""
    early = EpisodeResult(0.2, 0.0, 1.4, True, 4.4, 0.3, 0.4)  # fell before SETTLE_S: flight NaN
    assert math.isnan(early.flight)
    for flight in (0.0, 0.3, 1.0):  # a later fall, at the same progress, with any flight share
        later = EpisodeResult(0.2, 0.0, 6.0, True, 9.0, 0.3, 0.4, flight=flight)
        assert fitness(later, kind, 15.0, flight_penalty=50) >= fitness(
            early, kind, 15.0, flight_penalty=50
        )
    charged = fitness(early, kind, 15.0) - 50 * (1.0 - FLIGHT_ALLOWED)
    assert fitness(early, kind, 15.0, flight_penalty=50) == pytest.approx(charged)
    # only a fall is charged: a walk too short to measure, upright, pays nothing, as before
    short = EpisodeResult(0.2, 0.0, 1.4, False, 4.4, 0.3, 0.4)
    assert fitness(short, kind, 4.4, flight_penalty=50) == pytest.approx(0.2)


def test_problem_rejects_unknown_backend_and_bad_timing() -> None:
    info = registry().problem("nao-walk")
    with pytest.raises(ConfigError, match="Installed: mujoco, ode, pybullet"):
        info.factory(backend="bullet")
    with pytest.raises(ConfigError, match="lock"):
        info.factory(duration=3.0, lock=3.0)


def test_problem_evaluates_end_to_end_and_pickles() -> None:
    problem = registry().problem("nao-walk").factory(duration=5.0)
    assert problem.sense is Sense.MAXIMIZE and problem.space.dim == 10
    x = (problem.space.lower + problem.space.upper) / 2
    first = problem.evaluate(x, seed=1)
    assert problem.evaluate(x, seed=2) == first  # the seed does not matter: no noise
    assert set(problem.key_metrics) <= set(first.metrics)
    copy = pickle.loads(pickle.dumps(problem))
    assert copy.evaluate(x, seed=1) == first
    problem.close()


@pytest.mark.parametrize("backend", BACKENDS)
def test_friction_parameter_sets_the_ground_friction(backend: str) -> None:
    """On ice (mu 0.05) the sine gait's feet slide: the walk differs from the default mu 1,
    which `friction=1` reproduces exactly."""
    info = registry().problem("nao-walk")
    short = {"backend": backend, "duration": 4.0, "lock": 1.0}
    space = info.factory().space
    x = (space.lower + space.upper) / 2
    metrics = {}
    for friction in (None, 1.0, 0.05):
        params = resolve(
            info.params,
            {**short, **({} if friction is None else {"friction": friction})},
            "nao-walk",
        )
        problem = info.factory(**params)
        assert problem.physics.friction == (friction or 1.0)
        metrics[friction] = problem.evaluate(x, seed=1).metrics
        problem.close()
    assert metrics[None] == metrics[1.0]
    assert metrics[0.05] != metrics[1.0]
    with pytest.raises(ConfigError, match="friction"):
        resolve(info.params, {"friction": -1.0}, "nao-walk")


def test_a_friction_the_backend_cannot_stand_on_is_refused_up_front() -> None:
    """MuJoCo's pyramidal cone cannot hold the NAO up at mu 4 or more: the problem says so when
    it is made, naming the engine and its limit, instead of failing every evaluation."""
    info = registry().problem("nao-walk")
    with pytest.raises(ConfigError, match=r"friction 10.0 .*mujoco backend.*at most 3.0"):
        info.factory(backend="pybullet+mujoco", friction=10.0)
    problem = info.factory(backend="mujoco", friction=3.0, duration=2.0, lock=1.5)
    x = (problem.space.lower + problem.space.upper) / 2
    assert problem.evaluate(x, seed=1).metrics["time_walked"] > 0  # it stood through the lock
    problem.close()


def test_a_noise_that_could_draw_a_friction_past_the_engines_limit_is_refused() -> None:
    """The noise multiplies the nominal friction (friction x friction_scale) by up to
    exp(FRICTION_SPREAD * noise) in the walking phase: a problem whose draws could pass an
    engine's limit is refused when made, on every engine of the backend and in every cell its
    worlds draw, naming the largest draw and the limit; an unlimited friction (ODE's) is kept."""
    info = registry().problem("nao-walk")
    refused = (
        ({"friction": 3.0, "noise": 1.0}, r"noise 1 draws .* up to 3\.664 .*mujoco .*at most 3\);"),
        ({"backend": "pybullet+mujoco+ode", "noise": 10.0}, r"up to 7\.389 .*mujoco .*at most 3"),
        ({"backend": "pybullet", "friction": 1.5, "noise": 10.0}, r"pybullet .*at most 10"),
        ({"friction": 2.5, "friction_scale": 1.1, "noise": 0.5}, r"up to 3\.039 \(friction 2\.75"),
        # its own world draws up to 2.34, the 'friction x1.3' cell's up to 3.04
        ({"friction": 2.25, "noise": 0.2, "worlds": "standard"},
         r"in the cell 'friction x1\.3' that worlds=standard draws: noise 0\.2 draws .* 3\.044"),
    )  # fmt: skip
    for given, message in refused:
        with pytest.raises(ConfigError, match=message):
            info.factory(**given)
    draws = [Disturbance.draw(1.0, seed, 3.0, 1).friction for seed in range(200)]
    assert max(draws) > 3.0  # what was accepted before: draws past MuJoCo's limit
    for given in (
        {"friction": 3.0},  # no noise: the nominal friction alone
        {"friction": 2.4, "noise": 1.0},  # up to 2.93
        {"backend": "pybullet+ode", "noise": 10.0},  # up to 7.39, and unlimited on ODE
        {"backend": "ode", "friction": math.inf, "noise": 10.0},
    ):
        info.factory(**given).close()


def test_every_stored_gaits_settings_and_its_table_cells_stay_accepted() -> None:
    """No stored gait's settings, on its own engines or in any cell of the standard table
    (which scales the friction and sets noises of its own), are refused by the noise's
    friction limit or the push's rounding."""
    info = registry().problem("nao-walk")
    for name in stored_gait_names():
        params = load_gait(name)["problem_params"]
        info.factory(**resolve(info.params, params, name)).close()
        for engine in engine_names(params["backend"]):
            for cell in STANDARD_TABLE.cells:
                given = {**cell.apply({**params, **STANDARD_TABLE.common}), "backend": engine}
                info.factory(**resolve(info.params, given, f"{name} {cell.name}")).close()


def test_a_push_rounded_past_the_walking_phase_is_refused_up_front() -> None:
    """The push acts in the control step nearest to push_time: one that rounds to the end of
    the walking phase is refused when the problem is made (it failed every evaluation), and one
    that rounds to its last step is accepted."""
    info = registry().problem("nao-walk")
    for push_time in (14.995, 15.0, 2.99):
        with pytest.raises(ConfigError, match=r"push_time .* accepted from lock \(3\.0 s\) to "
                           r"14\.98 s, the last step's start"):  # fmt: skip
            info.factory(push=1.0, push_time=push_time)
    last = info.factory(push=1.0, push_time=14.985)
    try:
        assert last.runner_on("mujoco").run(SineGait()).time_walked == 12.0
    finally:
        last.close()


def test_an_unknown_fitness_is_refused_from_python_too() -> None:
    """NaoWalk built from Python checks fitness as the CLI does, instead of running the robust
    one under another name."""
    with pytest.raises(ConfigError, match=r"unknown fitness 'robustt'; accepted: robust, paper"):
        registry().problem("nao-walk").factory(fitness="robustt")


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_open_loop_replay_from_the_lock_state_retraces_the_episode(backend: str) -> None:
    """The lock state the runner keeps is where the walking phase starts: the episode's
    recorded targets replayed open-loop from it (benchmarks/episode_throughput.py's physics
    rate) end exactly where the episode did; from the state the episode left, they do not."""
    throughput = load_script("benchmarks/episode_throughput.py")
    episode = runner(backend)
    assert episode.lock_state is None  # no lock phase simulated yet
    recorded = episode.run(SineGait(), record=True)
    trajectory = recorded.trajectory
    robot = episode.backend.robot
    sequence = np.tile(robot.rest_angles, (len(trajectory["time"]), 1))
    for name in SineGait.joints:
        sequence[:, robot.joint_index(name)] = trajectory[f"{name}_target"]
    walked_to = [trajectory[axis][-1] for axis in "xyz"]
    after_walk = episode.backend.save_state()
    assert throughput.replay(episode.backend, after_walk, sequence).tolist() != walked_to
    assert throughput.replay(episode.backend, episode.lock_state, sequence).tolist() == walked_to
    episode.backend.close()


def test_motor_saturation_is_measured_over_the_steps_walked() -> None:
    """benchmarks/motor_model.py on a gait that falls (stride_mujoco on PyBullet, after 2.9 s):
    the torques are read on the walking steps up to the fall alone, not the lock phase's, and
    the speed is the episode's own (over the time walked, not the full 12 s)."""
    motors = load_script("benchmarks/motor_model.py")
    record = load_gait("stride_mujoco")
    problem = gait_problem(record["problem_params"], "pybullet")
    try:
        metrics = problem.evaluate(gait_vector(record), gait_seed(record)).metrics
    finally:
        problem.close()
    assert metrics["fell"] == 1.0 and metrics["time_walked"] < 12.0
    measured = motors.saturation("pybullet", "stride_mujoco")
    assert measured["speed"] == metrics["speed"]
    assert (measured["drift"], measured["fell"]) == (metrics["drift"], metrics["fell"])
    assert measured["steps"] == round(metrics["time_walked"] / 0.02)
    assert 0.0 <= measured["joint_steps_at_limit"] <= measured["steps_at_limit"] <= 1.0


@pytest.mark.parametrize(
    "benchmark",
    [
        ["benchmarks/noise_spread.py", "--seeds", "1", "--noise", "0"],
        ["benchmarks/motor_model.py", "--gaits", "hs_walk"],
    ],
)
def test_the_benchmarks_leave_out_an_engine_that_cannot_run_here(benchmark: list[str]) -> None:
    """Without libode8 (a library path that does not exist stands in for it) the benchmarks
    run on the other engines by default, instead of stopping at ODE with a ConfigError."""
    env = {**os.environ, LIBRARY_ENV: "libode-not-here.so.8"}
    done = subprocess.run(
        [sys.executable, *benchmark], cwd=REPO, env=env, capture_output=True, text=True,
        timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "mujoco" in done.stdout and "pybullet" in done.stdout
    assert "ode" not in re.findall(r"\w+", done.stdout)


def test_cli_run_then_replay_on_the_other_engine(tmp_path):
    """`metaopt run` on nao-walk, then `metaopt replay --backend pybullet` of its best gait."""
    done = metaopt_cli("run", "-o", "random", "-p", "nao-walk", "--budget", "3", "--seed", "5",
                       "--set", "duration=4", "--set", "lock=1", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "distance" in done.stdout and "tau1" in done.stdout
    replayed = metaopt_cli("replay", "1", "--backend", "pybullet", cwd=tmp_path)
    assert replayed.returncode == 0, replayed.stderr
    assert "backend=pybullet" in replayed.stdout and "distance" in replayed.stdout
    unknown = metaopt_cli("replay", "1", "--backend", "bullet", cwd=tmp_path)
    assert unknown.returncode == 2
    assert "unknown physics backend 'bullet'" in unknown.stderr and "mujoco" in unknown.stderr
