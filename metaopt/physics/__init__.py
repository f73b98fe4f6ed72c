"""A thin, typed interface between robot problems and physics engines.

A robot is described once (RobotDescription); each engine (MuJoCo, PyBullet, or one an outside
plugin adds through the ``metaopt_physics_backends`` hook) builds its own model from it and is
driven only through PhysicsBackend. Frame: x forward, y left, z up; SI units, angles in radians.
"""

from __future__ import annotations

import importlib.metadata
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from metaopt.errors import EvaluationError

Vec3 = tuple[float, float, float]

#: The view every engine's render() gives, so videos from different engines match: the camera
#: looks at camera_target from this far (m), from this compass direction (degrees: 0 looks along
#: +x, 90 along +y; 120 sees the robot's right front) and this elevation (degrees, negative: from
#: above), with this vertical field of view (degrees).
CAMERA_DISTANCE = 1.5
CAMERA_AZIMUTH = 120.0
CAMERA_ELEVATION = -15.0
CAMERA_FOVY = 45.0
#: The colour (RGBA, 0 to 1) every engine draws the robot in: orange, apart from any ground.
ROBOT_RGBA = (0.95, 0.55, 0.2, 1.0)


@dataclass(frozen=True)
class Shape:
    """A primitive solid: 'box' (size = full edge lengths x, y, z), 'sphere' (size = (radius,)),
    or 'capsule' along z (size = (radius, cylinder length))."""

    kind: str
    size: tuple[float, ...]

    def __post_init__(self) -> None:
        expected = {"box": 3, "sphere": 1, "capsule": 2}
        if expected.get(self.kind) != len(self.size):
            raise ValueError(f"bad shape {self.kind!r} with size {self.size}")

    def inertia(self, mass: float) -> Vec3:
        """Principal moments (Ixx, Iyy, Izz) about the centre of a uniform solid of this shape,
        with ODE's formulas (so every engine gets the rcssserver3d numbers)."""
        if self.kind == "box":
            x, y, z = self.size
            return (mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12,
                    mass * (x * x + y * y) / 12)  # fmt: skip
        if self.kind == "sphere":
            moment = 0.4 * mass * self.size[0] ** 2
            return (moment, moment, moment)
        r, length = self.size
        cylinder = math.pi * r * r * length
        spheres = 4.0 / 3.0 * math.pi * r**3
        m_cyl = mass * cylinder / (cylinder + spheres)
        m_sph = mass - m_cyl
        across = m_cyl * (0.25 * r * r + length * length / 12) + m_sph * (
            0.4 * r * r + 0.375 * r * length + 0.25 * length * length
        )
        return (across, across, (0.5 * m_cyl + 0.4 * m_sph) * r * r)

    @property
    def half_height(self) -> float:
        """Half the extent along z (for heights and bounding boxes)."""
        if self.kind == "box":
            return self.size[2] / 2
        if self.kind == "sphere":
            return self.size[0]
        return self.size[0] + self.size[1] / 2


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

    @property
    def inertia(self) -> Vec3:
        """Principal moments about the centre, kg·m² (axes of the construction pose)."""
        return self.shape.inertia(self.mass)


@dataclass(frozen=True)
class Hinge:
    """A revolute joint from ``parent`` to ``child`` about ``axis`` through ``anchor``
    (construction pose, root frame); angle 0 is the construction pose, ``rest`` the angle the
    joint starts at and is held at while nothing else drives it."""

    name: str
    parent: str
    child: str
    anchor: Vec3
    axis: Vec3
    lower: float
    upper: float
    rest: float = 0.0


@dataclass(frozen=True)
class RobotDescription:
    """A floating-base robot: bodies (root first, parents before children) and hinges.

    Every non-root body is the child of exactly one hinge (a tree of hinges).
    """

    name: str
    bodies: tuple[Body, ...]
    hinges: tuple[Hinge, ...]
    #: Bodies whose ground-contact force is reported (e.g. the feet).
    contact_bodies: tuple[str, ...]
    #: Height of the root body's centre when placed at reset.
    start_height: float

    def __post_init__(self) -> None:
        """Refuse a malformed robot here, naming what is wrong, rather than letting each engine
        fail on it in its own way (a parse error, a KeyError, a crash)."""
        names = [b.name for b in self.bodies]
        if len(set(names)) != len(names) or self.bodies[0].parent is not None:
            raise ValueError("bodies must have unique names, root first")
        seen = {names[0]}
        for body in self.bodies[1:]:
            if body.parent not in seen:
                raise ValueError(f"body {body.name!r} comes before its parent {body.parent!r}")
            seen.add(body.name)
        hinge_names = [h.name for h in self.hinges]
        if len(set(hinge_names)) != len(hinge_names):  # PyBullet's URDF import crashes on it
            raise ValueError("hinges must have unique names")
        children = sorted(h.child for h in self.hinges)
        if children != sorted(names[1:]):
            raise ValueError("every non-root body needs exactly one hinge to its parent")
        for h in self.hinges:
            if self.body(h.child).parent != h.parent or not h.lower <= h.rest <= h.upper:
                raise ValueError(f"hinge {h.name!r}: wrong parent or rest angle outside limits")
        for name in self.contact_bodies:
            if name not in names:
                raise ValueError(f"contact body {name!r} is not one of the bodies")

    @property
    def root(self) -> Body:
        """The free-floating root body (the torso)."""
        return self.bodies[0]

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Hinge names in description order (the order of every joint vector)."""
        return tuple(h.name for h in self.hinges)

    @property
    def total_mass(self) -> float:
        """Sum of body masses, kg."""
        return sum(b.mass for b in self.bodies)

    @property
    def rest_angles(self) -> np.ndarray:
        """Every joint's rest angle, radians, in joint order."""
        return np.array([h.rest for h in self.hinges], dtype=float)

    def with_mass_scale(self, scale: float) -> RobotDescription:
        """A copy with every body's mass (and so its inertia, which follows from mass and
        shape) multiplied by scale: a heavier or lighter robot of the same geometry, built
        alike by every engine."""
        if not scale > 0:
            raise ValueError(f"mass scale must be positive, got {scale}")
        bodies = tuple(replace(b, mass=b.mass * scale) for b in self.bodies)
        return replace(self, bodies=bodies)

    def body(self, name: str) -> Body:
        """The body called name."""
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(name)

    def joint_index(self, name: str) -> int:
        """Position of the hinge called name in every joint vector."""
        return self.joint_names.index(name)

    def hinge_of(self, body: str) -> Hinge:
        """The hinge whose child is body (the joint that carries it)."""
        for h in self.hinges:
            if h.child == body:
                return h
        raise KeyError(body)


@dataclass(frozen=True)
class PhysicsSettings:
    """Engine-independent simulation settings (documented defaults in docs/nao-walk.md).

    ``substeps`` 0 means the backend's own default (BackendInfo.default_substeps).
    ``friction`` is a Coulomb coefficient; math.inf means no sliding limit (where the engine
    handles it: BackendInfo.max_friction). ``slip`` is ODE's force-dependent slip, m/s per N
    of contact force (rcssserver3d's 5e-3; 0 = none); engines without it ignore it.
    """

    control_period: float = 0.02
    substeps: int = 0
    servo_gain: float = 10.0
    max_joint_speed: float = 6.1395
    max_joint_torque: float = 10.0
    friction: float = 1.0
    slip: float = 5e-3

    def timestep(self, default_substeps: int) -> float:
        """Physics step = control_period / substeps (the backend's default when 0)."""
        return self.control_period / (self.substeps or default_substeps)


def servo_velocities(
    targets: np.ndarray, angles: np.ndarray, settings: PhysicsSettings, out: np.ndarray
) -> np.ndarray:
    """The rcssserver3d agent's position loop, written into ``out``: target velocity =
    servo_gain * (target - angle), clamped to ±max_joint_speed. Raises EvaluationError when the
    targets are not finite numbers (a diverging controller)."""
    np.subtract(targets, angles, out=out)
    out *= settings.servo_gain
    if not math.isfinite(out.sum()):
        raise EvaluationError("joint targets are not finite numbers (the controller diverged)")
    return np.clip(out, -settings.max_joint_speed, settings.max_joint_speed, out=out)


def format_vector(values: Iterable[float]) -> str:
    """Numbers as an MJCF or URDF attribute takes them: space-separated, 10 significant digits
    (the one format of every generated model, so its text stays the same byte for byte)."""
    return " ".join(f"{v:.10g}" for v in values)


#: A root body's centre farther than this from the ground (m) means the simulation blew up.
UNSTABLE_HEIGHT = 1e3


def instability_error(engine: str, time: float) -> EvaluationError:
    """The error an engine raises when its simulation became unstable at time (s): one text
    for every engine, naming it."""
    return EvaluationError(f"{engine} simulation became unstable at t = {time:.3f} s")


def check_root_height(engine: str, height: float, time: float) -> None:
    """Raise instability_error(engine, time) when the root's height (m) is not finite or beyond
    UNSTABLE_HEIGHT: how engines that do not flag instability themselves detect it."""
    if not math.isfinite(height) or abs(height) > UNSTABLE_HEIGHT:
        raise instability_error(engine, time)


class PhysicsBackend(ABC):
    """One simulated robot on a flat ground plane, advanced one control period at a time.

    Joint vectors follow ``RobotDescription.joint_names``. Joints are velocity servos like
    rcssserver3d's (see servo_velocities), torque at most max_joint_torque; the velocity
    command is computed once per control period, as the server's agent does.
    """

    #: True when restore_state followed by the same steps reproduces a fresh run bit for bit.
    restores_exactly: bool = False

    def __init__(self, robot: RobotDescription, settings: PhysicsSettings) -> None:
        self.robot = robot
        self.settings = settings

    @abstractmethod
    def reset(self) -> None:
        """Rest pose (every joint at its rest angle) with the root upright at start_height,
        velocities zero, t = 0, ground friction back to settings.friction."""

    @abstractmethod
    def step(self, joint_targets: np.ndarray) -> None:
        """Servo every joint toward joint_targets (radians) for one control period.

        Raises EvaluationError when the simulation becomes unstable (non-finite state).
        """

    @abstractmethod
    def joint_angles(self) -> np.ndarray:
        """Measured joint angles, radians (may be a live read-only view: copy to keep)."""

    @abstractmethod
    def root_position(self) -> np.ndarray:
        """Root body (torso) centre in the world, metres, shape (3,)."""

    @abstractmethod
    def root_rotation(self) -> np.ndarray:
        """Root body orientation as a 3x3 rotation matrix (body to world)."""

    @abstractmethod
    def body_position(self, name: str) -> np.ndarray:
        """Centre of the body called name in the world, metres (for checks, plots, videos)."""

    @abstractmethod
    def contact_forces(self) -> np.ndarray:
        """Normal ground-contact force on each of contact_bodies, newtons: its mean over the last
        control period's physics steps (the period's impulse / its length), so that engines
        stepping 1, 2 or 16 times a period report the same quantity; zero after reset."""

    @abstractmethod
    def time(self) -> float:
        """Simulated seconds since reset."""

    @abstractmethod
    def set_ground_friction(self, mu: float) -> None:
        """Coefficient of friction between the robot and the ground from now on (until the
        next call or reset); not part of the saved state."""

    @abstractmethod
    def push_root(self, velocity: Vec3) -> None:
        """Add velocity (m/s, world frame) to the root's linear velocity; the joints keep
        their velocities relative to it, so the whole robot is pushed."""

    # Read-backs and an external force: what an engine actually simulates, measured from the
    # engine itself (the agreement suite in metaopt.testing and perturbations use them).

    @abstractmethod
    def joint_velocities(self) -> np.ndarray:
        """Measured joint velocities, rad/s, in joint order."""

    @abstractmethod
    def joint_torques(self) -> np.ndarray:
        """Torque each joint's motor applied during the last physics step, N·m, in joint
        order, read back from the engine (not the limit it was given)."""

    @abstractmethod
    def body_mass(self, name: str) -> float:
        """Mass of the body called name as the engine holds it, kg."""

    @abstractmethod
    def body_inertia(self, name: str) -> Vec3:
        """Principal moments of inertia of the body called name about its centre as the
        engine holds them, kg·m², in the axes of the construction pose."""

    @abstractmethod
    def ground_friction(self) -> float:
        """The friction coefficient the engine's robot–ground contacts use now, read back from
        the engine (math.inf where friction is unlimited)."""

    @abstractmethod
    def apply_force(self, body: str, force: Vec3) -> None:
        """From now on, a constant force (N, world frame) at the centre of mass of ``body``
        during every physics step, until the next call for that body or reset;
        (0, 0, 0) removes it. Part of the state save_state captures."""

    @abstractmethod
    def save_state(self) -> Any:
        """An opaque snapshot of the full simulation state."""

    @abstractmethod
    def restore_state(self, state: Any) -> None:
        """Return to a snapshot taken by save_state in this same backend instance."""

    def render(self, width: int, height: int, camera_target: Vec3) -> np.ndarray:
        """An image of the scene now, (height, width, 3) uint8 RGB, seen by the CAMERA_* view
        looking at camera_target (world, m), headless. Optional: engines that cannot draw raise
        NotImplementedError."""
        raise NotImplementedError(f"the physics backend {type(self).__name__} cannot render")

    def close(self) -> None:  # noqa: B027 - optional
        """Free engine resources."""


@dataclass(frozen=True)
class BackendInfo:
    """How a plugin announces a physics engine: ``factory(robot, settings) -> PhysicsBackend``.

    ``default_substeps`` is the number of physics steps per control period the engine uses
    when PhysicsSettings.substeps is 0; ``max_friction`` the largest ground friction
    coefficient its contact model handles (problems refuse a larger one up front; math.inf:
    unlimited friction too); ``default_friction`` the coefficient a problem uses on it unless
    told otherwise. ``unavailable``, when not empty, says in one line why the engine cannot
    run here and how to install what it needs (it is listed, but not used). ``version`` says
    which build of the engine runs here, where that is not the version of a Python
    distribution named like the engine (see engine_version).
    """

    name: str
    summary: str
    factory: Callable[[RobotDescription, PhysicsSettings], PhysicsBackend]
    default_substeps: int = 10
    max_friction: float = math.inf
    default_friction: float = 1.0
    unavailable: str = ""
    version: Callable[[], str] | None = None


def engine_version(info: BackendInfo) -> str:
    """The installed engine's version: its own ``version``, else that of the Python
    distribution named like the engine (mujoco, pybullet)."""
    if info.version is not None:
        return info.version()
    return importlib.metadata.version(info.name)


#: A robot problem's ``backend`` parameter may name several engines joined by this, to be
#: evaluated on all of them ('mujoco+pybullet').
ENGINE_SEPARATOR = "+"


def engine_names(backend: str) -> tuple[str, ...]:
    """The engines a ``backend`` parameter value names: 'mujoco+pybullet' -> both."""
    return tuple(name.strip() for name in backend.split(ENGINE_SEPARATOR))
