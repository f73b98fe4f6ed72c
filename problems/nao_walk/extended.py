"""Extended CPG walking controllers: the paper's Matsuoka rhythm, with lateral sway, knee lift,
torso feedback and a smooth start (nao-walk's ``controller=extended``), and with an ankle
push-off (``controller=stride``).

The paper's controller moves only the six pitch joints, within Table 2's few degrees, and
nothing shifts the weight sideways (docs/paper-reproduction.md). This one keeps a Matsuoka pair
as the rhythm generator but fixes its shape (tau2 = TAU_RATIO tau1, BETA, GAMMA, c = 1: inside
Matsuoka's oscillation conditions, so every candidate oscillates) and sets its tempo with one
parameter, ``period``. Its signals, normalized by the free rhythm's amplitudes:

* s = (y1 - y2) / Y_SWING, in [-1, 1]: + when element 1 (left leg) is active;
* q = (v1 - v2) / V_SWING: the adaptation states, lagging s by a quarter period or so;
* y1 / Y_PEAK, y2 / Y_PEAK, in [0, 1]: each element's own activity.

Joint targets, server convention (docs/nao-walk.md), degrees here and radians on the joints:

* hip pitch: hip_bias +- hip_swing * s (left +, right -);
* knee: -(knee_bias + knee_lift * y / Y_PEAK), each leg with its own element;
* ankle pitch: keeps the foot parallel to the torso (-(hip + knee)), plus ankle_bias, plus
  pitch_gain * torso pitch;
* hip roll = -ankle roll, both legs alike (the feet stay parallel to the ground):
  sway * (cos(sway_phase) s + sin(sway_phase) q) + roll_gain * torso roll.

Everything but the torso feedback starts from the standing pose and reaches full size after
RAMP_S seconds. Each target is clipped to its joint's limits.

The stride controller (``controller=stride``) is this one with the hip feedback's range
doubled and a leg's knee and ankle driven at free phases of its own signals (s and q signed
for the leg: + for the left, - for the right):

* knee: -(knee_bias + knee_lift * max(0, cos(knee_phase) s + sin(knee_phase) q));
* ankle pitch: as above, plus push * (cos(push_phase) s + sin(push_phase) q), a push-off
  (toes down while the leg is behind) for push > 0 at phase 0.

The steered controller (``controller=steered``) is the stride one with heading feedback: with
u = steer * yaw (the torso's heading turned since walking began) within +-STEER_LIMIT, the left
hip swings by hip_swing * (1 + u) and the right by hip_swing * (1 - u), so that a robot turned
left steps further with its left leg and turns back.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence

import numpy as np

from metaopt import ConfigError, Space, Variable

from .controller import CONTROL_STEP_S, MatsuokaPair, checked_params
from .episode import Sensors

#: The rhythm's fixed shape: tau2 = TAU_RATIO * tau1, adaptation BETA, inhibition GAMMA, c = 1.
#: Matsuoka's conditions 1 + tau1/tau2 < GAMMA < 1 + BETA hold (1.5 < 2 < 3.5).
TAU_RATIO, BETA, GAMMA = 2.0, 2.5, 2.0
#: Seconds over which the gait grows from the standing pose to its full size.
RAMP_S = 1.0

#: name, lower, upper, meaning (degrees where the name says an angle).
_BOUNDS: tuple[tuple[str, float, float, str], ...] = (
    ("period", 0.2, 1.2, "period of the free rhythm, s (hip feedback shifts it)"),
    ("feedback", -2.0, 2.0, "measured hip pitch into the oscillator's drive, per radian"),
    ("hip_bias", -30.0, 30.0, "hip pitch offset, degrees (+: thighs forward)"),
    ("hip_swing", 0.0, 45.0, "hip pitch amplitude, degrees (legs in anti-phase)"),
    ("knee_bias", 0.0, 80.0, "knee flexion of both legs at all times, degrees"),
    ("knee_lift", 0.0, 80.0, "extra knee flexion while a leg's element is active, degrees"),
    ("ankle_bias", -20.0, 20.0, "ankle pitch from foot-parallel, degrees (+: toes up)"),
    ("sway", 0.0, 15.0, "hip and ankle roll amplitude, degrees (sideways weight shift)"),
    ("sway_phase", -180.0, 180.0, "phase of the sway against the hip swing, degrees"),
    ("pitch_gain", -1.5, 1.5, "torso pitch into ankle pitch, rad per rad"),
    ("roll_gain", -1.5, 1.5, "torso roll into hip and ankle roll, rad per rad"),
)
PARAM_NAMES: tuple[str, ...] = tuple(name for name, *_ in _BOUNDS)

#: The stride controller's: the extended one's, the hip feedback twice as wide (the extended
#: searches ended on its bound), and a free knee phase and an ankle push-off.
_STRIDE_BOUNDS: tuple[tuple[str, float, float, str], ...] = (
    *((name, -4.0, 4.0, meaning) if name == "feedback" else (name, lo, hi, meaning)
      for name, lo, hi, meaning in _BOUNDS),
    ("knee_phase", -180.0, 180.0, "phase of the knee lift against the leg's hip swing, degrees"),
    ("push", -30.0, 30.0, "ankle pitch swing, degrees (+: toes down while the leg is behind)"),
    ("push_phase", -180.0, 180.0, "phase of the ankle swing against the hip swing, degrees"),
)  # fmt: skip
STRIDE_PARAM_NAMES: tuple[str, ...] = tuple(name for name, *_ in _STRIDE_BOUNDS)

#: The steered controller's: the stride one's and the heading feedback's gain.
_STEERED_BOUNDS: tuple[tuple[str, float, float, str], ...] = (
    *_STRIDE_BOUNDS,
    ("steer", 0.0, 4.0, "heading error into stride asymmetry, per radian (0: no steering)"),
)
STEERED_PARAM_NAMES: tuple[str, ...] = tuple(name for name, *_ in _STEERED_BOUNDS)

#: The balanced controller's: the steered one's and the stepping strategy's two gains.
_BALANCED_BOUNDS: tuple[tuple[str, float, float, str], ...] = (
    *_STEERED_BOUNDS,
    ("place_gain", -1.5, 1.5, "torso pitch into both hips' pitch, rad per rad"),
    ("place_rate", -0.3, 0.3, "torso pitch rate into both hips' pitch, rad per rad/s"),
)
BALANCED_PARAM_NAMES: tuple[str, ...] = tuple(name for name, *_ in _BALANCED_BOUNDS)

#: The values at which a controller's added variables make it the smaller one exactly (the
#: steered one without steering is the stride one; the balanced one without its two gains is
#: the steered one), so a smaller controller's gait can start a larger one's search.
_STEERED_NEUTRAL: dict[str, float] = {"steer": 0.0}
_BALANCED_NEUTRAL: dict[str, float] = {**_STEERED_NEUTRAL, "place_gain": 0.0, "place_rate": 0.0}
#: The steered controller's largest stride asymmetry: a leg's hip swing x (1 +- this).
STEER_LIMIT = 0.5

LEFT = ("llj2", "llj3", "llj4", "llj5", "llj6")
RIGHT = ("rlj2", "rlj3", "rlj4", "rlj5", "rlj6")


def _space(
    bounds: tuple[tuple[str, float, float, str], ...], neutral: Mapping[str, float] | None = None
) -> Space:
    neutral = neutral or {}
    return Space([Variable(name, lo, hi, meaning, neutral.get(name))
                  for name, lo, hi, meaning in bounds])  # fmt: skip


def extended_space() -> Space:
    """The extended controller's decision variables, named and bounded."""
    return _space(_BOUNDS)


def stride_space() -> Space:
    """The stride controller's decision variables, named and bounded."""
    return _space(_STRIDE_BOUNDS)


def steered_space() -> Space:
    """The steered controller's decision variables, named and bounded. Its steering gain is
    neutral at 0, where it is the stride controller exactly."""
    return _space(_STEERED_BOUNDS, _STEERED_NEUTRAL)


def balanced_space() -> Space:
    """The balanced controller's decision variables, named and bounded. Its two gains are
    neutral at 0, where it is the steered controller exactly, so a steered gait can start a
    balanced search (metaopt.warm_start.fitted_start)."""
    return _space(_BALANCED_BOUNDS, _BALANCED_NEUTRAL)


@functools.cache
def free_rhythm() -> tuple[float, float, float, float]:
    """The free pair's (c = 1, no feedback) period in units of tau1 (control steps per unit of
    tau1) and its amplitudes Y_PEAK (largest y), Y_SWING (largest |y1 - y2|) and V_SWING
    (largest |v1 - v2|), measured by simulating it once: tau1 scales time and nothing else."""
    tau = 4.0
    pair = MatsuokaPair(tau, TAU_RATIO * tau, BETA, GAMMA)
    rows = []
    for _ in range(4000):
        y1, y2 = pair.advance(1.0, 1.0)
        rows.append((y1, y2, pair.v1 - pair.v2))
    y1, y2, v = np.array(rows[2000:]).T  # the settled rhythm
    s = y1 - y2
    rising = np.flatnonzero((s[:-1] < 0.0) & (s[1:] >= 0.0))
    period = float(np.diff(rising).mean()) / tau
    return period, float(max(y1.max(), y2.max())), float(np.abs(s).max()), float(np.abs(v).max())


def _phased(amplitude_rad: float, phase_deg: float) -> tuple[float, float]:
    """(weight of s, weight of q) of amplitude * (cos(phase) s + sin(phase) q)."""
    phase = math.radians(phase_deg)
    return amplitude_rad * math.cos(phase), amplitude_rad * math.sin(phase)


class ExtendedCpg:
    """The extended controller (module docstring): ten leg joints from one Matsuoka rhythm and
    the torso's roll and pitch."""

    #: The joints it drives, in the order act() returns their targets.
    joints = LEFT + RIGHT
    #: Its parameters, in order, and its name in messages.
    param_names = PARAM_NAMES
    label = "the extended controller"

    def __init__(self, params: Sequence[float], limits: Mapping[str, tuple[float, float]]) -> None:
        values = dict(zip(self.param_names, checked_params(params, self.param_names, self.label)))
        period = values["period"]
        if period <= 0.0:
            raise ConfigError(f"period must be positive seconds, got {period}")
        steps_per_tau, self._y_peak, self._y_swing, self._v_swing = free_rhythm()
        tau1 = period / CONTROL_STEP_S / steps_per_tau
        self._pair = MatsuokaPair(tau1, TAU_RATIO * tau1, BETA, GAMMA)
        self._feedback = values["feedback"]
        self._pitch_gain, self._roll_gain = values["pitch_gain"], values["roll_gain"]
        rad = math.pi / 180.0
        self._hip_bias, self._hip_swing = values["hip_bias"] * rad, values["hip_swing"] * rad
        self._knee_bias, self._knee_lift = values["knee_bias"] * rad, values["knee_lift"] * rad
        self._lift_per_y = self._knee_lift / self._y_peak
        self._ankle_bias = values["ankle_bias"] * rad
        self._sway_s, self._sway_q = _phased(values["sway"] * rad, values["sway_phase"])
        self._configure(values)
        missing = [joint for joint in self.joints if joint not in limits]
        if missing:
            raise ConfigError(f"no limits given for {', '.join(missing)}")
        self._limits = [tuple(float(v) for v in limits[joint]) for joint in self.joints]

    def _configure(self, values: Mapping[str, float]) -> None:
        """Read the parameters a subclass adds (none here)."""

    def reset(self) -> None:
        """Back to the initial state (the rhythm's, and the start of the ramp)."""
        self._pair.reset()

    def act(self, sensors: Sensors) -> tuple[float, ...]:
        """Targets (radians) for ``joints``: left hip roll, hip, knee, ankle, ankle roll, then
        the right leg's."""
        pair = self._pair
        y1, y2 = pair.advance(
            1.0 + self._feedback * sensors.left_hip, 1.0 + self._feedback * sensors.right_hip
        )
        ramp = min(1.0, (sensors.time + CONTROL_STEP_S) / RAMP_S)
        s = (y1 - y2) / self._y_swing
        q = (pair.v1 - pair.v2) / self._v_swing
        roll = ramp * (self._sway_s * s + self._sway_q * q) + self._roll_gain * sensors.roll
        ankle = ramp * self._ankle_bias + self._pitch_gain * sensors.pitch
        left_swing, right_swing = self._hip_swings(sensors)
        placement = self._placement(sensors)
        return (
            *self._leg(ramp, s, q, y1, ankle, roll, left_swing, placement, 0),
            *self._leg(ramp, -s, -q, y2, ankle, roll, right_swing, placement, 5),
        )

    def _placement(self, sensors: Sensors) -> float:
        """What both hips' pitch targets move by from the torso's sensed motion, radians: none
        here."""
        return 0.0

    def _hip_swings(self, sensors: Sensors) -> tuple[float, float]:
        """The left and the right hip's swing amplitude, radians: both hip_swing here."""
        return self._hip_swing, self._hip_swing

    def _knee_and_ankle(self, s: float, q: float, y: float) -> tuple[float, float]:
        """A leg's rhythmic (knee flexion, ankle pitch), radians, from its own signals (s and
        q signed for this leg, y its element's output): the knee lifts while its element is
        active, the ankle has no rhythm of its own."""
        return self._lift_per_y * y, 0.0

    def _leg(
        self,
        ramp: float,
        s: float,
        q: float,
        y: float,
        ankle: float,
        roll: float,
        hip_swing: float,
        placement: float,
        first: int,
    ) -> tuple[float, float, float, float, float]:
        """One leg's clipped (hip roll, hip, knee, ankle, ankle roll), its hip swinging by
        ``hip_swing`` and moved by ``placement``; the ankle pitch keeps the foot parallel to the
        torso (from the clipped hip and knee) plus ``ankle`` and the leg's ankle rhythm."""
        limits = self._limits
        lift, ankle_swing = self._knee_and_ankle(s, q, y)
        hip = _clip(ramp * (self._hip_bias + hip_swing * s) + placement, limits[first + 1])
        knee = _clip(-ramp * (self._knee_bias + lift), limits[first + 2])
        return (
            _clip(roll, limits[first]),
            hip,
            knee,
            _clip(ankle + ramp * ankle_swing - (hip + knee), limits[first + 3]),
            _clip(-roll, limits[first + 4]),
        )


class StrideCpg(ExtendedCpg):
    """The stride controller: the extended one with the knee lift at a free phase of the leg's
    swing and an ankle swing (a push-off) at another."""

    param_names = STRIDE_PARAM_NAMES
    label = "the stride controller"

    def _configure(self, values: Mapping[str, float]) -> None:
        self._knee_s, self._knee_q = _phased(1.0, values["knee_phase"])
        self._push_s, self._push_q = _phased(math.radians(values["push"]), values["push_phase"])

    def _knee_and_ankle(self, s: float, q: float, y: float) -> tuple[float, float]:
        """The knee lifts by knee_lift x max(0, cos(knee_phase) s + sin(knee_phase) q); the
        ankle swings by push x (cos(push_phase) s + sin(push_phase) q)."""
        lift = self._knee_lift * max(0.0, self._knee_s * s + self._knee_q * q)
        return lift, self._push_s * s + self._push_q * q


class SteeredCpg(StrideCpg):
    """The steered controller: the stride one, steering back to the heading it started with
    by stepping further with one leg than with the other."""

    param_names = STEERED_PARAM_NAMES
    label = "the steered controller"

    def _configure(self, values: Mapping[str, float]) -> None:
        super()._configure(values)
        self._steer = values["steer"]

    def _hip_swings(self, sensors: Sensors) -> tuple[float, float]:
        """hip_swing x (1 + u) on the left and x (1 - u) on the right, u = steer x yaw within
        +-STEER_LIMIT: turned left (yaw > 0), the left leg steps further and turns it back."""
        u = _clip(self._steer * sensors.yaw, (-STEER_LIMIT, STEER_LIMIT))
        return self._hip_swing * (1.0 + u), self._hip_swing * (1.0 - u)


class BalancedCpg(SteeredCpg):
    """The balanced controller: the steered one, moving both hips' pitch with the torso's pitch
    and its rate (positive gains place the feet further ahead as the torso pitches forward, a
    stepping strategy; negative ones extend the hips, pulling the torso back upright)."""

    param_names = BALANCED_PARAM_NAMES
    label = "the balanced controller"

    def _configure(self, values: Mapping[str, float]) -> None:
        super()._configure(values)
        self._place_gain, self._place_rate = values["place_gain"], values["place_rate"]
        self._last_pitch: float | None = None

    def reset(self) -> None:
        super().reset()
        self._last_pitch = None

    def _placement(self, sensors: Sensors) -> float:
        """place_gain x pitch + place_rate x (pitch - the last step's pitch) / control step."""
        last = sensors.pitch if self._last_pitch is None else self._last_pitch
        self._last_pitch = sensors.pitch
        rate = (sensors.pitch - last) / CONTROL_STEP_S
        return self._place_gain * sensors.pitch + self._place_rate * rate


def _clip(value: float, limits: tuple[float, float]) -> float:
    lower, upper = limits
    return lower if value < lower else upper if value > upper else value
