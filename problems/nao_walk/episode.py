"""The paper's walking episode: a lock phase, then a gait drives both legs' pitch joints.

One EpisodeRunner per backend: it simulates the lock phase once, keeps the resulting state
(where the engine restores bit for bit, keyed by everything the lock phase depends on) and
starts every episode from it. The walking phase stops at a fall. An episode may be disturbed
(Disturbance: ground friction, a push, noisy hip sensors; Push: an impulse on the torso at a
set time; sensor latency), all from the walking phase on, so the lock phase stays shared.
Metrics and the two fitness formulas (robust, paper) live here too.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Hashable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

from metaopt.errors import EvaluationError
from metaopt.physics import PhysicsBackend, PhysicsSettings, RobotDescription

#: The joints the paper's gait drives (MatsuokaCpg.joints), in the order of its targets.
DRIVEN_JOINTS = ("llj3", "llj4", "llj5", "rlj3", "rlj4", "rlj5")
#: The joints whose measured angles feed back into a gait (left, right hip pitch).
FEEDBACK_JOINTS = ("llj3", "rlj3")
#: robust fitness: a fall costs this much progress, metres ...
FALL_PENALTY = 1.0
#: ... plus this much per second of walking phase left at the fall, metres per second
#: (more than twice the paper's best walking speed of 0.44 m/s).
FALL_PENALTY_RATE = 1.0
FITNESS_KINDS = ("robust", "paper", "progress")
#: Share of the walking phase a walk may spend with neither foot on the ground before
#: flight_penalty applies, by default (issue 16's "a walk, not a run": at most 5 %).
FLIGHT_ALLOWED = 0.05
#: A foot touches the ground when its normal contact force exceeds this, N (the robot weighs
#: about 50 N).
CONTACT_FORCE_N = 5.0
#: Seconds of the walking phase left out at its start when measuring foot use: the gait grows
#: over the first second or two.
SETTLE_S = 2.0


@dataclass(slots=True)
class Sensors:
    """What a gait senses each control step (updated in place by the episode runner)."""

    time: float = 0.0  #: seconds since walking began
    left_hip: float = 0.0  #: measured llj3, rad (with the disturbance's sensor error)
    right_hip: float = 0.0  #: measured rlj3, rad (with the disturbance's sensor error)
    roll: float = 0.0  #: torso roll, rad: positive when its left side is up
    pitch: float = 0.0  #: torso pitch, rad: positive when it leans forward
    #: torso heading against the walking phase's start, rad in [-pi, pi]: positive when
    #: turned to the left (what a gyro integrates; read exactly, without sensor error)
    yaw: float = 0.0


class Gait(Protocol):
    """A walking controller: targets for its joints each control step from what it senses."""

    #: The joints it drives, in the order act() returns their targets; every other joint is
    #: held at its rest angle.
    joints: tuple[str, ...]

    def reset(self) -> None:
        """Back to the controller's initial state."""

    def act(self, sensors: Sensors) -> Sequence[float]:
        """Targets (radians) for ``joints`` at this control step."""


class SineGait:
    """A fixed reference gait (for tests and benchmarks, no optimization): hips swing in
    anti-phase about a slight flexion, knees bend on the forward swing, ankles keep the feet
    parallel to the torso (lj5 = -(lj3 + lj4))."""

    joints = DRIVEN_JOINTS

    def __init__(self, period: float = 0.6, hip: float = 0.15, knee: float = 0.3) -> None:
        self.period, self.hip, self.knee = period, hip, knee

    def reset(self) -> None:
        pass

    def act(self, sensors: Sensors) -> tuple[float, ...]:
        s = math.sin(2 * math.pi * (sensors.time + 0.02) / self.period)
        lh, rh = 0.2 + self.hip * s, 0.2 - self.hip * s
        lk, rk = -0.3 - self.knee * max(0.0, s), -0.3 - self.knee * max(0.0, -s)
        return (lh, lk, -(lh + lk), rh, rk, -(rh + rk))


@dataclass(frozen=True)
class Push:
    """A shove on the torso: ``impulse`` N·s, horizontal, ``direction`` degrees from forward
    (90: to the left), at episode time ``time`` s, made as a constant force impulse/period over
    the one control period that starts then."""

    impulse: float
    direction: float = 0.0
    time: float = 6.0

    def force(self, period: float) -> tuple[float, float, float]:
        """The world-frame force, N, that gives the impulse over one control period."""
        angle = math.radians(self.direction)
        magnitude = self.impulse / period
        return (magnitude * math.cos(angle), magnitude * math.sin(angle), 0.0)


@dataclass(frozen=True)
class EpisodeSettings:
    """Timing and fall rule of an episode (seconds, metres, degrees), the walking phase's
    perturbations (a push; ``latency``: the gait senses what was measured that many control
    steps earlier), and whether to measure foot use (``feet``: costs a contact query a step)."""

    duration: float = 15.0
    lock: float = 3.0
    fall_height: float = 0.25
    fall_tilt: float = 60.0
    push: Push | None = None
    latency: int = 0
    feet: bool = False


def lock_phase_key(robot: RobotDescription, physics: PhysicsSettings, lock_steps: int) -> Hashable:
    """Everything the simulated lock phase depends on: the robot as built (masses included),
    the physics settings (friction, servo gain, substeps, ...) and its length. A saved lock
    state is reused only for an equal key."""
    return (robot, physics, lock_steps)


#: Disturbance scales at noise = 1: ground friction is multiplied by exp(FRICTION_SPREAD * u),
#: u ~ U(-1, 1) ...
FRICTION_SPREAD = 0.2
#: ... the torso is pushed at the start of the walking phase with a horizontal velocity whose
#: x and y are N(0, PUSH_STD²), m/s ...
PUSH_STD = 0.05
#: ... and every hip angle the gait reads carries its own N(0, SENSOR_STD²) error, radians (1°).
SENSOR_STD = math.radians(1.0)


@dataclass(frozen=True)
class Disturbance:
    """One noisy episode's random conditions, all applied from the walking phase on."""

    friction: float  #: ground friction coefficient for the walking phase
    push: tuple[float, float, float]  #: velocity added to the torso as walking starts, m/s
    #: per control step, the errors added to the measured (llj3, rlj3) the gait reads, radians
    sensor_errors: list[list[float]]

    @classmethod
    def draw(cls, noise: float, seed: int, nominal_friction: float, steps: int) -> Disturbance:
        """The disturbance of scale ``noise`` (> 0) for an episode of ``steps`` walking control
        steps, a pure function of its arguments (numpy's default_rng(seed))."""
        rng = np.random.default_rng(seed)
        u = rng.uniform(-1.0, 1.0)
        normal = rng.standard_normal(2 + 2 * steps)
        push_x, push_y = noise * PUSH_STD * normal[:2]
        return cls(
            friction=nominal_friction * math.exp(noise * FRICTION_SPREAD * u),
            push=(float(push_x), float(push_y), 0.0),
            sensor_errors=(noise * SENSOR_STD * normal[2:]).reshape(steps, 2).tolist(),
        )


@dataclass
class EpisodeResult:
    """What one episode measured. Positions are of the torso centre, relative to where the
    walking phase started; x forward, y left."""

    distance: float  #: forward progress X, m
    drift: float  #: lateral displacement Y, m (signed)
    time_walked: float  #: seconds of walking phase before the fall or the end
    fell: bool
    fall_time: float  #: episode time of the fall; the duration when it did not fall
    height_min: float  #: torso height extremes during the walking phase, m
    height_max: float
    #: share of the walking phase after SETTLE_S with neither foot touching the ground; NaN
    #: unless measured (EpisodeSettings.feet) or when the episode ended before SETTLE_S
    flight: float = math.nan
    #: per control step, when recorded: time since walking began, torso x, y, z (world),
    #: torso tilt (degrees), then targets and measured angles of DRIVEN_JOINTS (radians)
    trajectory: dict[str, np.ndarray] | None = field(default=None, repr=False)

    @property
    def speed(self) -> float:
        """Mean forward speed over the time walked, m/s."""
        return self.distance / self.time_walked if self.time_walked > 0 else 0.0

    def metrics(self) -> dict[str, float]:
        """The scalar metrics stored with every evaluation; ``time_to_fall`` (seconds walked
        before the fall) only in an episode that fell, so that its median over a table's
        episodes says when a gait falls, not how long most of them walked."""
        values = {k: float(v) for k, v in asdict(self).items() if k != "trajectory"}
        if math.isnan(self.flight):
            del values["flight"]
        values["speed"] = self.speed
        values["height_range"] = self.height_max - self.height_min
        if self.fell:
            values["time_to_fall"] = self.time_walked
        return values


def heading(rotation: np.ndarray) -> float:
    """The heading about the vertical, rad, of a body whose rotation matrix is rotation: the
    angle of its forward (x) axis in the ground plane."""
    return math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))


def fitness(
    result: EpisodeResult,
    kind: str,
    duration: float,
    flight_penalty: float = 0.0,
    cap: float = math.inf,
    flight_allowed: float = FLIGHT_ALLOWED,
) -> float:
    """Score an episode (to be maximized); progress is X - |Y|.

    robust: progress, minus FALL_PENALTY + FALL_PENALTY_RATE * (time left) after a fall.
    Monotone: with the same progress a later fall scores higher, and a fall always scores below
    stopping on the spot at that moment.
    paper: eq. 9 as printed: progress, divided by the time left after a fall. Flawed: a fall
    with under 1 s left multiplies the score, and with negative progress falling early helps.
    progress: progress, minus FALL_PENALTY after a fall, without the rate: a fall costs the
    constant and the walk it cut short, so a gait that walks on one engine and falls after
    walking on another scores above standing (a first search over several engines from
    random gaits), and a lunge forward does not pay.
    The score counts at most cap (nao-walk's engine_cap: progress past it stops paying). Each
    kind then loses flight_penalty metres per unit of flight share above flight_allowed: a run
    scores below a walk of the same progress, past the cap too. A fall before the flight could
    be measured (within SETTLE_S of walking) is charged as flight throughout, so that falling at
    once never escapes the penalty that a longer walk pays (a search would learn to fall).
    """
    progress = result.distance - abs(result.drift)
    remaining = duration - result.fall_time
    if not result.fell or remaining <= 0:
        score = progress
    elif kind == "progress":
        score = progress - FALL_PENALTY
    elif kind == "paper":
        score = progress / remaining
    else:
        score = progress - FALL_PENALTY - FALL_PENALTY_RATE * remaining
    score = min(score, cap)
    flight = 1.0 if result.fell and math.isnan(result.flight) else result.flight
    if flight_penalty and not math.isnan(flight):
        score -= flight_penalty * max(0.0, flight - flight_allowed)
    return score


def control_steps(seconds: float, period: float) -> int:
    """The whole control steps nearest to ``seconds`` (how the runner counts a phase's length
    and places a push), so that nao-walk can check its settings exactly as the runner will."""
    return round(seconds / period)


class EpisodeRunner:
    """Runs episodes on one backend, reusing the simulated lock phase where that is exact."""

    def __init__(self, backend: PhysicsBackend, settings: EpisodeSettings) -> None:
        self.backend = backend
        self.settings = settings
        robot = backend.robot
        period = backend.settings.control_period
        self._lock_steps = control_steps(settings.lock, period)
        self._walk_steps = control_steps(settings.duration - settings.lock, period)
        self._period = period
        self._indices: dict[tuple[str, ...], list[int]] = {}
        self._feedback = [robot.joint_index(name) for name in FEEDBACK_JOINTS]
        self._rest = robot.rest_angles
        self._targets = self._rest.copy()
        self._cos_tilt = math.cos(math.radians(settings.fall_tilt))
        #: the saved end of the lock phase, with the lock_phase_key it was simulated under
        self._after_lock: tuple[Hashable, Any] | None = None
        #: the settings' push: the walking step it acts in (-1: none) and its force
        self._push = self._push_plan(settings.push)
        self._settle_steps = math.ceil(SETTLE_S / period - 1e-9)

    def _push_plan(self, push: Push | None) -> tuple[int, tuple[float, float, float]]:
        """The walking control step a push acts in (-1 for none) and its force; ValueError
        for a push outside the walking phase."""
        if push is None or push.impulse == 0:
            return -1, (0.0, 0.0, 0.0)
        step = control_steps(push.time - self.settings.lock, self._period)
        if not 0 <= step < self._walk_steps:
            raise ValueError(
                f"the push at {push.time} s is outside the walking phase "
                f"({self.settings.lock} s to {self.settings.duration} s)"
            )
        return step, push.force(self._period)

    @property
    def walk_steps(self) -> int:
        """Control steps in the walking phase (the length a Disturbance must cover)."""
        return self._walk_steps

    @property
    def lock_state(self) -> Any | None:
        """The saved end of the lock phase the next episode's walking phase starts from, for
        replays that must start where the episodes do (read only: restore it, never change it);
        None before the first episode, or where the backend does not restore exactly."""
        if self._after_lock is None or self._after_lock[0] != self.lock_key:
            return None
        return self._after_lock[1]

    @property
    def lock_key(self) -> Hashable:
        """The lock_phase_key of this runner's backend as it is now."""
        backend = self.backend
        return lock_phase_key(backend.robot, backend.settings, self._lock_steps)

    def _start_walking(self, disturbance: Disturbance | None) -> None:
        """Put the backend at the end of the lock phase (restored where a state saved under an
        equal lock_key exists, simulated otherwise), then set the walking phase's ground
        friction (nominal, or the disturbance's) and push."""
        if self._after_lock is not None and self._after_lock[0] == self.lock_key:
            self.backend.restore_state(self._after_lock[1])
        else:
            self._simulate_lock()
        if disturbance is None:
            self.backend.set_ground_friction(self.backend.settings.friction)
        else:
            self.backend.set_ground_friction(disturbance.friction)
            self.backend.push_root(disturbance.push)

    def _simulate_lock(self) -> None:
        """The lock phase from reset (nominal friction); kept where the backend restores it
        exactly."""
        self._after_lock = None
        key = self.lock_key
        self.backend.reset()
        for _ in range(self._lock_steps):
            self.backend.step(self._rest)
        if self._fallen():
            raise EvaluationError(
                "the robot fell during the lock phase; the physics settings do not let it stand"
            )
        if self.backend.restores_exactly:
            self._after_lock = (key, self.backend.save_state())

    def _fallen(self) -> bool:
        z = float(self.backend.root_position()[2])
        return z < self.settings.fall_height or self.backend.root_rotation()[2, 2] < self._cos_tilt

    def run(
        self,
        gait: Gait,
        record: bool = False,
        disturbance: Disturbance | None = None,
        on_step: Callable[[int], None] | None = None,
        push: Push | None = None,
    ) -> EpisodeResult:
        """One episode: lock phase (all joints held at rest), then gait drives DRIVEN_JOINTS
        until the end or a fall, under ``disturbance`` if given (None: noise-free), the
        settings' latency and ``push`` (None: the settings' push). ``record`` keeps a per-step
        trajectory for plots (true angles, not the sensed ones); ``on_step(steps)`` is called
        after every walking control step (e.g. to film it)."""
        if disturbance is not None and len(disturbance.sensor_errors) != self._walk_steps:
            raise ValueError(f"the disturbance must cover {self._walk_steps} walking steps")
        push_step, push_force = self._push if push is None else self._push_plan(push)
        backend, targets = self.backend, self._targets
        targets[:] = self._rest
        self._start_walking(disturbance)
        gait.reset()
        x0, y0, z = (float(v) for v in backend.root_position())
        height_min = height_max = z
        left, right = self._feedback
        driven = self._joint_indices(gait.joints)
        fall_height, cos_tilt = self.settings.fall_height, self._cos_tilt
        rows: list[list[float]] = []
        fell, steps, airborne = False, 0, 0
        errors = disturbance.sensor_errors if disturbance is not None else None
        sensors = Sensors()
        # what was measured at the last latency + 1 steps; the gait reads the oldest
        readings: deque[tuple[float, float, float, float, float]] = deque(
            maxlen=self.settings.latency + 1
        )
        feet = self.settings.feet
        root = backend.robot.root.name
        rotation = backend.root_rotation()
        start_heading = heading(rotation)
        while steps < self._walk_steps:
            angles = backend.joint_angles()
            left_hip, right_hip = float(angles[left]), float(angles[right])
            if errors is not None:
                left_hip += errors[steps][0]
                right_hip += errors[steps][1]
            roll = math.asin(max(-1.0, min(1.0, float(rotation[2, 1]))))
            pitch = math.asin(max(-1.0, min(1.0, -float(rotation[2, 0]))))
            yaw = math.remainder(heading(rotation) - start_heading, math.tau)  # in [-pi, pi]
            readings.append((left_hip, right_hip, roll, pitch, yaw))
            sensors.time = steps * self._period
            sensors.left_hip, sensors.right_hip, sensors.roll, sensors.pitch, sensors.yaw = (
                readings[0]
            )
            out = gait.act(sensors)
            for index, target in zip(driven, out):
                targets[index] = target
            if steps == push_step:
                backend.apply_force(root, push_force)
                backend.step(targets)
                backend.apply_force(root, (0.0, 0.0, 0.0))
            else:
                backend.step(targets)
            steps += 1
            if on_step is not None:
                on_step(steps)
            if feet and steps > self._settle_steps:
                airborne += bool(np.all(backend.contact_forces() <= CONTACT_FORCE_N))
            position = backend.root_position()
            z = float(position[2])
            height_min, height_max = min(height_min, z), max(height_max, z)
            rotation = backend.root_rotation()
            upright = float(rotation[2, 2])
            if record:
                angles = backend.joint_angles()
                tilt = math.degrees(math.acos(max(-1.0, min(1.0, upright))))
                rows.append([steps * self._period, *position, tilt, *out, *angles[driven]])
            if z < fall_height or upright < cos_tilt:
                fell = True
                break
        if not math.isfinite(z):
            raise EvaluationError("the simulation produced a non-finite torso position")
        x, y, _ = (float(v) for v in backend.root_position())
        time_walked = steps * self._period
        measured = steps - self._settle_steps
        return EpisodeResult(
            distance=x - x0,
            drift=y - y0,
            time_walked=time_walked,
            fell=fell,
            fall_time=self.settings.lock + time_walked if fell else self.settings.duration,
            height_min=height_min,
            height_max=height_max,
            flight=airborne / measured if feet and measured > 0 else math.nan,
            trajectory=_trajectory(rows, gait.joints) if record else None,
        )

    def _joint_indices(self, joints: tuple[str, ...]) -> list[int]:
        """The backend's indices of a gait's joints (cached per tuple of names)."""
        indices = self._indices.get(joints)
        if indices is None:
            indices = self._indices[joints] = [self.backend.robot.joint_index(j) for j in joints]
        return indices


def _trajectory(rows: list[list[float]], joints: tuple[str, ...]) -> dict[str, np.ndarray]:
    table = np.array(rows, dtype=float).reshape(-1, 5 + 2 * len(joints))
    names = ["time", "x", "y", "z", "tilt"]
    names += [f"{j}_target" for j in joints] + [f"{j}_angle" for j in joints]
    return {name: table[:, i] for i, name in enumerate(names)}
