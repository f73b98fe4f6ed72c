"""Both engines build the same NAO from the one description, stand it still, and obey the
joint signs of shared/nao-model.md §3."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pybullet
import pytest

from metaopt.errors import ConfigError, EvaluationError
from metaopt.physics import PhysicsBackend, PhysicsSettings
from metaopt.plugins import registry
from metaopt_problems.nao_walk.robot import nao
from tests.engines import needs_ode

BACKENDS = ("mujoco", "pybullet")
#: Every engine, ODE where its library is installed (.ci/run installs it).
ENGINES = (*BACKENDS, pytest.param("ode", marks=needs_ode))


@pytest.fixture(params=ENGINES)
def backend(request: pytest.FixtureRequest) -> Iterator[PhysicsBackend]:
    engine = registry().physics_backend(request.param).factory(nao(), PhysicsSettings())
    yield engine
    engine.close()


def _model_mass_and_limits(engine: PhysicsBackend) -> tuple[float, dict, float]:
    """Total mass, joint limits by name and the height of all geometry, read from the engine."""
    if hasattr(engine, "model"):  # MuJoCo
        import mujoco

        model, data = engine.model, mujoco.MjData(engine.model)
        mujoco.mj_forward(model, data)  # construction pose: every qpos 0 but the root
        limits = {model.joint(j).name: tuple(model.jnt_range[j]) for j in range(1, model.njnt)}
        tops, bottoms = [], []
        for g in range(1, model.ngeom):
            reach = model.geom_rbound[g] if model.geom_type[g] != 6 else model.geom_size[g][2]
            tops.append(data.geom_xpos[g][2] + reach)
            bottoms.append(data.geom_xpos[g][2] - reach)
        return float(model.body_subtreemass[1]), limits, max(tops) - min(bottoms)
    client, body = engine._client, engine._robot  # PyBullet
    mass = pybullet.getDynamicsInfo(body, -1, physicsClientId=client)[0]
    limits, tops, bottoms = {}, [], []
    for j in range(pybullet.getNumJoints(body, physicsClientId=client)):
        info = pybullet.getJointInfo(body, j, physicsClientId=client)
        mass += pybullet.getDynamicsInfo(body, j, physicsClientId=client)[0]
        limits[info[1].decode()] = (info[8], info[9])
    for name, sign in (("head", 1), ("lfoot", -1), ("rfoot", -1)):
        link = engine._links[name]
        shape = pybullet.getCollisionShapeData(body, link, physicsClientId=client)[0]
        reach = shape[3][0] if shape[2] == pybullet.GEOM_SPHERE else shape[3][2] / 2
        (tops if sign > 0 else bottoms).append(engine.body_position(name)[2] + sign * reach)
    return mass, limits, max(tops) - min(bottoms)


def _construction_pose(engine: PhysicsBackend) -> None:
    if hasattr(engine, "_links"):  # PyBullet: every joint to 0 (arms forward)
        for joint in engine._joints:
            pybullet.resetJointState(engine._robot, joint, 0.0, physicsClientId=engine._client)


@pytest.mark.parametrize("name", BACKENDS)
def test_model_matches_the_description(name: str) -> None:
    robot = nao()
    backend = registry().physics_backend(name).factory(robot, PhysicsSettings())
    _construction_pose(backend)
    mass, limits, height = _model_mass_and_limits(backend)
    assert mass == pytest.approx(4.6071, abs=1e-6)
    assert list(limits) == list(robot.joint_names)
    for h in robot.hinges:
        assert limits[h.name] == pytest.approx((h.lower, h.upper), abs=1e-9)
    assert height == pytest.approx(0.605, abs=1e-6)
    backend.close()


def _tilt_degrees(engine: PhysicsBackend) -> float:
    return math.degrees(math.acos(min(1.0, float(engine.root_rotation()[2, 2]))))


def test_stands_three_seconds_with_all_joints_held(backend: PhysicsBackend) -> None:
    rest = backend.robot.rest_angles
    tilts = []
    for _ in range(150):
        backend.step(rest)
        tilts.append(_tilt_degrees(backend))
    assert backend.time() == pytest.approx(3.0)
    assert max(tilts[50:]) < 2.0
    assert backend.root_position()[2] == pytest.approx(0.385, abs=0.003)
    assert np.abs(backend.joint_angles() - rest).max() < math.radians(1)
    assert sum(backend.contact_forces()) == pytest.approx(4.6071 * 9.81, rel=0.1)


@pytest.mark.parametrize(
    ("joint", "degrees", "forward"),
    [("llj3", 30, True), ("llj4", -30, False), ("rlj3", 30, True)],
)
def test_joint_signs_move_the_foot_as_specified(
    backend: PhysicsBackend, joint: str, degrees: float, forward: bool
) -> None:
    """Hip pitch +30° swings the foot forward, knee -30° swings it back (torso frame)."""
    foot = "lfoot" if joint.startswith("l") else "rfoot"

    def foot_ahead() -> float:
        offset = backend.body_position(foot) - backend.root_position()
        return float((backend.root_rotation().T @ offset)[0])

    start = foot_ahead()
    targets = backend.robot.rest_angles
    targets[backend.robot.joint_index(joint)] = math.radians(degrees)
    for _ in range(25):
        backend.step(targets)
    moved = foot_ahead() - start
    angle = backend.joint_angles()[backend.robot.joint_index(joint)]
    assert angle == pytest.approx(math.radians(degrees), abs=math.radians(3))
    assert (moved > 0.03) if forward else (moved < -0.01)


def test_restore_state_is_exact_where_claimed(backend: PhysicsBackend) -> None:
    assert backend.restores_exactly
    targets = backend.robot.rest_angles
    targets[backend.robot.joint_index("llj3")] = 0.3
    for _ in range(5):
        backend.step(targets)
    saved = backend.save_state()
    runs = []
    for _ in range(2):
        backend.restore_state(saved)
        for _ in range(20):
            backend.step(targets)
        runs.append((backend.joint_angles().copy(), backend.root_position().copy()))
    assert backend.time() == pytest.approx(0.5)
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


def test_non_finite_targets_are_an_evaluation_error(backend: PhysicsBackend) -> None:
    targets = backend.robot.rest_angles
    targets[3] = math.nan
    with pytest.raises(EvaluationError, match="not finite"):
        backend.step(targets)


def test_unknown_backend_lists_the_installed_ones() -> None:
    with pytest.raises(ConfigError, match="Installed: mujoco, ode, pybullet"):
        registry().physics_backend("bullet")
