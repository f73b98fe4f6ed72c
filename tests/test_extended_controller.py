"""The extended, stride, steered and balanced CPG controllers: their spaces, rhythm, joint
targets, the steered one's heading feedback on an engine, the balanced one's stepping strategy,
and nao-walk's switch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from metaopt import ConfigError
from metaopt.assessment.robustness import summarize
from metaopt.warm_start import fitted_start
from metaopt_problems.nao_walk.episode import Sensors
from metaopt_problems.nao_walk.extended import (
    BALANCED_PARAM_NAMES,
    PARAM_NAMES,
    RAMP_S,
    STEER_LIMIT,
    STEERED_PARAM_NAMES,
    STRIDE_PARAM_NAMES,
    BalancedCpg,
    ExtendedCpg,
    SteeredCpg,
    StrideCpg,
    balanced_space,
    extended_space,
    steered_space,
    stride_space,
)
from metaopt_problems.nao_walk.plugin import NaoWalk
from metaopt_problems.nao_walk.robot import nao
from metaopt_problems.nao_walk.stored_gaits import (
    gait_vector,
    load_gait,
    replay_over_seeds,
    with_steering,
)
from tests.engines import needs_ode

LIMITS = {hinge.name: (hinge.lower, hinge.upper) for hinge in nao().hinges}
STEP = 0.02


def params(controller: type[ExtendedCpg] = ExtendedCpg, **given: float) -> list[float]:
    """A mid-range parameter vector of `controller` with some values replaced."""
    space = SPACES[controller]()
    middle = dict(zip(space.names, (space.lower + space.upper) / 2))
    middle.update(sway_phase=0.0, pitch_gain=0.0, roll_gain=0.0, feedback=0.0)
    middle.update(given)
    return [middle[name] for name in controller.param_names]


SPACES = {ExtendedCpg: extended_space, StrideCpg: stride_space, SteeredCpg: steered_space,
          BalancedCpg: balanced_space}  # fmt: skip


def drive(controller: ExtendedCpg, steps: int, sensors: Sensors | None = None) -> np.ndarray:
    """Targets of `steps` control steps, shape (steps, 10)."""
    sensors = sensors or Sensors()
    rows = []
    for step in range(steps):
        sensors.time = step * STEP
        rows.append(controller.act(sensors))
    return np.array(rows)


def test_space_is_named_and_bounded():
    space = extended_space()
    assert space.names == PARAM_NAMES and len(PARAM_NAMES) == 11
    assert np.all(space.lower < space.upper)
    assert ExtendedCpg.joints == (
        "llj2", "llj3", "llj4", "llj5", "llj6", "rlj2", "rlj3", "rlj4", "rlj5", "rlj6",
    )  # fmt: skip


@pytest.mark.parametrize("period", [0.2, 0.3, 0.55, 0.8, 1.2])
def test_every_candidate_oscillates_with_its_period_in_anti_phase(period):
    targets = drive(ExtendedCpg(params(period=period, hip_bias=0.0), LIMITS), 1500)[500:]
    left_hip, right_hip = targets[:, 1], targets[:, 6]
    np.testing.assert_allclose(left_hip, -right_hip, atol=1e-12)  # anti-phase about bias 0
    rising = np.flatnonzero((left_hip[:-1] < 0) & (left_hip[1:] >= 0))
    measured = np.diff(rising).mean() * STEP
    assert measured == pytest.approx(period, rel=0.05)  # whole control steps: 1 in 15 to 60
    swing = math.radians(params()[PARAM_NAMES.index("hip_swing")])
    assert left_hip.max() == pytest.approx(swing, rel=0.02)


def test_stride_space_adds_knee_phase_and_push_off_to_the_extended_one():
    space = stride_space()
    assert space.names == STRIDE_PARAM_NAMES == (*PARAM_NAMES, "knee_phase", "push", "push_phase")
    assert np.all(space.lower < space.upper)
    extended = extended_space()
    wider = np.array([2.0 if name == "feedback" else 1.0 for name in PARAM_NAMES])
    np.testing.assert_array_equal(space.lower[: len(PARAM_NAMES)], wider * extended.lower)
    np.testing.assert_array_equal(space.upper[: len(PARAM_NAMES)], wider * extended.upper)


@pytest.mark.parametrize("controller", [ExtendedCpg, StrideCpg, SteeredCpg])
def test_targets_stay_in_the_joint_limits(controller):
    rng = np.random.default_rng(3)
    for x in SPACES[controller]().sample(rng, 40):
        sensors = Sensors(
            roll=rng.uniform(-0.5, 0.5), pitch=rng.uniform(-0.5, 0.5), yaw=rng.uniform(-3, 3)
        )
        targets = drive(controller(x, LIMITS), 200, sensors)
        for column, joint in enumerate(controller.joints):
            lower, upper = LIMITS[joint]
            assert np.all((lower <= targets[:, column]) & (targets[:, column] <= upper)), joint


def test_extended_keeps_the_feet_flat_when_unclipped():
    space = extended_space()
    rng = np.random.default_rng(3)
    for x in space.sample(rng, 40):
        controller = ExtendedCpg(x, LIMITS)
        sensors = Sensors(roll=rng.uniform(-0.5, 0.5), pitch=rng.uniform(-0.5, 0.5))
        targets = drive(controller, 200, sensors)
        for column, joint in enumerate(ExtendedCpg.joints):
            lower, upper = LIMITS[joint]
            assert np.all((lower <= targets[:, column]) & (targets[:, column] <= upper)), joint
        values = dict(zip(PARAM_NAMES, x))
        extra = math.radians(values["ankle_bias"]) + values["pitch_gain"] * sensors.pitch
        for first in (0, 5):
            roll, hip, knee, ankle, ankle_roll = targets[-1, first : first + 5]
            ankle_lower, ankle_upper = LIMITS[ExtendedCpg.joints[first + 3]]
            if ankle_lower < ankle < ankle_upper:  # not clipped: the sum is the offset
                assert hip + knee + ankle == pytest.approx(extra, abs=1e-9)
            roll_lower, roll_upper = LIMITS[ExtendedCpg.joints[first]]
            if roll_lower < roll < roll_upper and roll_lower < -ankle_roll < roll_upper:
                assert ankle_roll == pytest.approx(-roll, abs=1e-12)


def test_the_gait_grows_from_standing_over_the_ramp():
    x = params(hip_bias=20.0, knee_bias=40.0, sway=10.0)
    targets = drive(ExtendedCpg(x, LIMITS), round(3 * RAMP_S / STEP))
    ramp_steps = round(RAMP_S / STEP)
    assert np.abs(targets[0]).max() < 2.5 * np.abs(targets[ramp_steps:]).max() / ramp_steps
    assert targets[ramp_steps:, 1].mean() == pytest.approx(math.radians(20.0), rel=0.1)


def test_deterministic_and_reset_restarts():
    controller = ExtendedCpg(params(feedback=1.0), LIMITS)
    sensors = Sensors(left_hip=0.1, right_hip=-0.05)
    first = drive(controller, 100, sensors)
    controller.reset()
    np.testing.assert_array_equal(drive(controller, 100, sensors), first)


def test_bad_parameters_are_config_errors():
    with pytest.raises(ConfigError, match="takes 11 parameters"):
        ExtendedCpg([1.0] * 10, LIMITS)
    with pytest.raises(ConfigError, match="not finite: hip_swing"):
        ExtendedCpg(params(hip_swing=math.nan), LIMITS)
    with pytest.raises(ConfigError, match="stride controller takes 14 parameters"):
        StrideCpg(params(), LIMITS)
    with pytest.raises(ConfigError, match="unknown controller 'fast'; accepted: paper, extended, "
                       "stride, steered, balanced"):  # fmt: skip
        NaoWalk(controller="fast")


def test_nao_walk_switches_controller_and_space():
    paper, extended = NaoWalk(duration=4.0, lock=1.0), NaoWalk(controller="extended",
                                                             duration=4.0, lock=1.0)  # fmt: skip
    assert len(paper.space.names) == 10 and extended.space.names == PARAM_NAMES
    stride = NaoWalk(controller="stride", duration=4.0, lock=1.0)
    assert stride.space.names == STRIDE_PARAM_NAMES
    assert stride.evaluate(np.array(params(StrideCpg)), 0).metrics["time_walked"] > 0
    x = np.array(params())
    first = extended.evaluate(x, 0)
    assert first == extended.evaluate(x, 0)
    assert first.metrics["time_walked"] > 0
    figures = extended.figures(x, 0)
    assert set(figures) == {"joint_angles", "drift", "torso_height"}


@pytest.mark.parametrize("knee_phase", [0.0, 180.0])
def test_stride_lifts_the_knee_at_its_phase_and_pushes_off_behind(knee_phase):
    x = params(StrideCpg, hip_bias=0.0, hip_swing=20.0, knee_bias=20.0, knee_lift=30.0,
               ankle_bias=0.0, knee_phase=knee_phase, push=15.0, push_phase=0.0)  # fmt: skip
    targets = drive(StrideCpg(x, LIMITS), 400)[round(RAMP_S / STEP) :]
    for first in (0, 5):
        hip, knee, ankle = targets[:, first + 1], targets[:, first + 2], targets[:, first + 3]
        s = hip / math.radians(20.0)  # this leg's swing signal, in [-1, 1]
        forward = s if knee_phase == 0.0 else -s
        lift = math.radians(20.0) + math.radians(30.0) * np.maximum(0.0, forward)
        np.testing.assert_allclose(knee, -lift, atol=1e-12)
        lower, upper = LIMITS[StrideCpg.joints[first + 3]]
        free = (lower < ankle) & (ankle < upper)
        assert free.mean() > 0.5
        # from foot-parallel, the ankle follows push x s: toes down (-) while the leg is behind
        np.testing.assert_allclose((hip + knee + ankle)[free], math.radians(15.0) * s[free],
                                   atol=1e-12)  # fmt: skip
        assert np.any(s[free] < -0.5) and np.any(s[free] > 0.5)


def test_stride_without_knee_lift_and_push_is_the_extended_controller():
    sensors = Sensors(left_hip=0.1, right_hip=-0.05, roll=0.1, pitch=-0.1)
    stride = StrideCpg(params(StrideCpg, knee_lift=0.0, push=0.0, feedback=1.0), LIMITS)
    extended = ExtendedCpg(params(knee_lift=0.0, feedback=1.0), LIMITS)
    np.testing.assert_array_equal(drive(stride, 300, sensors), drive(extended, 300, sensors))


def test_steered_space_adds_the_heading_gain_to_the_stride_one():
    space = steered_space()
    assert space.names == STEERED_PARAM_NAMES == (*STRIDE_PARAM_NAMES, "steer")
    stride = stride_space()
    np.testing.assert_array_equal(space.lower[:-1], stride.lower)
    np.testing.assert_array_equal(space.upper[:-1], stride.upper)
    assert (space.lower[-1], space.upper[-1]) == (0.0, 4.0)


@pytest.mark.parametrize(("steer", "yaw"), [(0.0, 0.3), (2.0, 0.0)])
def test_steered_on_its_heading_is_the_stride_controller(steer, yaw):
    sensors = Sensors(left_hip=0.1, right_hip=-0.05, roll=0.1, pitch=-0.1, yaw=yaw)
    x = params(SteeredCpg, feedback=1.0, steer=steer)
    steered, stride = SteeredCpg(x, LIMITS), StrideCpg(x[:-1], LIMITS)
    np.testing.assert_array_equal(drive(steered, 300, sensors), drive(stride, 300, sensors))


@pytest.mark.parametrize(("yaw", "asymmetry"), [(0.1, 0.2), (-0.1, -0.2), (1.0, STEER_LIMIT)])
def test_turned_left_the_left_leg_steps_further(yaw, asymmetry):
    """u = steer x yaw within the limit: the left hip swings by (1 + u), the right by (1 - u)."""
    x = params(SteeredCpg, hip_bias=0.0, hip_swing=15.0, steer=2.0)  # unclipped at x 1.5
    straight = drive(SteeredCpg(x, LIMITS), 300)
    turned = drive(SteeredCpg(x, LIMITS), 300, Sensors(yaw=yaw))
    np.testing.assert_allclose(turned[:, 1], (1 + asymmetry) * straight[:, 1], atol=1e-12)
    np.testing.assert_allclose(turned[:, 6], (1 - asymmetry) * straight[:, 6], atol=1e-12)


def test_balanced_space_adds_the_stepping_gains_to_the_steered_one():
    space = balanced_space()
    assert space.names == BALANCED_PARAM_NAMES == (*STEERED_PARAM_NAMES, "place_gain",
                                                   "place_rate")  # fmt: skip
    steered = steered_space()
    np.testing.assert_array_equal(space.lower[:-2], steered.lower)
    np.testing.assert_array_equal(space.upper[:-2], steered.upper)
    assert np.all(space.lower[-2:] < 0.0) and np.all(space.upper[-2:] > 0.0)


def test_balanced_without_stepping_gains_is_the_steered_controller():
    sensors = Sensors(left_hip=0.1, right_hip=-0.05, roll=0.1, pitch=-0.1, yaw=0.2)
    x = params(BalancedCpg, feedback=1.0, steer=1.0, place_gain=0.0, place_rate=0.0)
    balanced, steered = BalancedCpg(x, LIMITS), SteeredCpg(x[:-2], LIMITS)
    np.testing.assert_array_equal(drive(balanced, 300, sensors), drive(steered, 300, sensors))


@pytest.mark.parametrize(("larger", "smaller"), [(SteeredCpg, StrideCpg),
                                                 (BalancedCpg, SteeredCpg),
                                                 (BalancedCpg, StrideCpg)])  # fmt: skip
def test_a_smaller_controllers_gait_at_the_neutral_values_drives_the_same_targets(larger, smaller):
    """The neutral values a controller's space declares are where it is the smaller
    controller exactly: a smaller one's gait, fitted into the larger space as `run --start-from`
    fits it, drives the very same targets (with the torso off level and turned)."""
    sensors = Sensors(left_hip=0.1, right_hip=-0.05, roll=0.1, pitch=-0.1, yaw=0.2)
    x = params(smaller, feedback=1.0)
    fitted = fitted_start("gait", SPACES[smaller]().names, x, SPACES[larger]())
    assert len(fitted) > len(x)
    np.testing.assert_array_equal(drive(larger(fitted, LIMITS), 300, sensors),
                                  drive(smaller(x, LIMITS), 300, sensors))  # fmt: skip


def test_a_torso_pitched_forward_moves_both_hips_by_the_gain_and_the_rate():
    """Hip targets move by place_gain x pitch + place_rate x pitch rate (per control step),
    the ankles by the opposite (the feet stay parallel to the torso); knees and rolls don't."""
    x = params(BalancedCpg, hip_bias=0.0, hip_swing=10.0, place_gain=0.5, place_rate=0.1)
    still = drive(BalancedCpg(x, LIMITS), 200)
    balanced = BalancedCpg(x, LIMITS)
    sensors, rows = Sensors(), []
    for step in range(200):  # pitch 0 until step 100, then 0.1 rad from then on
        sensors.time, sensors.pitch = step * STEP, 0.1 if step >= 100 else 0.0
        rows.append(balanced.act(sensors))
    moved = np.array(rows) - still
    expected = np.zeros(200)
    expected[100:] = 0.5 * 0.1
    expected[100] += 0.1 * 0.1 / STEP  # the step the pitch changed: its rate
    for hip, knee, ankle in ((1, 2, 3), (6, 7, 8)):
        np.testing.assert_allclose(moved[:, hip], expected, atol=1e-12)
        np.testing.assert_allclose(moved[:, ankle], -expected, atol=1e-12)
        np.testing.assert_array_equal(moved[:, knee], 0.0)
    np.testing.assert_array_equal(moved[:, [0, 4, 5, 9]], 0.0)
    balanced.reset()  # the rate starts again from the first pitch sensed, not from the last 0.1
    assert balanced.act(Sensors(pitch=0.2))[1] == pytest.approx(
        BalancedCpg(x, LIMITS).act(Sensors())[1] + 0.5 * 0.2, abs=1e-12
    )


def test_the_runner_senses_the_torso_heading_since_walking_began():
    """Sensors.yaw is the torso's heading turned since the lock phase ended, as the engine
    holds it when the controller is asked (no latency)."""
    problem = NaoWalk(controller="stride", backend="mujoco", duration=6.0, noise=0.5)
    backend = problem.runner.backend
    stride = problem.gait(np.array(params(StrideCpg, sway=5.0)))
    sensed: list[float] = []
    held: list[float] = []

    class Recording:
        joints = stride.joints

        def reset(self) -> None:
            stride.reset()

        def act(self, sensors: Sensors):
            sensed.append(sensors.yaw)
            rotation = backend.root_rotation()
            held.append(math.atan2(rotation[1, 0], rotation[0, 0]))
            return stride.act(sensors)

    problem.runner.run(Recording(), disturbance=problem.disturbance(3))
    np.testing.assert_allclose(sensed, np.array(held) - held[0], atol=1e-12)
    assert np.abs(sensed).max() > 0.01  # it did turn


@pytest.mark.parametrize("engine", ["mujoco", pytest.param("ode", marks=needs_ode)])
def test_heading_feedback_keeps_the_robust_walk_on_its_line(engine):
    """The stored robust walk (a stride gait) wanders by tens of degrees on ODE over noise
    seeds; with the steered controller's feedback at gain 1 the median |drift| over the same
    seeds shrinks several times, without a fall."""
    record = load_gait("robust_walk")
    stride = replay_over_seeds(record, engine, 6, 0.1)
    steered = replay_over_seeds(with_steering(record, 1.0), engine, 6, 0.1)
    assert not any(sample["fell"] for sample in steered)
    drift = {name: summarize(samples, "|drift|")[0]
             for name, samples in (("stride", stride), ("steered", steered))}  # fmt: skip
    assert drift["steered"] < 0.15
    assert drift["steered"] < drift["stride"] / 2


def test_only_a_stride_gait_can_be_steered():
    steered = with_steering(load_gait("robust_walk"), 1.5)
    assert steered["problem_params"]["controller"] == "steered"
    np.testing.assert_array_equal(gait_vector(steered)[:-1], gait_vector(load_gait("robust_walk")))
    assert gait_vector(steered)[-1] == 1.5
    with pytest.raises(ValueError, match="only a stride gait can be steered, not a paper one"):
        with_steering(load_gait("hs_walk"), 1.0)
