"""nao-walk's perturbations do what they say on every engine: a push changes the robot's
momentum by its impulse, a mass scale is the mass and inertia the engine holds, latency delays
what the gait senses by exactly k steps, flight is the footfalls' share; and a lock phase
saved for one model is never restored into another; worlds=standard draws a cell of the
standard table per evaluation (world_cells: of the named cells), worlds=pushes a push (and with
world_cells a cell as well), and a candidate's figures and video show the world its evaluation
walked."""

from __future__ import annotations

import math
import re
import sys

import numpy as np
import pytest

from metaopt import ConfigError
from metaopt.executors.base import EvaluationTask, evaluate_task, release_problems
from metaopt.params import resolve
from metaopt.physics import PhysicsSettings
from metaopt.plugins import registry
from metaopt_problems.nao_walk.episode import (
    FLIGHT_ALLOWED,
    EpisodeRunner,
    EpisodeSettings,
    Push,
    Sensors,
    SineGait,
)
from metaopt_problems.nao_walk.footfalls import footfalls
from metaopt_problems.nao_walk.robot import nao
from metaopt_problems.nao_walk.robustness import PUSH_IMPULSE, STANDARD_TABLE
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait
from tests.conftest import load_script

#: every installed engine (an engine plugin added later is covered without a change here)
BACKENDS = tuple(registry().physics_backends)
SHORT = {"duration": 4.0, "lock": 1.0}


def _params(backend: str, **given: object) -> dict:
    info = registry().problem("nao-walk")
    return resolve(info.params, {"backend": backend, **given}, "nao-walk")


def _problem(backend: str, **given: object):
    return registry().problem("nao-walk").factory(**_params(backend, **given))


def _evaluated(params: dict, x: np.ndarray, seed: int):
    """x's evaluation with seed by a fresh nao-walk built from resolved params, closed after."""
    problem = registry().problem("nao-walk").factory(**params)
    try:
        return problem.evaluate(x, seed)
    finally:
        problem.close()


class SensingSine(SineGait):
    """The sine gait (its targets ignore the sensors), keeping every reading it was given."""

    def reset(self) -> None:
        self.seen: list[tuple[float, ...]] = []

    def act(self, sensors: Sensors) -> tuple[float, ...]:
        self.seen.append((sensors.left_hip, sensors.right_hip, sensors.roll, sensors.pitch))
        return super().act(sensors)


def _runner(backend: str, friction: float = 1.0, **settings: object) -> EpisodeRunner:
    physics = PhysicsSettings(friction=friction)
    engine = registry().physics_backend(backend).factory(nao(), physics)
    return EpisodeRunner(engine, EpisodeSettings(**{**SHORT, **settings}))


def _centre_of_mass(runner: EpisodeRunner) -> np.ndarray:
    backend = runner.backend
    bodies = backend.robot.bodies
    weighted = sum(b.mass * backend.body_position(b.name) for b in bodies)
    return weighted / sum(b.mass for b in bodies)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("direction", [0.0, 90.0])
def test_a_push_changes_the_robots_momentum_by_its_impulse(backend: str, direction: float):
    # On (almost) frictionless ground the ground cannot take the impulse back: the centre of
    # mass's horizontal velocity must change by impulse / mass in the push's direction.
    impulse, period = 0.5, 0.02
    velocities = []
    for push in (None, Push(impulse, direction, 1.2)):
        runner = _runner(backend, friction=0.001, push=push)
        before = []

        def measure(steps: int, runner=runner, before=before) -> None:
            if steps in (12, 14):  # the push acts during step 11 (t = 1.2 s after 1 s lock)
                before.append(_centre_of_mass(runner))

        runner.run(SensingSine(), on_step=measure)
        velocities.append((before[1] - before[0])[:2] / (2 * period))
    change = velocities[1] - velocities[0]
    mass = nao().total_mass
    angle = math.radians(direction)
    expected = impulse / mass * np.array([math.cos(angle), math.sin(angle)])
    assert change == pytest.approx(expected, abs=0.05 * impulse / mass)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_push_changes_nothing_before_its_time_and_the_walk_after(backend: str) -> None:
    plain = _runner(backend).run(SineGait(), record=True).trajectory
    pushed = _runner(backend, push=Push(1.0, 0.0, 2.0)).run(SineGait(), record=True).trajectory
    step = round((2.0 - 1.0) / 0.02)  # rows before the push step's row are identical
    for name in ("x", "y", "z"):
        assert np.array_equal(plain[name][:step], pushed[name][:step])
    assert abs(pushed["x"][step + 5] - plain["x"][step + 5]) > 1e-3


@pytest.mark.parametrize("backend", BACKENDS)
def test_mass_scale_is_the_mass_and_inertia_the_engine_holds(backend: str) -> None:
    nominal, heavier = nao(), _problem(backend, mass_scale=1.1, **SHORT)
    try:
        engine = heavier.runner.backend
        for body in nominal.bodies:
            assert engine.body_mass(body.name) == pytest.approx(1.1 * body.mass, rel=1e-6)
            assert engine.body_inertia(body.name) == pytest.approx(
                [1.1 * moment for moment in body.inertia], rel=1e-6
            )
    finally:
        heavier.close()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("latency", [1, 3])
def test_latency_delays_what_the_gait_senses_by_exactly_k_steps(backend: str, latency: int):
    prompt, late = SensingSine(), SensingSine()
    first = _runner(backend).run(prompt, record=True)
    second = _runner(backend, latency=latency).run(late, record=True)
    # the sine gait ignores what it senses: the same walk, so the same measurements ...
    assert np.array_equal(first.trajectory["x"], second.trajectory["x"])
    assert len(late.seen) == len(prompt.seen) > 100
    # ... which the late gait reads k steps later (the first reading until then)
    assert late.seen[latency:] == prompt.seen[:-latency]
    assert late.seen[:latency] == [prompt.seen[0]] * latency


@pytest.mark.parametrize("backend", BACKENDS)
def test_flight_is_the_share_footfalls_measures(backend: str) -> None:
    runner = _runner(backend, feet=True)
    gait = SineGait(period=0.5, hip=0.3, knee=0.6)
    assert runner.run(gait).flight == footfalls(runner, gait).flight
    assert "flight" not in _runner(backend).run(gait).metrics()


@pytest.mark.parametrize("backend", BACKENDS)
def test_flight_penalty_costs_a_run_its_flight_above_the_allowed_share(backend: str) -> None:
    """The same running gait (stride_both flies about a third of the time) loses exactly
    flight_penalty x (flight - 5 %) with the penalty on, which turns the flight measurement on
    by itself; a gait that keeps a foot down (hs_walk) loses nothing. With flight_allowed 0
    every bit of flight is charged."""
    for name, flies in (("stride_both", True), ("hs_walk", False)):
        record = load_gait(name)
        params = {k: v for k, v in record["problem_params"].items() if k != "friction"}
        params.update(backend=backend, duration=7.0, lock=1.0)  # each engine's own friction
        free, penalised, strict = (
            _problem(**params, flight_penalty=p, flight_allowed=allowed)
            for p, allowed in ((0.0, FLIGHT_ALLOWED), (20.0, FLIGHT_ALLOWED), (20.0, 0.0))
        )
        try:
            x = gait_vector(record)
            plain, charged, all_charged = (p.evaluate(x, 0) for p in (free, penalised, strict))
        finally:
            for problem in (free, penalised, strict):
                problem.close()
        assert "flight" not in plain.metrics
        assert charged.metrics["distance"] == plain.metrics["distance"]  # the same episode
        flight = charged.metrics["flight"]
        excess = max(0.0, flight - FLIGHT_ALLOWED)
        assert (excess > 0.1) == flies, (name, flight)
        assert charged.fitness == pytest.approx(plain.fitness - 20.0 * excess, abs=1e-12)
        assert all_charged.fitness == pytest.approx(plain.fitness - 20.0 * flight, abs=1e-12)


def test_a_push_outside_the_walking_phase_is_refused() -> None:
    with pytest.raises(ConfigError, match="push_time"):
        _problem("mujoco", push=1.0, push_time=0.5, **SHORT)
    with pytest.raises(ConfigError, match="mass_scale"):
        _params("mujoco", mass_scale=0.0)
    with pytest.raises(ConfigError, match="latency"):
        _params("mujoco", latency=-1)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_lock_phase_is_only_restored_into_the_model_it_was_simulated_for(backend: str):
    # the key holds what the lock phase depends on, not what only the walking phase does
    def key(**given: object):
        problem = _problem(backend, **SHORT, **given)
        try:
            return problem.runner.lock_key
        finally:
            problem.close()

    nominal = key()
    for changed in ({"mass_scale": 1.1}, {"friction": 0.7}, {"servo_gain": 8.0}):
        assert key(**changed) != nominal, changed
    for walking_only in ({"push": 1.0, "push_time": 2.0}, {"latency": 1}, {"noise": 1.0}):
        assert key(**walking_only) == nominal, walking_only
    # a runner that saved the nominal lock phase, given a heavier robot's engine, simulates
    # the heavier robot's lock phase instead of restoring the nominal one
    x = gait_vector(load_gait())
    light, heavy = _problem(backend, **SHORT), _problem(backend, mass_scale=1.1, **SHORT)
    fresh = _problem(backend, mass_scale=1.1, **SHORT)
    try:
        light_metrics = light.evaluate(x, 0).metrics
        light.runner.backend = heavy.runner.backend
        swapped = light.evaluate(x, 0).metrics
        assert swapped == fresh.evaluate(x, 0).metrics != light_metrics
    finally:
        for problem in (light, heavy, fresh):
            problem.close()


def test_evaluations_in_one_process_never_share_a_perturbed_model() -> None:
    # the worker's problem cache is keyed by every parameter: the heavier robot evaluated
    # after the nominal one in one process equals it evaluated first
    factory = registry().problem("nao-walk").factory
    x = gait_vector(load_gait())

    def metrics(mass_scale: float) -> dict[str, float]:
        task = EvaluationTask(0, x, 0, factory, _params("mujoco", mass_scale=mass_scale, **SHORT))
        return evaluate_task(task).metrics

    try:
        heavy_first = metrics(1.1)
        release_problems()
        nominal = metrics(1.0)
        assert metrics(1.1) == heavy_first != nominal
    finally:
        release_problems()


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_perturbed_episode_is_deterministic(backend: str) -> None:
    given = {"mass_scale": 0.9, "push": 1.0, "push_time": 2.0, "latency": 1, "noise": 1.0}
    x = gait_vector(load_gait())
    first, second = _problem(backend, **given, **SHORT), _problem(backend, **given, **SHORT)
    try:
        assert first.evaluate(x, 5).metrics == second.evaluate(x, 5).metrics
        assert first.evaluate(x, 5).metrics == first.evaluate(x, 5).metrics
    finally:
        first.close()
        second.close()


def test_worlds_standard_walks_each_evaluation_in_a_seed_drawn_cell_of_the_table() -> None:
    world = {"duration": 7.0, "lock": 1.0, "noise": 0.1}
    sampled = _problem("mujoco", worlds="standard", **world)
    cells = [sampled.world_of(seed) for seed in range(400)]
    assert cells == [sampled.world_of(seed) for seed in range(400)]
    assert set(cells) == set(range(len(STANDARD_TABLE.cells)))
    x = gait_vector(load_gait())
    try:
        for name in ("mass x1.1", "push forward"):
            index = [c.name for c in STANDARD_TABLE.cells].index(name)
            seed = cells.index(index)
            expected = _evaluated(STANDARD_TABLE.cells[index].apply(_params("mujoco", **world)),
                                  x, seed)  # fmt: skip
            evaluation = sampled.evaluate(x, seed)
            assert evaluation.metrics == {**expected.metrics, "world": float(index)}
            assert evaluation.fitness == expected.fitness
    finally:
        sampled.close()
    with pytest.raises(ConfigError, match="push_time"):  # the push cells need 6 s
        _problem("mujoco", worlds="standard", **SHORT)


def test_worlds_pushes_walks_each_evaluation_with_a_seed_drawn_push_on_every_engine() -> None:
    # lock 1 s, 6 s walked: pushes from t = 3 s (2 s into the walk) to t = 4 s (3 s before the end)
    world = {"duration": 7.0, "lock": 1.0, "noise": 0.1}
    engines = "mujoco+pybullet"
    pushed, unpushed = _problem(engines, worlds="pushes", **world), _problem(engines, **world)
    pushes = [pushed.drawn_push(seed) for seed in range(200)]
    assert pushes == [pushed.drawn_push(seed) for seed in range(200)]
    assert {push.impulse for push in pushes} == {PUSH_IMPULSE}
    assert all(3.0 <= push.time <= 4.0 for push in pushes)
    quadrants = {math.floor(push.direction / 90.0) for push in pushes}
    assert quadrants == {-2, -1, 0, 1}  # any horizontal direction
    x = gait_vector(load_gait())
    try:
        for seed in (3, 4):
            push = pushed.drawn_push(seed)
            given = {"push": push.impulse, "push_direction": push.direction, "push_time": push.time}
            expected = _evaluated(_params(engines, **world, **given), x, seed)
            evaluation = pushed.evaluate(x, seed)
            drawn = {"push_direction": push.direction, "push_time": push.time}
            assert evaluation.metrics == {**expected.metrics, **drawn}
            assert evaluation.fitness == expected.fitness
            assert unpushed.evaluate(x, seed).metrics["distance"] != evaluation.metrics["distance"]
    finally:
        pushed.close()
        unpushed.close()
    with pytest.raises(ConfigError, match="leave push at 0"):
        _problem("mujoco", worlds="pushes", push=1.0, duration=7.0, lock=1.0)
    with pytest.raises(ConfigError, match="duration must be more than 6 s"):
        _problem("mujoco", worlds="pushes", **SHORT)


def test_world_cells_draws_each_evaluation_from_the_named_cells_pushed_or_not() -> None:
    world = {"duration": 7.0, "lock": 1.0, "noise": 0.1}
    names = ("nominal", "servo gain x1.2", "latency 1")
    table = [cell.name for cell in STANDARD_TABLE.cells]
    # every cell when empty, each seed drawing the cell it drew before world_cells existed
    every = _problem("mujoco", worlds="standard", **world)
    drawn = [int(np.random.default_rng((seed, 1)).integers(len(table))) for seed in range(300)]
    assert [every.world_of(seed) for seed in range(300)] == drawn
    restricted = _problem("mujoco", worlds="standard", world_cells=",".join(names), **world)
    assert {restricted.world_of(seed) for seed in range(300)} == {table.index(n) for n in names}
    # a cell named twice is drawn twice as often, each draw as if listed once in table order
    weighted = _problem("mujoco", worlds="standard", world_cells="latency 1,nominal,nominal",
                        **world)  # fmt: skip
    try:
        assert weighted.world_cells == (0, 0, table.index("latency 1"))
        shares = np.bincount([weighted.world_of(seed) for seed in range(3000)]) / 3000
        assert shares[0] == pytest.approx(2 / 3, abs=0.03)
    finally:
        weighted.close()
    engines = "mujoco+pybullet"
    pushed = _problem(engines, worlds="pushes", world_cells=" , ".join(names), **world)
    cells = [pushed.world_of(seed) for seed in range(300)]
    assert set(cells) == {table.index(name) for name in names}
    x = gait_vector(load_gait())
    try:
        for name, gain, latency in (("servo gain x1.2", 12.0, 0), ("latency 1", 10.0, 1)):
            seed = cells.index(table.index(name))
            walk, _, push = pushed.walked(seed)
            assert push is not None and push == pushed.drawn_push(seed)
            for engine in ("mujoco", "pybullet"):  # what the cell's runner and engine hold
                runner = walk.runner_on(engine)
                assert runner.backend.settings.servo_gain == pytest.approx(gain)
                assert runner.settings.latency == latency
            given = {"push": push.impulse, "push_direction": push.direction, "push_time": push.time}
            cell = STANDARD_TABLE.cells[table.index(name)]
            expected = _evaluated(cell.apply(_params(engines, **world, **given)), x, seed)
            evaluation = pushed.evaluate(x, seed)
            drawn_world = {"world": float(table.index(name)), "push_direction": push.direction,
                           "push_time": push.time}  # fmt: skip
            assert evaluation.metrics == {**expected.metrics, **drawn_world}
            assert evaluation.fitness == expected.fitness
    finally:
        for problem in (every, restricted, pushed):
            problem.close()
    with pytest.raises(ConfigError, match=r"world_cells: no perturbation 'servo x2'.*accepted"):
        _problem("mujoco", worlds="standard", world_cells="nominal,servo x2", **world)
    # a push cell keeps the table's own push; the other cells' evaluations get a drawn one
    table_push = _problem("mujoco", worlds="pushes", world_cells="nominal,push forward", **world)
    try:
        cells = [table_push.world_of(seed) for seed in range(40)]
        forward, nominal = cells.index(table.index("push forward")), cells.index(0)
        walk, _, push = table_push.walked(forward)
        assert push is None and walk.runner.settings.push == Push(PUSH_IMPULSE, 0.0, 6.0)
        cell = STANDARD_TABLE.cells[table.index("push forward")]
        expected = _evaluated(cell.apply(_params("mujoco", **world)), x, forward)
        evaluation = table_push.evaluate(x, forward)
        assert evaluation.metrics == {**expected.metrics, "world": float(cells[forward])}
        drawn = table_push.drawn_push(nominal)
        assert table_push.walked(nominal)[2] == drawn
        assert table_push.evaluate(x, nominal).metrics["push_time"] == drawn.time
    finally:
        table_push.close()
    with pytest.raises(ConfigError, match="with worlds=none leave it empty"):
        _problem("mujoco", world_cells="nominal", **world)


def test_cell_durations_walks_the_named_cells_longer_at_the_same_capped_speed() -> None:
    """A cell given its own duration walks that long on every engine (read back from its
    runners), capped at the same speed (engine_cap scaled by the walking time), and scores as
    that cell's problem built by hand; the other cells and the drawn push are unchanged."""
    world = {"duration": 7.0, "lock": 1.0, "noise": 0.1, "engine_cap": 1.0,
             "fitness": "progress"}  # fmt: skip
    engines = "mujoco+pybullet"
    table = [cell.name for cell in STANDARD_TABLE.cells]
    cells = "nominal,servo gain x1.2"
    longer = _problem(engines, worlds="pushes", world_cells=cells,
                      cell_durations="servo gain x1.2=9", **world)  # fmt: skip
    plain = _problem(engines, worlds="pushes", world_cells=cells, **world)
    x = gait_vector(load_gait())
    try:
        drawn = [longer.world_of(seed) for seed in range(40)]
        servo, nominal = drawn.index(table.index("servo gain x1.2")), drawn.index(0)
        walk, _, push = longer.walked(servo)
        assert walk.episode.duration == 9.0 and walk.engine_cap == pytest.approx(8 / 6)
        for engine in ("mujoco", "pybullet"):
            runner = walk.runner_on(engine)
            assert runner.walk_steps == round(8.0 / runner.backend.settings.control_period)
            assert runner.backend.settings.servo_gain == pytest.approx(12.0)
        assert push == plain.walked(servo)[2]  # drawn in the problem's own window
        given = {"push": push.impulse, "push_direction": push.direction, "push_time": push.time}
        by_hand = STANDARD_TABLE.cells[table.index("servo gain x1.2")].apply(
            _params(engines, **{**world, "duration": 9.0, "engine_cap": 8 / 6}, **given)
        )
        expected = _evaluated(by_hand, x, servo)
        evaluation = longer.evaluate(x, servo)
        assert evaluation.fitness == expected.fitness
        assert evaluation.metrics["time_walked"] == expected.metrics["time_walked"] > 6.0
        assert longer.evaluate(x, nominal) == plain.evaluate(x, nominal)
        assert longer.walked(nominal)[0].episode.duration == 7.0
    finally:
        longer.close()
        plain.close()
    for given, needle in (
        ("servo gain x1.2", "expected 'NAME=SECONDS'"),
        ("servo gain x1.2=1", "more than the lock (1 s)"),
        ("servo gain x1.2=inf", "expected 'NAME=SECONDS'"),
        ("latency 1=9", "'latency 1', which world_cells does not draw; accepted: nominal, servo"),
    ):
        with pytest.raises(ConfigError, match=re.escape(needle)):
            _problem("mujoco", worlds="pushes", world_cells=cells, cell_durations=given, **world)
    with pytest.raises(ConfigError, match=r"accepted: none \(set worlds and world_cells"):
        _problem("mujoco", cell_durations="nominal=9", **world)


def test_figures_and_video_show_the_world_an_evaluation_walked() -> None:
    world = {"duration": 7.0, "lock": 1.0, "noise": 0.1}
    x = gait_vector(load_gait())

    def outcome(metrics: dict) -> str:  # as the figures' titles write it
        return f"{metrics['distance']:.2f} m forward, drift {metrics['drift']:+.3f} m"

    def recorded_x(problem, seed: int) -> np.ndarray:  # the walk's x, once per filmed frame
        walk = problem.runner.run(
            problem.gait(x), record=True, disturbance=problem.disturbance(seed)
        )
        return walk.trajectory["x"][1::2]

    plain = _problem("mujoco", **world)
    try:
        for worlds, seed in (("standard", 1), ("pushes", 3)):
            problem = _problem("mujoco", worlds=worlds, **world)
            # the same world given as plain parameters: the seed's cell, or the seed's push
            if worlds == "standard":
                given = STANDARD_TABLE.cells[problem.world_of(seed)].apply(
                    _params("mujoco", **world)
                )
            else:
                push = problem.drawn_push(seed)
                given = _params("mujoco", **world, push=push.impulse,
                                push_direction=push.direction, push_time=push.time)  # fmt: skip
            direct = registry().problem("nao-walk").factory(**given)
            try:
                walked = outcome(problem.evaluate(x, seed).metrics)
                assert walked != outcome(plain.evaluate(x, seed).metrics)
                assert walked in problem.figures(x, seed)["joint_angles"]._suptitle.get_text()
                targets: list[tuple[float, float, float]] = []

                def render(width: int, height: int, target: tuple, targets=targets):
                    targets.append(target)
                    return np.zeros((height, width, 3), np.uint8)

                problem.walked(seed)[0].runner.backend.render = render  # a fake camera
                problem.video(x, seed, lambda image: None, (32, 24), 25)
                filmed = np.array(targets)[:, 0]
                np.testing.assert_array_equal(filmed, recorded_x(direct, seed))
                assert not np.array_equal(filmed, recorded_x(plain, seed))
            finally:
                problem.close()
                direct.close()
    finally:
        plain.close()


def test_heading_drift_replays_a_gait_searched_over_world_cells_in_the_nominal_world(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """scripts/heading_drift.py leaves out every sampling setting, world_cells included, as
    replay_over_seeds does: a gait searched over cells (throughput_walk) is replayed, not
    refused for world_cells without worlds."""
    drift = load_script("scripts/heading_drift.py")
    monkeypatch.setattr(drift, "ENGINES", ("mujoco",))  # one engine keeps it short
    monkeypatch.setattr(sys, "argv", ["heading_drift.py", "throughput_walk", "--seeds", "2"])
    drift.main()
    printed = capsys.readouterr().out
    assert "throughput_walk, 2 seeds at noise 0.1, nominal world" in printed
    assert re.search(r"^mujoco: \|yaw\| half-way max .* falls [012]$", printed, re.MULTILINE)
