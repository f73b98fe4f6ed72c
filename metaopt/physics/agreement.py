"""The engine agreement suite: what a physics engine actually simulates, measured from it.

Every figure is read back from the engine through PhysicsBackend (positions, contact forces,
joint velocities and torques, the masses it holds) while the robot is pushed, dropped, loaded
or left standing, never taken from the settings the engine was given. Each figure comes with
the value physics predicts and a tolerance; ``metaopt.testing.engine_checks`` turns them into
checks, benchmarks/engine_agreement.py prints them side by side for every installed engine.

The measurements use the NAO of the nao-walk problem (the robot every engine of this project
simulates): its feet are pushed, its left elbow is loaded, its head turned.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from metaopt.physics import BackendInfo, PhysicsBackend, PhysicsSettings, RobotDescription
from metaopt.plugins import registry

#: Gravity every engine of the project is built with, m/s² (the free fall measures it back).
GRAVITY = 9.81
#: Control periods the robot stands still before a measurement starts (contacts settle).
SETTLE_STEPS = 25
#: The friction measurement's pushes last this many control periods (0.3 s).
PUSH_STEPS = 15
#: Sliding is measured at this multiple of the force the friction coefficient predicts; holding
#: at HOLD_FRACTION of it.
SLIDE_FRACTION, HOLD_FRACTION = 1.15, 0.9
#: The free fall: the robot is thrown straight up to this height (m) above where it stood.
DROP_HEIGHT = 0.3
#: Velocity commanded to the head's yaw joint for the motor response, rad/s (below the joint
#: speed limit, and far below what 10 N·m gives the head in a period).
COMMANDED_SPEED = 3.0
#: The load on the left elbow: equal and opposite forces (N) on the lower arm, whose centre is
#: 5 cm from the elbow's axis, and on the torso: 20 N·m about the axis, twice the motor limit.
OVERLOAD = 400.0


@dataclass(frozen=True)
class Figure:
    """One measured figure, what physics predicts for it and how far it may be off."""

    label: str
    unit: str
    measured: float
    expected: float
    tolerance: float
    #: Why the tolerance is what it is (printed with a breach).
    why: str

    @property
    def agrees(self) -> bool:
        """True when the measured figure is within tolerance of the prediction."""
        if math.isinf(self.expected):
            return math.isinf(self.measured)
        return abs(self.measured - self.expected) <= self.tolerance

    def describe(self) -> str:
        """One line: label, measured, expected ± tolerance, unit."""
        return (
            f"{self.label}: measured {self.measured:.4g} {self.unit}, expected "
            f"{self.expected:.4g} ± {self.tolerance:.2g} ({self.why})"
        )


Measurement = Callable[[PhysicsBackend], list[Figure]]


def default_robot() -> RobotDescription:
    """The NAO every engine of the project simulates (the nao-walk problem's robot)."""
    from metaopt_problems.nao_walk.robot import nao

    return nao()


@contextmanager
def engine(
    backend: str | BackendInfo, robot: RobotDescription | None = None, **settings: float
) -> Iterator[PhysicsBackend]:
    """A fresh simulation of robot (the NAO by default) on the named engine, closed after use,
    at the engine's default friction unless settings name one."""
    info = registry().physics_backend(backend) if isinstance(backend, str) else backend
    settings = {"friction": info.default_friction, **settings}
    simulation = info.factory(robot or default_robot(), PhysicsSettings(**settings))
    try:
        yield simulation
    finally:
        simulation.close()


def _stand(sim: PhysicsBackend, steps: int = SETTLE_STEPS) -> None:
    for _ in range(steps):
        sim.step(sim.robot.rest_angles)


def _weight(sim: PhysicsBackend) -> float:
    return sum(sim.body_mass(b.name) for b in sim.robot.bodies) * GRAVITY


def _feet_x(sim: PhysicsBackend) -> float:
    return float(np.mean([sim.body_position(f)[0] for f in sim.robot.contact_bodies]))


def _push_feet(sim: PhysicsBackend, force: float, steps: int) -> float:
    """Push the feet forward with force (N, shared equally) for steps periods: how far they
    travel, m."""
    feet = sim.robot.contact_bodies
    start = _feet_x(sim)
    for foot in feet:
        sim.apply_force(foot, (force / len(feet), 0.0, 0.0))
    _stand(sim, steps)
    for foot in feet:
        sim.apply_force(foot, (0.0, 0.0, 0.0))
    return _feet_x(sim) - start


def measure_mass(sim: PhysicsBackend) -> list[Figure]:
    """Total mass and the largest relative inertia error, as the engine holds them."""
    robot = sim.robot
    inertia_error = max(
        abs(held - given) / given
        for body in robot.bodies
        for held, given in zip(sim.body_inertia(body.name), body.inertia, strict=True)
    )
    why = "the engine holds the description's numbers"
    return [
        Figure(
            "total mass",
            "kg",
            sum(sim.body_mass(b.name) for b in robot.bodies),
            robot.total_mass,
            1e-6 * robot.total_mass,
            why,
        ),
        Figure("largest inertia error", "relative", inertia_error, 0.0, 1e-6, why),
    ]


def measure_friction(sim: PhysicsBackend) -> list[Figure]:
    """Foot–ground friction: the coefficient read back; the coefficient the feet's slide
    measures (pushed for 0.3 s at SLIDE_FRACTION of μ·m·g, the feet accelerate at
    (F - μ_slide·m·g)/m); how far they creep held at HOLD_FRACTION of it. Where the engine's
    friction is unlimited (force-dependent slip), the slip speed per newton instead."""
    _stand(sim)
    mu, weight = sim.ground_friction(), _weight(sim)
    figures = [
        Figure(
            "ground friction read back",
            "",
            mu,
            mu if math.isinf(mu) else sim.settings.friction,
            1e-9,
            "the engine's contacts use the coefficient it was given (unlimited: reported)",
        )
    ]
    settled = sim.save_state()
    seconds = PUSH_STEPS * sim.settings.control_period
    if math.isinf(mu):
        speeds = []
        for share in (0.25, 0.5):
            sim.restore_state(settled)
            speeds.append(_push_feet(sim, share * weight, PUSH_STEPS) / seconds / (share * weight))
        return [
            *figures,
            Figure(
                "slip speed per newton",
                "m/s/N",
                speeds[1],
                speeds[0],
                0.25 * speeds[0],
                "slip grows in proportion to the force: the same per newton at 1/4 and "
                "1/2 of the weight (25 %: the feet's contacts share it unevenly)",
            ),
        ]
    force = SLIDE_FRACTION * mu * weight
    travelled = _push_feet(sim, force, PUSH_STEPS)
    slide_mu = (force / weight - 2 * travelled / seconds**2 / GRAVITY) / mu
    sim.restore_state(settled)
    crept = _push_feet(sim, HOLD_FRACTION * mu * weight, PUSH_STEPS)
    excess = (SLIDE_FRACTION - 1) * mu * GRAVITY * seconds**2 / 2
    return [
        *figures,
        Figure(
            "sliding friction / read-back μ",
            "",
            slide_mu,
            1.0,
            0.1,
            "10 %: the feet need a few periods to break loose (measured 2 % in the "
            "slide) and the upper body lags",
        ),
        Figure(
            f"creep at {HOLD_FRACTION} μ·m·g in {seconds:g} s / slide at {SLIDE_FRACTION}",
            "",
            crept / excess,
            0.0,
            0.25,
            "below the limit the feet hold: soft contacts creep a little (under a "
            "quarter of the slide 15 % above the limit)",
        ),
    ]


def measure_standing(sim: PhysicsBackend) -> list[Figure]:
    """Mean ground-contact force on the feet over the second half of 1 s of standing, as a
    fraction of the weight."""
    _stand(sim)
    forces = []
    for _ in range(SETTLE_STEPS):
        sim.step(sim.robot.rest_angles)
        forces.append(float(np.sum(sim.contact_forces())))
    return [
        Figure(
            "standing contact force / weight",
            "",
            float(np.mean(forces)) / _weight(sim),
            1.0,
            0.02,
            "2 %: the robot stands still; what remains is contact jitter",
        )
    ]


def measure_free_fall(sim: PhysicsBackend) -> list[Figure]:
    """Thrown straight up to DROP_HEIGHT above where it stood, the robot lands (its torso back
    at its standing height, interpolated between periods) after 2·√(2h/g)."""
    _stand(sim)
    period = sim.settings.control_period
    start = float(sim.root_position()[2])
    sim.push_root((0.0, 0.0, math.sqrt(2 * GRAVITY * DROP_HEIGHT)))
    height, steps = start, 0
    while steps < 200:
        previous = height
        sim.step(sim.robot.rest_angles)
        steps += 1
        height = float(sim.root_position()[2])
        if steps > 1 and height <= start < previous:
            break
    landed = (steps - 1 + (previous - start) / (previous - height)) * period
    expected = 2 * math.sqrt(2 * DROP_HEIGHT / GRAVITY)
    return [
        Figure(
            "flight time / 2·√(2h/g)",
            "",
            landed / expected,
            1.0,
            0.05,
            "5 %: semi-implicit Euler lands one physics step early, up to 20 ms (ODE's one "
            "step per period) of the 0.49 s flight",
        )
    ]


def measure_motor(sim: PhysicsBackend) -> list[Figure]:
    """The servo motor: the head's yaw joint, commanded COMMANDED_SPEED, turns at it after one
    control period; the left elbow overloaded (OVERLOAD) reads the torque limit."""
    robot, settings = sim.robot, sim.settings
    _stand(sim)
    head = robot.joint_index("hj1")
    targets = robot.rest_angles
    targets[head] = sim.joint_angles()[head] + COMMANDED_SPEED / settings.servo_gain
    sim.step(targets)
    reached = sim.joint_velocities()[head] / COMMANDED_SPEED
    elbow = robot.joint_index("laj4")
    sim.apply_force("llowerarm", (0.0, -OVERLOAD, 0.0))
    sim.apply_force(robot.root.name, (0.0, OVERLOAD, 0.0))
    sim.step(robot.rest_angles)
    torque = abs(float(sim.joint_torques()[elbow]))
    return [
        Figure(
            "head yaw speed after one period / command",
            "",
            reached,
            1.0,
            0.02,
            "a motor below its limit reaches its target within the period; 2 %: the "
            "servo's command changes as the joint turns",
        ),
        Figure(
            "overloaded elbow's torque",
            "N·m",
            torque,
            settings.max_joint_torque,
            0.01 * settings.max_joint_torque,
            "the motor pushes with exactly its limit",
        ),
    ]


#: Every measurement by name: the function that makes it on an engine (its docstring says what).
MEASUREMENTS: dict[str, Measurement] = {
    "mass_and_inertia": measure_mass,
    "ground_friction": measure_friction,
    "standing_contact_force": measure_standing,
    "free_fall": measure_free_fall,
    "motor_response": measure_motor,
}


def measure(backend: str | BackendInfo, name: str) -> list[Figure]:
    """One measurement's figures on a fresh simulation of the NAO on backend."""
    with engine(backend) as sim:
        return MEASUREMENTS[name](sim)
