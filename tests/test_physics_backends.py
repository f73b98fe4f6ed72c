"""Both engines build the same NAO from the one description, stand it still, and obey the
joint signs of shared/nao-model.md §3."""

from __future__ import annotations

import dataclasses
import gc
import math
from collections.abc import Iterator

import numpy as np
import pybullet
import pytest

from metaopt.errors import ConfigError, EvaluationError
from metaopt.physics import (
    UNSTABLE_HEIGHT,
    Body,
    Hinge,
    PhysicsBackend,
    PhysicsSettings,
    RobotDescription,
    Shape,
    check_root_height,
    format_vector,
)
from metaopt.physics.agreement import engine, measure_friction
from metaopt.plugins import registry
from metaopt_problems.nao_walk.robot import nao
from tests.engines import needs_ode

BACKENDS = ("mujoco", "pybullet")
#: Every engine, ODE where its library is installed (.ci/run installs it).
ENGINES = (*BACKENDS, pytest.param("ode", marks=needs_ode))
#: Why ODE's elbow does not read a steady 5 N·m under the 100 N load below.
ODE_ONE_STEP_LOAD = (
    "the 100 N also loads the shoulder roll with 14 N·m, over its 10 N·m motor, and at ODE's "
    "one 20 ms step the arm swings within the step: the elbow reads 3.6 and 6.5 N·m on "
    "alternate steps (mean 5.0)"
)


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
    try:
        _construction_pose(backend)
        mass, limits, height = _model_mass_and_limits(backend)
        assert mass == pytest.approx(4.6071, abs=1e-6)
        assert list(limits) == list(robot.joint_names)
        for h in robot.hinges:
            assert limits[h.name] == pytest.approx((h.lower, h.upper), abs=1e-9)
        assert height == pytest.approx(0.605, abs=1e-6)
    finally:
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


def _mean_support_while_stepping(backend: PhysicsBackend) -> float:
    """The feet's summed contact force, one reading per control period, averaged over 4 s of
    stepping in place (each leg lifted 25° in turn, four steps a second) after 1 s standing."""
    robot, period = backend.robot, backend.settings.control_period
    rest = robot.rest_angles
    for _ in range(50):  # settle standing
        backend.step(rest)
    hips = [robot.joint_index(name) for name in ("llj3", "rlj3")]
    knees = [robot.joint_index(name) for name in ("llj4", "rlj4")]
    ankles = [robot.joint_index(name) for name in ("llj5", "rlj5")]
    total, steps = 0.0, round(4.0 / period)
    for k in range(steps):
        phase = 2 * math.pi * 2.0 * k * period
        targets = rest.copy()
        for leg, sign in enumerate((1.0, -1.0)):
            lift = math.radians(25) * max(0.0, sign * math.sin(phase))
            targets[hips[leg]] += lift
            targets[knees[leg]] -= 2 * lift
            targets[ankles[leg]] += lift
        backend.step(targets)
        total += float(np.sum(backend.contact_forces()))
    assert _tilt_degrees(backend) < 20  # still upright: the ground carried it throughout
    return total / steps


def test_contact_forces_are_the_control_periods_mean_so_they_carry_the_weight(
    backend: PhysicsBackend,
) -> None:
    """Stepping in place, the feet's reported normal forces average to the robot's weight
    within 1 %: the ground carries it on average, and a period's mean force is its impulse
    over the period. The last physics step's force instead read 2.9 % (MuJoCo, 16 steps a
    period) and 2.4 % (PyBullet, 2) heavy here, and 9-21 % heavy during the stored walks,
    where the load chatters between steps; ODE takes one step a period, the same either way."""
    weight = backend.robot.total_mass * 9.81
    assert _mean_support_while_stepping(backend) == pytest.approx(weight, rel=0.01)


@needs_ode
def test_ode_reports_the_mean_over_several_physics_steps_too() -> None:
    """At substeps=2 (not the server's one step a period) ODE's reading is the mean of its
    two steps' forces, and it carries the weight as the other engines do."""
    sim = registry().physics_backend("ode").factory(nao(), PhysicsSettings(substeps=2))
    try:
        weight = sim.robot.total_mass * 9.81
        assert _mean_support_while_stepping(sim) == pytest.approx(weight, rel=0.01)
    finally:
        sim.close()


def test_mujoco_touch_sensors_hold_every_contact_of_the_feet() -> None:
    """MuJoCo reads each foot's force with a touch sensor (summing the contacts inside a site
    around the foot): rocking from foot to foot, it equals the sum of the normal forces of
    every contact of that foot, from mj_contactForce."""
    import mujoco

    sim = registry().physics_backend("mujoco").factory(nao(), PhysicsSettings())
    model, data = sim.model, sim.data
    feet = [model.body(name).id for name in sim.robot.contact_bodies]
    roll = [sim.robot.joint_index(name) for name in ("llj2", "rlj2")]
    force, checked = np.zeros(6), 0
    for k in range(100):
        targets = sim.robot.rest_angles.copy()
        targets[roll] += math.radians(8) * math.sin(2 * math.pi * k / 25)
        sim.step(targets)
        expected = np.zeros(len(feet))
        for i in range(data.ncon):
            bodies = model.geom_bodyid[data.contact[i].geom]
            for f, foot in enumerate(feet):
                if foot in bodies:
                    mujoco.mj_contactForce(model, data, i, force)
                    expected[f] += force[0]
        assert data.sensordata[: len(feet)] == pytest.approx(expected, rel=1e-9, abs=1e-9)
        checked += int((expected > 1).sum())
    assert checked > 80  # each foot bore load in about half of the 100 periods
    sim.close()


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


def test_mass_and_inertia_read_back_equal_the_description(backend: PhysicsBackend) -> None:
    for body in backend.robot.bodies:
        assert backend.body_mass(body.name) == pytest.approx(body.mass, rel=1e-9)
        assert backend.body_inertia(body.name) == pytest.approx(body.inertia, rel=1e-9)


def test_joint_velocities_read_back(backend: PhysicsBackend) -> None:
    """A swinging arm's measured velocity matches its angle's change over a control period
    (its motor, far below its limit, keeps the commanded speed within one)."""
    robot = backend.robot
    arm = robot.joint_index("laj1")
    targets = robot.rest_angles
    targets[arm] += 0.6
    for _ in range(3):
        before = backend.joint_angles()[arm]
        backend.step(targets)
    swing = (backend.joint_angles()[arm] - before) / backend.settings.control_period
    assert backend.joint_velocities()[arm] == pytest.approx(swing, rel=0.05)
    assert backend.joint_velocities()[arm] > 1.0


def test_joint_torques_read_back_a_known_load(
    backend: PhysicsBackend, request: pytest.FixtureRequest
) -> None:
    """Equal and opposite forces of 100 N on the left lower arm (its centre 5 cm from the elbow
    axis) and on the torso load the elbow alone with 5 N·m about z, below the torque limit:
    the elbow's motor holds it with 5 N·m (5 %: the arm sags a little, changing the lever)."""
    if request.node.callspec.params["backend"] == "ode":
        request.applymarker(pytest.mark.xfail(strict=True, reason=ODE_ONE_STEP_LOAD))
    robot = backend.robot
    for _ in range(10):
        backend.step(robot.rest_angles)
    elbow = robot.joint_index("laj4")
    assert abs(backend.joint_torques()[elbow]) < 0.1  # gravity is along its axis
    backend.apply_force("llowerarm", (0.0, -100.0, 0.0))
    backend.apply_force(robot.root.name, (0.0, 100.0, 0.0))
    for _ in range(10):
        backend.step(robot.rest_angles)
    assert backend.joint_torques()[elbow] == pytest.approx(5.0, rel=0.05)


def _center_of_mass(engine: PhysicsBackend) -> np.ndarray:
    bodies = engine.robot.bodies
    weighted = sum(engine.body_mass(b.name) * engine.body_position(b.name) for b in bodies)
    return weighted / sum(engine.body_mass(b.name) for b in bodies)


def test_apply_force_changes_the_momentum_by_force_times_time(backend: PhysicsBackend) -> None:
    """In flight (launched upward, nothing touches the ground), a horizontal force F on the
    torso for 0.1 s leaves the robot coasting with momentum F * 0.1 s. The coast carries no
    horizontal force, so the centre of mass's displacement over it measures the momentum
    exactly but for the engines' joint-constraint drift (measured < 3e-4 of F * t): 1 %."""
    robot, period = backend.robot, backend.settings.control_period
    backend.push_root((0.0, 0.0, 3.0))  # about 0.6 s in the air
    backend.step(robot.rest_angles)
    force = (5.0, -2.0, 0.0)
    backend.apply_force(robot.root.name, force)
    pushed = backend.save_state()
    backend.apply_force(robot.root.name, (0.0, 0.0, 0.0))
    backend.restore_state(pushed)  # brings the force back
    for _ in range(5):
        backend.step(robot.rest_angles)
    backend.apply_force(robot.root.name, (0.0, 0.0, 0.0))
    start = _center_of_mass(backend)
    for _ in range(5):
        backend.step(robot.rest_angles)
    assert not backend.contact_forces().any()
    momentum = robot.total_mass * (_center_of_mass(backend) - start) / (5 * period)
    assert momentum[:2] == pytest.approx(np.array(force[:2]) * 5 * period, rel=0.01, abs=1e-3)


def test_ground_friction_reads_back_the_coefficient_set(backend: PhysicsBackend) -> None:
    assert backend.ground_friction() == pytest.approx(1.0)
    backend.step(backend.robot.rest_angles)
    backend.set_ground_friction(0.7)
    assert backend.ground_friction() == pytest.approx(0.7)
    backend.reset()
    assert backend.ground_friction() == pytest.approx(backend.settings.friction)


def test_every_pybullet_link_has_friction_one_and_the_ground_the_setting() -> None:
    """Read from PyBullet itself: the pair's coefficient is the product of the two bodies'."""
    engine = registry().physics_backend("pybullet").factory(nao(), PhysicsSettings(friction=0.8))
    try:
        client = engine._client
        links = [pybullet.getDynamicsInfo(engine._robot, link, physicsClientId=client)[1]
                 for link in engine._links.values()]  # fmt: skip
        assert links == [1.0] * len(nao().bodies)
        assert pybullet.getDynamicsInfo(engine._plane, -1, physicsClientId=client)[1] == 0.8
        engine.set_ground_friction(20.0)
        assert engine.ground_friction() == 10.0  # Bullet clamps the pair's coefficient
    finally:
        engine.close()


#: ODE's friction pyramid (dContactApprox1) under dWorldStep is not exact Coulomb friction.
ODE_APPROX1 = pytest.mark.xfail(
    strict=True,
    reason="measured: at mu = 1, feet pushed with 1.5 mu·m·g are held by 67.8 N of friction "
    "on a 45.2 N normal force (dWorldStep's LCP bounds the friction rows approximately); "
    "exact Coulomb sliding at mu = 0.1 (docs/nao-walk.md, ODE)",
)


@pytest.mark.parametrize("name", [*BACKENDS, pytest.param("ode", marks=[needs_ode, ODE_APPROX1])])
@pytest.mark.parametrize("mu", [0.5, 1.0])
def test_the_feet_slide_at_the_force_friction_predicts(name: str, mu: float) -> None:
    """Pushed 15 % beyond μ·m·g the feet slide as friction μ predicts; at 90 % they hold."""
    with engine(name, friction=mu) as sim:
        read, slide, creep = measure_friction(sim)
    assert read.measured == pytest.approx(mu)
    assert slide.agrees, slide.describe()
    assert creep.agrees, creep.describe()


def _steps_then_saved(sim: PhysicsBackend, steps: int = 5) -> object:
    """The state after steps control periods at rest, saved."""
    for _ in range(steps):
        sim.step(sim.robot.rest_angles)
    return sim.save_state()


#: The instability every engine raises in the control period after the first five (one text).
UNSTABLE_AT_0_12 = r"^(MuJoCo|PyBullet|ODE) simulation became unstable at t = 0\.120 s$"


@pytest.mark.parametrize("name", ENGINES)
def test_a_nan_force_is_an_evaluation_error_every_time(name: str) -> None:
    """From the same saved state three times over, a NaN force on the torso raises each time,
    naming the period's end. MuJoCo's automatic reset (mj_resetData) left its bad-qacc counter
    at 1, so only the first raised and the others walked on from the reset pose; ODE's
    dWorldStep aborted the whole process on the NaN load."""
    with engine(name) as sim:
        saved = _steps_then_saved(sim)
        for _ in range(3):
            sim.restore_state(saved)
            sim.apply_force(sim.robot.root.name, (math.nan, 0.0, 0.0))
            with pytest.raises(EvaluationError, match=UNSTABLE_AT_0_12):
                sim.step(sim.robot.rest_angles)


@pytest.mark.parametrize("name", ENGINES)
def test_a_huge_push_is_an_evaluation_error_every_time(name: str) -> None:
    """A push to 1e300 m/s raises every time; MuJoCo flags it as a bad qvel, which it did not
    check at all (only bad qacc)."""
    with engine(name) as sim:
        saved = _steps_then_saved(sim)
        for _ in range(3):
            sim.restore_state(saved)
            sim.push_root((1e300, 0.0, 0.0))
            with pytest.raises(EvaluationError, match=UNSTABLE_AT_0_12):
                sim.step(sim.robot.rest_angles)


def test_check_root_height_raises_one_text_naming_the_engine() -> None:
    """The shared instability check of the engines that do not flag it themselves."""
    check_root_height("ODE", 0.385, 0.5)
    check_root_height("ODE", -UNSTABLE_HEIGHT, 0.5)
    for height in (math.nan, math.inf, -math.inf, UNSTABLE_HEIGHT * 1.01):
        with pytest.raises(EvaluationError, match=r"^PyBullet simulation .* t = 0\.120 s$"):
            check_root_height("PyBullet", height, 0.12)
    assert format_vector((0.5, -1e-12, 1 / 3)) == "0.5 -1e-12 0.3333333333"


def test_an_unknown_contact_body_is_refused_by_the_description() -> None:
    """A misspelt contact body fails where the robot is described, not differently in each
    engine (an MJCF error in MuJoCo, a KeyError in PyBullet and ODE)."""
    with pytest.raises(ValueError, match="contact body 'lfot' is not one of the bodies"):
        dataclasses.replace(nao(), contact_bodies=("lfot", "rfoot"))


def test_hinges_with_one_name_are_refused_by_the_description() -> None:
    """Two hinges of one name are refused up front (PyBullet's URDF import segfaults on them)."""
    robot = nao()
    hinges = (robot.hinges[0], dataclasses.replace(robot.hinges[1], name=robot.hinges[0].name))
    with pytest.raises(ValueError, match="hinges must have unique names"):
        dataclasses.replace(robot, hinges=hinges + robot.hinges[2:])


def test_joint_angles_cannot_be_written_through(backend: PhysicsBackend) -> None:
    """joint_angles is at most a live read-only view: PyBullet's was the writable buffer its
    servo reads, so a caller's write steered the robot."""
    for _ in range(2):
        with pytest.raises(ValueError, match="read-only"):
            backend.joint_angles()[0] = 1.0
        backend.step(backend.robot.rest_angles)


def _connected_pybullet_clients() -> set[int]:
    """The PyBullet client ids connected in this process now."""
    gc.collect()  # backends nobody closed disconnect as they are collected
    return {i for i in range(64) if pybullet.isConnected(physicsClientId=i)}


def test_a_failed_pybullet_construction_disconnects_its_client() -> None:
    """A failure after connecting (here the ground friction reset() sets, which PyBullet
    refuses) disconnects the new client before the error propagates."""
    before = _connected_pybullet_clients()
    with pytest.raises(TypeError):
        registry().physics_backend("pybullet").factory(nao(), PhysicsSettings(friction=None))
    assert _connected_pybullet_clients() == before


def test_closing_a_pybullet_backend_twice_leaves_other_clients_alone() -> None:
    """PyBullet reuses a freed client id: a second close (or one from the garbage collector)
    of a closed backend must not disconnect the client a newer backend got."""
    factory = registry().physics_backend("pybullet").factory
    first = factory(nao(), PhysicsSettings())
    first.save_state()
    first.close()
    second = factory(nao(), PhysicsSettings())
    try:
        first.close()
        del first
        second.step(second.robot.rest_angles)
        assert second.time() == pytest.approx(0.02)
    finally:
        second.close()


def _capsule_footed_robot() -> RobotDescription:
    """A torso on one capsule foot: a contact body that is not a box."""
    torso = Body("torso", None, Shape("box", (0.1, 0.1, 0.2)), 1.0, (0.0, 0.0, 0.0), True)
    foot = Body("foot", "torso", Shape("capsule", (0.02, 0.1)), 0.2, (0.0, 0.0, -0.2), True)
    ankle = Hinge("ankle", "torso", "foot", (0.0, 0.0, -0.1), (0.0, 1.0, 0.0), -1.0, 1.0)
    return RobotDescription("capsule", (torso, foot), (ankle,), ("foot",), 0.33)


@pytest.mark.parametrize("robot", [nao(), _capsule_footed_robot()], ids=["nao", "capsule"])
def test_mujoco_touch_sites_are_their_geoms_plus_the_margin(robot: RobotDescription) -> None:
    """Each contact body's touch site is its geom grown by TOUCH_MARGIN all round; a capsule's
    site was given the full cylinder length where MuJoCo takes half, twice too long."""
    from metaopt_problems.physics.mujoco_engine import TOUCH_MARGIN, MujocoBackend

    sim = MujocoBackend(robot, PhysicsSettings())
    try:
        model = sim.model
        for name in robot.contact_bodies:
            geom = int(np.flatnonzero(model.geom_bodyid == model.body(name).id)[0])
            site = model.site("touch_" + name).id
            assert model.site_type[site] == model.geom_type[geom]
            used = {"box": 3, "sphere": 1, "capsule": 2}[robot.body(name).shape.kind]
            assert model.site_size[site][:used] == pytest.approx(
                model.geom_size[geom][:used] + TOUCH_MARGIN, abs=1e-12
            )
    finally:
        sim.close()
