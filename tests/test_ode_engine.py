"""The ode engine: the robot ODE holds is the description's, it stands as in rcssserver3d, its
contacts slip as the server's do, its motor and read-backs behave as ODE's hinge motor, its
state restores exactly, nao-walk episodes on it are deterministic, and where libode is missing
it says how to install it."""

from __future__ import annotations

import importlib.metadata
import math
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from metaopt.physics import PhysicsBackend, PhysicsSettings, engine_version
from metaopt.plugins import registry
from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.robot import nao
from metaopt_problems.physics.ode_binding import LIBRARY_ENV, PARAM_HI_STOP, PARAM_LO_STOP
from tests.engines import needs_ode

WEIGHT = 4.6071 * 9.81


def _ode(**settings: float) -> PhysicsBackend:
    return registry().physics_backend("ode").factory(nao(), PhysicsSettings(**settings))


@pytest.fixture
def engine() -> Iterator[PhysicsBackend]:
    backend = _ode(friction=math.inf)
    yield backend
    backend.close()


def _stand(backend: PhysicsBackend, steps: int) -> None:
    rest = backend.robot.rest_angles
    for _ in range(steps):
        backend.step(rest)


@needs_ode
def test_the_bodies_and_joints_ode_holds_are_the_description(engine) -> None:
    robot = engine.robot
    for body in robot.bodies:
        assert engine.body_mass(body.name) == body.mass
        assert engine.body_inertia(body.name) == pytest.approx(body.inertia, rel=1e-12)
    assert sum(engine.body_mass(b.name) for b in robot.bodies) == pytest.approx(4.6071, abs=1e-9)
    get = engine._ode.dJointGetHingeParam
    limits = [(get(j, PARAM_LO_STOP), get(j, PARAM_HI_STOP)) for j in engine._joints]
    assert limits == [(h.lower, h.upper) for h in robot.hinges]
    assert engine.joint_angles() == pytest.approx(robot.rest_angles, abs=1e-12)
    assert engine.ground_friction() == math.inf
    engine.set_ground_friction(0.7)
    assert engine.ground_friction() == 0.7


@needs_ode
def test_it_stands_as_in_the_server_feet_carrying_the_weight(engine) -> None:
    """Dropped from 0.40 m with every joint held: the torso settles at 0.384 m (the sole at
    0.385 m below it, sunk about 1 mm into the soft contacts), upright."""
    _stand(engine, 150)
    assert engine.time() == pytest.approx(3.0)
    assert engine.root_position()[2] == pytest.approx(0.3839, abs=5e-4)
    assert math.degrees(math.acos(engine.root_rotation()[2, 2])) < 0.01
    assert np.abs(engine.joint_angles() - engine.robot.rest_angles).max() < 1e-5
    forces = engine.contact_forces()
    assert sum(forces) == pytest.approx(WEIGHT, rel=1e-3)
    assert forces[0] == pytest.approx(forces[1], rel=0.01)


@needs_ode
@pytest.mark.parametrize("body", ["lfoot", "torso"])
def test_a_pushed_robot_slides_at_the_force_dependent_slip(engine, body) -> None:
    """With mu = inf nothing limits friction, but each contact point yields at 5e-3 m/s per N
    it carries; 8 points (4 per foot) share a steady sideways push, so the robot slides at
    5e-3 / 8 m/s per N of it (drag, 0.23 N per m/s over all bodies, is negligible)."""
    _stand(engine, 50)
    force = 4.0
    engine.apply_force(body, (0.0, force, 0.0))
    _stand(engine, 25)  # the slide reaches its steady speed
    start = engine.body_position("lfoot")[1]
    _stand(engine, 50)
    speed = engine.body_position("lfoot")[1] - start  # over 1 s
    assert speed / force == pytest.approx(5e-3 / 8, rel=0.01)


@needs_ode
def test_without_slip_infinite_friction_holds_the_feet() -> None:
    backend = _ode(friction=math.inf, slip=0.0)
    _stand(backend, 50)
    start = backend.body_position("lfoot")[1]
    backend.apply_force("lfoot", (0.0, 4.0, 0.0))
    _stand(backend, 50)
    assert abs(backend.body_position("lfoot")[1] - start) < 1e-5
    backend.close()


@needs_ode
@pytest.mark.parametrize("ratio", [0.9, 1.5])
def test_a_finite_friction_is_a_coulomb_coefficient(ratio: float) -> None:
    """friction = 0.1 (dContactApprox1, no slip): a sideways push on a foot below mu·m·g
    holds the robot; above it the robot slides with acceleration (F - mu·m·g) / m."""
    mu = 0.1
    backend = _ode(friction=mu, slip=0.0)
    assert backend.ground_friction() == mu
    _stand(backend, 50)
    start = backend.body_position("lfoot")[1]
    backend.apply_force("lfoot", (0.0, ratio * mu * WEIGHT, 0.0))
    _stand(backend, 50)  # 1 s
    moved = backend.body_position("lfoot")[1] - start
    backend.close()
    if ratio < 1:
        assert abs(moved) < 1e-4
    else:
        assert moved == pytest.approx(0.5 * (ratio - 1) * mu * WEIGHT / 4.6071, rel=0.02)


@needs_ode
def test_the_motor_reaches_its_command_within_the_step_or_saturates_at_10_nm(engine) -> None:
    """A free arm reaches the clamped velocity command (6.1395 rad/s) in one 20 ms step; a hip
    swinging the leg of a standing robot pushes at exactly FMax = 10 N·m, read back from
    ODE's joint feedback."""
    _stand(engine, 50)
    robot = engine.robot
    hip, arm = robot.joint_index("llj3"), robot.joint_index("laj1")
    targets = robot.rest_angles
    targets[hip], targets[arm] = 1.2, 0.0
    engine.step(targets)
    assert engine.joint_velocities()[arm] == pytest.approx(6.1395, rel=1e-3)
    assert engine.joint_torques()[hip] == pytest.approx(10.0, abs=1e-9)
    assert np.abs(engine.joint_torques()).max() <= 10.0 + 1e-9


def _walk(backend: PhysicsBackend, steps: int) -> np.ndarray:
    """Swing the left hip for some steps; every body's pose and velocities after them."""
    targets = backend.robot.rest_angles
    for k in range(steps):
        targets[backend.robot.joint_index("llj3")] = 0.4 * math.sin(k / 5)
        backend.step(targets)
    return backend.save_state()[0]


@needs_ode
def test_restore_continues_exactly_as_the_run_it_was_saved_from(engine) -> None:
    """The lock-phase cache relies on it: restore + the same steps = the live run, every bit
    (the first episode continues live, later ones from the restored state)."""
    _walk(engine, 60)
    engine.apply_force("torso", (0.0, 3.0, 0.0))
    saved = engine.save_state()
    live = _walk(engine, 40)
    engine.apply_force("torso", (0.0, 0.0, 0.0))
    engine.restore_state(saved)
    assert np.array_equal(_walk(engine, 40), live)  # the force came back with the state


@needs_ode
def test_reset_is_a_fresh_engine(engine) -> None:
    engine.apply_force("torso", (0.0, 3.0, 0.0))
    _walk(engine, 30)
    engine.reset()
    fresh = _ode(friction=math.inf)
    assert np.array_equal(_walk(engine, 30), _walk(fresh, 30))
    fresh.close()


@needs_ode
def test_a_nao_walk_episode_on_ode_is_deterministic() -> None:
    """Same candidate and seed (noise on) -> the same episode, in two separate problems."""
    info = registry().problem("nao-walk")
    results = []
    for _ in range(2):
        problem = info.factory(backend="ode", duration=3.0, lock=1.0, noise=1.0)
        x = (problem.space.lower + problem.space.upper) / 2
        results.append(problem.evaluate(x, seed=7))
        assert problem.physics.friction == math.inf
        assert problem.runner.backend.ground_friction() == math.inf  # as ODE's contacts hold it
        problem.close()
    assert results[0] == results[1]
    assert results[0].metrics["time_walked"] > 0


def test_without_libode_the_engine_says_how_to_install_it(tmp_path: Path) -> None:
    """Pointing METAOPT_ODE_LIBRARY at a library that does not exist stands in for a machine
    without libode8: `metaopt list` marks ode unavailable, choosing it is one line, exit 2."""
    env = {**os.environ, LIBRARY_ENV: "libode-not-here.so.8", "COLUMNS": "200"}
    command = [sys.executable, "-m", "metaopt"]
    listed = subprocess.run([*command, "list", "ode"], env=env, capture_output=True, text=True)
    assert listed.returncode == 0
    assert "unavailable: cannot load the ODE library" in listed.stdout
    assert "apt-get install libode8" in listed.stdout
    chosen = subprocess.run(
        [*command, "run", "-o", "random", "-p", "nao-walk", "--budget", "1",
         "--set", "backend=ode", "--db", str(tmp_path / "runs.db")],
        env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert chosen.returncode == 2
    lines = chosen.stderr.strip().splitlines()
    assert len(lines) == 1 and "physics backend 'ode' is unavailable" in lines[0]
    assert lines[0].endswith("install it with: apt-get install libode8")
    with RunStore(tmp_path / "runs.db") as store:
        assert store.runs() == []


@needs_ode
def test_every_engine_says_which_build_runs() -> None:
    """ODE's C API has no version call: its version is the library file the linker loaded, so
    a stored gait's exact replay is compared only on the build it was recorded with."""
    backends = registry().physics_backends
    versions = {name: engine_version(backends[name]) for name in ("mujoco", "pybullet", "ode")}
    assert re.fullmatch(r"libode\.so\.\d+(\.\d+)*", versions["ode"]), versions
    assert versions["mujoco"] == importlib.metadata.version("mujoco")
    assert versions["pybullet"] == importlib.metadata.version("pybullet")
