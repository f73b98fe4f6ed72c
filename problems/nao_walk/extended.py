"""An extended CPG walking controller: the paper's Matsuoka rhythm, with lateral sway, knee lift,
torso feedback and a smooth start (nao-walk's ``controller=extended``).

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

LEFT = ("llj2", "llj3", "llj4", "llj5", "llj6")
RIGHT = ("rlj2", "rlj3", "rlj4", "rlj5", "rlj6")


def extended_space() -> Space:
    """The extended controller's decision variables, named and bounded."""
    return Space([Variable(name, lo, hi, meaning) for name, lo, hi, meaning in _BOUNDS])


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


class ExtendedCpg:
    """The extended controller (module docstring): ten leg joints from one Matsuoka rhythm and
    the torso's roll and pitch."""

    #: The joints it drives, in the order act() returns their targets.
    joints = LEFT + RIGHT

    def __init__(self, params: Sequence[float], limits: Mapping[str, tuple[float, float]]) -> None:
        values = checked_params(params, PARAM_NAMES, "the extended controller")
        (period, self._feedback, hip_bias, hip_swing, knee_bias, knee_lift, ankle_bias, sway,
         sway_phase, self._pitch_gain, self._roll_gain) = values  # fmt: skip
        if period <= 0.0:
            raise ConfigError(f"period must be positive seconds, got {period}")
        steps_per_tau, self._y_peak, self._y_swing, self._v_swing = free_rhythm()
        tau1 = period / CONTROL_STEP_S / steps_per_tau
        self._pair = MatsuokaPair(tau1, TAU_RATIO * tau1, BETA, GAMMA)
        rad = math.pi / 180.0
        self._hip_bias, self._hip_swing = hip_bias * rad, hip_swing * rad
        self._knee_bias, self._knee_lift = knee_bias * rad, knee_lift * rad
        self._ankle_bias = ankle_bias * rad
        phase = sway_phase * rad
        self._sway_s, self._sway_q = sway * rad * math.cos(phase), sway * rad * math.sin(phase)
        missing = [joint for joint in self.joints if joint not in limits]
        if missing:
            raise ConfigError(f"no limits given for {', '.join(missing)}")
        self._limits = [tuple(float(v) for v in limits[joint]) for joint in self.joints]

    @property
    def pair(self) -> MatsuokaPair:
        """The rhythm generator."""
        return self._pair

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
        swing = self._hip_swing * s
        roll = ramp * (self._sway_s * s + self._sway_q * q) + self._roll_gain * sensors.roll
        ankle = ramp * self._ankle_bias + self._pitch_gain * sensors.pitch
        lift = self._knee_lift / self._y_peak
        return (
            *self._leg(ramp * (self._hip_bias + swing),
                       -ramp * (self._knee_bias + lift * y1), ankle, roll, 0),
            *self._leg(ramp * (self._hip_bias - swing),
                       -ramp * (self._knee_bias + lift * y2), ankle, roll, 5),
        )  # fmt: skip

    def _leg(
        self, hip: float, knee: float, ankle: float, roll: float, first: int
    ) -> tuple[float, float, float, float, float]:
        """One leg's clipped (hip roll, hip, knee, ankle, ankle roll); the ankle pitch keeps
        the foot parallel to the torso (from the clipped hip and knee) plus ``ankle``."""
        limits = self._limits
        hip = _clip(hip, limits[first + 1])
        knee = _clip(knee, limits[first + 2])
        return (
            _clip(roll, limits[first]),
            hip,
            knee,
            _clip(ankle - (hip + knee), limits[first + 3]),
            _clip(-roll, limits[first + 4]),
        )


def _clip(value: float, limits: tuple[float, float]) -> float:
    lower, upper = limits
    return lower if value < lower else upper if value > upper else value
