"""A thin, typed interface between robot problems and physics engines.

A robot is described once (RobotDescription); each engine (MuJoCo, PyBullet, or one an outside
plugin adds through the ``metaopt_physics_backends`` hook) builds its own model from it and is
driven only through PhysicsBackend. Frame: x forward, y left, z up; SI units, angles in radians.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Shape:
    """A primitive solid: 'box' (size = full edge lengths x, y, z), 'sphere' (size = (radius,)),
    or 'capsule' along z (size = (radius, cylinder length))."""

    kind: str
    size: tuple[float, ...]


@dataclass(frozen=True)
class Body:
    """A rigid body: uniform solid of ``shape`` with ``mass``, centred at ``center`` (construction
    pose, relative to the root body's centre). ``collides`` False = mass carrier only."""

    name: str
    parent: str | None
    shape: Shape
    mass: float
    center: Vec3
    collides: bool


@dataclass(frozen=True)
class Hinge:
    """A revolute joint from ``parent`` to ``child`` about ``axis`` through ``anchor``
    (construction pose, root frame); angle 0 is the construction pose."""

    name: str
    parent: str
    child: str
    anchor: Vec3
    axis: Vec3
    lower: float
    upper: float


@dataclass(frozen=True)
class RobotDescription:
    """A floating-base robot: bodies (root first, parents before children) and hinges."""

    name: str
    bodies: tuple[Body, ...]
    hinges: tuple[Hinge, ...]
    #: Bodies whose ground-contact force is reported (e.g. the feet).
    contact_bodies: tuple[str, ...]
    #: Height of the root body's centre when placed at reset.
    start_height: float

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Hinge names in description order (the order of every joint vector)."""
        return tuple(h.name for h in self.hinges)

    @property
    def total_mass(self) -> float:
        """Sum of body masses, kg."""
        return sum(b.mass for b in self.bodies)


@dataclass(frozen=True)
class PhysicsSettings:
    """Engine-independent simulation settings (documented defaults in docs/nao-walk.md)."""

    control_period: float = 0.02
    substeps: int = 10
    servo_gain: float = 10.0
    max_joint_speed: float = 6.1395
    max_joint_torque: float = 10.0
    friction: float = 1.0

    @property
    def timestep(self) -> float:
        """Physics step = control_period / substeps."""
        return self.control_period / self.substeps


class PhysicsBackend(ABC):
    """One simulated robot on a flat ground plane, advanced one control period at a time.

    Joint vectors follow ``RobotDescription.joint_names``. Joints are velocity servos like
    rcssserver3d's: target velocity = servo_gain * (target - angle), clamped to
    ±max_joint_speed, torque at most max_joint_torque.
    """

    #: True when restore_state followed by the same steps reproduces a fresh run bit for bit.
    restores_exactly: bool = False

    @abstractmethod
    def reset(self) -> None:
        """Construction pose (all joints 0) with the root at start_height, velocities zero, t=0."""

    @abstractmethod
    def step(self, joint_targets: np.ndarray) -> None:
        """Servo every joint toward joint_targets (radians) for one control period."""

    @abstractmethod
    def joint_angles(self) -> np.ndarray:
        """Measured joint angles, radians."""

    @abstractmethod
    def root_position(self) -> np.ndarray:
        """Root body (torso) centre in the world, metres, shape (3,)."""

    @abstractmethod
    def root_rotation(self) -> np.ndarray:
        """Root body orientation as a 3x3 rotation matrix (body to world)."""

    @abstractmethod
    def contact_forces(self) -> np.ndarray:
        """Normal ground-contact force on each of contact_bodies, newtons."""

    @abstractmethod
    def time(self) -> float:
        """Simulated seconds since reset."""

    @abstractmethod
    def save_state(self) -> Any:
        """An opaque snapshot of the full simulation state."""

    @abstractmethod
    def restore_state(self, state: Any) -> None:
        """Return to a snapshot taken by save_state in this same backend instance."""

    def close(self) -> None:  # noqa: B027 - optional
        """Free engine resources."""


@dataclass(frozen=True)
class BackendInfo:
    """How a plugin announces a physics engine: ``factory(robot, settings) -> PhysicsBackend``."""

    name: str
    summary: str
    factory: Callable[[RobotDescription, PhysicsSettings], PhysicsBackend]
