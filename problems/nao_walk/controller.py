"""The paper's walking controller: a Matsuoka pair (eqs 1-4) and the linear layer of Fig. 3.

Units and conventions (docs/nao-walk.md, "The controller", explains them):

* time constants tau1, tau2 are in control steps of 20 ms;
* the oscillator's outputs feed linear neurons whose weights and biases give joint angles in
  degrees, in the paper's convention (hip and knee pitch negative when the leg flexes);
* feedback u_f1, u_f2 are the measured hip pitch angles in the paper's convention, in radians;
* step() takes and returns the simulator's (server's) joint angles in radians:
  lj3 = -paper_hip, lj4 = +paper_knee, and lj5 = -(lj3 + lj4) keeps the foot parallel to the torso.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from metaopt import ConfigError, Space, Variable

if TYPE_CHECKING:
    from .episode import Sensors

PARAM_NAMES: tuple[str, ...] = (
    "tau1",
    "tau2",
    "alpha",
    "beta",
    "gamma",
    "c",
    "w11",
    "w12",
    "b1",
    "b2",
)

CONTROL_STEP_S = 0.02
"""One control step (50 Hz); tau1 and tau2 are counted in these steps."""

TAU_MIN = 0.5
"""Lower bound of tau1, tau2 (Table 2 prints 0, which the equations cannot take), in steps.

Half a step (10 ms): the rhythm's period scales with tau2 and, at this bound, already falls to
2-5 steps, the Nyquist limit of the 50 Hz joint commands; faster rhythms cannot be represented
by the commands (nor followed by the 7 deg/step servos) and would only cost integration work.
"""

SUBSTEP_FRACTION = 0.25
"""Integration substeps are at most this fraction of min(tau1, tau2): 1 to 8 per control step."""

INITIAL_X1 = 0.1
"""Initial x1 (x2, v1, v2 start at 0): the asymmetry that lets the left element win first."""

STATE_LIMIT = 1e6
"""Saturation of the oscillator state; reached only where eqs 1-4 themselves diverge."""

_BOUNDS: tuple[tuple[float, float, str], ...] = (
    (TAU_MIN, 25.0, "time constant of the membrane states x1, x2 (control steps of 20 ms)"),
    (TAU_MIN, 25.0, "time constant of the adaptation states v1, v2 (control steps of 20 ms)"),
    (-5.0, 5.0, "gain of the hip-angle feedback u_f (per radian)"),
    (-5.0, 5.0, "strength of self-adaptation (dimensionless)"),
    (-5.0, 5.0, "mutual inhibition between the two elements (dimensionless)"),
    (2.0, 4.0, "tonic input (dimensionless; Table 2 prints the bounds reversed)"),
    (-4.0, 1.0, "weight from an element's output to its hip neuron (degrees per unit)"),
    (-5.0, 0.0, "weight from an element's output to its knee neuron (degrees per unit)"),
    (-95.0, 20.0, "bias of the hip neurons (degrees, paper convention)"),
    (-125.0, -5.0, "bias of the knee neurons (degrees, paper convention)"),
)


#: The output weights, whose bounds ``weight_scale`` widens.
WEIGHT_NAMES = ("w11", "w12")


def cpg_space(weight_scale: float = 1.0) -> Space:
    """The 10 decision variables in the paper's order with Table 2's bounds (slips fixed).

    ``weight_scale`` multiplies the bounds of the output weights w11 and w12: Table 2 read as
    if its weights were in other units, the knob of the experiment that asks whether Table 2's
    few degrees of joint swing are what keeps the paper's controller from walking.
    """
    return Space(
        [
            Variable(
                name,
                lower * weight_scale if name in WEIGHT_NAMES else lower,
                upper * weight_scale if name in WEIGHT_NAMES else upper,
                description,
            )
            for name, (lower, upper, description) in zip(PARAM_NAMES, _BOUNDS)
        ]
    )


def oscillation_conditions_hold(params: Sequence[float]) -> bool:
    """Matsuoka's conditions for a sustained rhythm of the free pair (alpha = 0).

    c > 0 and 1 + tau1/tau2 < gamma < 1 + beta: the symmetric equilibrium is unstable (left
    bound) and no state with one element permanently on exists (right bound).
    """
    tau1, tau2, _, beta, gamma, c = _checked(params)[:6]
    return c > 0.0 and 1.0 + tau1 / tau2 < gamma < 1.0 + beta


def matsuoka_period(params: Sequence[float]) -> float | None:
    """Period of the free rhythm (control steps) by Matsuoka's describing-function estimate.

    omega = (1/tau2) * sqrt((tau1 + tau2) * beta / (tau1 * gamma) - 1); None where the
    oscillation conditions fail. Accurate near the onset of oscillation, too short in the
    relaxation regime (gamma near 1 + beta).
    """
    if not oscillation_conditions_hold(params):
        return None
    tau1, tau2, _, beta, gamma = _checked(params)[:5]
    omega = math.sqrt((tau1 + tau2) * beta / (tau1 * gamma) - 1.0) / tau2
    return 2.0 * math.pi / omega


def paper_angles_deg(targets: Sequence[float]) -> tuple[float, float, float, float, float, float]:
    """Server joint angles (llj3, llj4, llj5, rlj3, rlj4, rlj5; rad) in the paper's convention.

    Returns (left hip, left knee, left ankle, right hip, right knee, right ankle) in degrees,
    negative when the leg flexes, as in the paper's Table 1 and figures.
    """
    lhip, lknee, lankle, rhip, rknee, rankle = (math.degrees(a) for a in targets)
    return (-lhip, lknee, -lankle, -rhip, rknee, -rankle)


class MatsuokaPair:
    """Matsuoka's two mutually inhibiting neurons (eqs 1-4), advanced one control step at a time.

    Integration: each element's own (x, v) loop is linear between switches of its rectifier and
    is integrated exactly (precomputed matrix exponential); the mutual inhibition is coupled by
    a symmetric predictor-corrector (exponential Heun), so left and right are treated alike.
    Substeps are at most SUBSTEP_FRACTION * min(tau1, tau2).
    """

    def __init__(self, tau1: float, tau2: float, beta: float, gamma: float) -> None:
        for label, value in (("tau1", tau1), ("tau2", tau2)):
            if value < TAU_MIN:
                raise ConfigError(
                    f"{label} = {value} control steps; time constants must be >= {TAU_MIN} "
                    "(the equations divide by them; faster rhythms cannot be commanded at 50 Hz)"
                )
        self._gamma, self._half_gamma = gamma, 0.5 * gamma
        self._n_substeps = max(1, math.ceil(1.0 / (SUBSTEP_FRACTION * min(tau1, tau2))))
        h = 1.0 / self._n_substeps
        self._on = _element_propagator(tau1, tau2, beta, True, h)
        self._off = _element_propagator(tau1, tau2, beta, False, h)
        self.reset()

    def reset(self) -> None:
        """Back to the initial state: x1 = INITIAL_X1, x2 = v1 = v2 = 0."""
        self.x1, self.x2, self.v1, self.v2 = INITIAL_X1, 0.0, 0.0, 0.0

    @property
    def outputs(self) -> tuple[float, float]:
        """The elements' outputs y1 = [x1]+, y2 = [x2]+ after the last step."""
        return max(self.x1, 0.0), max(self.x2, 0.0)

    def advance(self, drive1: float, drive2: float) -> tuple[float, float]:
        """One control step with the elements' tonic drives (c plus feedback) held; returns the
        outputs (y1, y2)."""
        gamma, half_gamma = self._gamma, self._half_gamma
        on, off = self._on, self._off
        x1, x2, v1, v2 = self.x1, self.x2, self.v1, self.v2
        for _ in range(self._n_substeps):
            y1 = x1 if x1 > 0.0 else 0.0
            y2 = x2 if x2 > 0.0 else 0.0
            a11, a12, a21, a22, g1, g2 = on if x1 > 0.0 else off
            b11, b12, b21, b22, h1, h2 = on if x2 > 0.0 else off
            # Predictor: each element sees the other's activity held at the substep start.
            p1 = a11 * x1 + a12 * v1 + g1 * (drive1 - gamma * y2)
            p2 = b11 * x2 + b12 * v2 + h1 * (drive2 - gamma * y1)
            # Corrector: the other's activity averaged over the substep (trapezoid rule).
            i1 = drive1 - half_gamma * (y2 + (p2 if p2 > 0.0 else 0.0))
            i2 = drive2 - half_gamma * (y1 + (p1 if p1 > 0.0 else 0.0))
            x1, v1 = a11 * x1 + a12 * v1 + g1 * i1, a21 * x1 + a22 * v1 + g2 * i1
            x2, v2 = b11 * x2 + b12 * v2 + h1 * i2, b21 * x2 + b22 * v2 + h2 * i2
        if max(abs(x1), abs(x2), abs(v1), abs(v2)) > STATE_LIMIT:
            x1, x2, v1, v2 = (max(-STATE_LIMIT, min(STATE_LIMIT, s)) for s in (x1, x2, v1, v2))
        self.x1, self.x2, self.v1, self.v2 = x1, x2, v1, v2
        return (x1 if x1 > 0.0 else 0.0), (x2 if x2 > 0.0 else 0.0)


class MatsuokaCpg:
    """The paper's controller: a MatsuokaPair -> linear hip/knee neurons -> server joint
    targets, one 20 ms step at a time. Element 1 drives the left leg, element 2 the right; both
    legs share w11, w12, b1, b2."""

    #: The joints it drives, in the order step() returns their targets.
    joints = ("llj3", "llj4", "llj5", "rlj3", "rlj4", "rlj5")

    def __init__(
        self,
        params: Sequence[float],
        hip_limits: tuple[float, float],
        knee_limits: tuple[float, float],
        ankle_limits: tuple[float, float],
    ) -> None:
        tau1, tau2, alpha, beta, gamma, c, w11, w12, b1, b2 = _checked(params)
        self._pair = MatsuokaPair(tau1, tau2, beta, gamma)
        self._hip_limits = _checked_limits("hip", hip_limits)
        self._knee_limits = _checked_limits("knee", knee_limits)
        self._ankle_limits = _checked_limits("ankle", ankle_limits)
        self._c, self._alpha = c, alpha
        rad = math.pi / 180.0
        # Server hip = -(paper hip), server knee = +(paper knee), both in radians.
        self._hip_gain, self._hip_offset = -w11 * rad, -b1 * rad
        self._knee_gain, self._knee_offset = w12 * rad, b2 * rad

    def reset(self) -> None:
        """Back to the initial state: x1 = INITIAL_X1, x2 = v1 = v2 = 0."""
        self._pair.reset()

    @property
    def outputs(self) -> tuple[float, float]:
        """The elements' outputs y1 = [x1]+, y2 = [x2]+ (left, right) after the last step."""
        return self._pair.outputs

    def act(self, sensors: Sensors) -> tuple[float, float, float, float, float, float]:
        """The Gait interface (episode.py): step() on the sensed hip angles."""
        return self.step(sensors.left_hip, sensors.right_hip)

    def step(
        self, left_hip: float, right_hip: float
    ) -> tuple[float, float, float, float, float, float]:
        """One control step; clipped targets (llj3, llj4, llj5, rlj3, rlj4, rlj5) in radians.

        left_hip, right_hip: measured server hip pitch llj3, rlj3 (rad, finite). The feedback
        term -alpha * u_f with u_f = -lj3 (paper convention) becomes +alpha * lj3.
        """
        y1, y2 = self._pair.advance(
            self._c + self._alpha * left_hip, self._c + self._alpha * right_hip
        )
        return (*self._leg_targets(y1), *self._leg_targets(y2))

    def _leg_targets(self, y: float) -> tuple[float, float, float]:
        """One leg's (lj3, lj4, lj5) for element output y; the ankle uses the clipped hip, knee."""
        hip_lo, hip_hi = self._hip_limits
        knee_lo, knee_hi = self._knee_limits
        ankle_lo, ankle_hi = self._ankle_limits
        hip = self._hip_gain * y + self._hip_offset
        hip = hip_lo if hip < hip_lo else hip_hi if hip > hip_hi else hip
        knee = self._knee_gain * y + self._knee_offset
        knee = knee_lo if knee < knee_lo else knee_hi if knee > knee_hi else knee
        ankle = -(hip + knee)
        ankle = ankle_lo if ankle < ankle_lo else ankle_hi if ankle > ankle_hi else ankle
        return hip, knee, ankle


def _checked(params: Sequence[float]) -> tuple[float, ...]:
    """The 10 parameters as floats, or a ConfigError naming what is wrong."""
    return checked_params(params, PARAM_NAMES, "the Matsuoka controller")


def checked_params(
    params: Sequence[float], names: Sequence[str], controller: str
) -> tuple[float, ...]:
    """A controller's parameters (``names``, in order) as floats, or a ConfigError naming what
    is wrong."""
    values = tuple(float(p) for p in params)
    if len(values) != len(names):
        raise ConfigError(
            f"{controller} takes {len(names)} parameters ({', '.join(names)}); got {len(values)}"
        )
    bad = [name for name, value in zip(names, values) if not math.isfinite(value)]
    if bad:
        raise ConfigError(
            f"controller parameters must be finite numbers; not finite: {', '.join(bad)}"
        )
    return values


def _checked_limits(joint: str, limits: tuple[float, float]) -> tuple[float, float]:
    """(lower, upper) joint limits in radians, lower < upper."""
    lower, upper = (float(v) for v in limits)
    if not lower < upper:
        raise ConfigError(f"{joint} limits must be (lower, upper) with lower < upper; got {limits}")
    return lower, upper


def _element_propagator(
    tau1: float, tau2: float, beta: float, active: bool, h: float
) -> tuple[float, float, float, float, float, float]:
    """Exact flow over h of one element's (x, v) loop for a constant net input I.

    With the rectifier [x]+ fixed on (active) or off, tau1 x' = I - x - beta v and
    tau2 v' = [x]+ - v are linear: (x, v)(h) = F (x, v)(0) + g I. Returns (F11, F12, F21, F22,
    g1, g2), read off the exponential of the augmented matrix [[A, e1/tau1], [0, 0]] * h.
    """
    augmented = np.array(
        [
            [-1.0 / tau1, -beta / tau1, 1.0 / tau1],
            [(1.0 if active else 0.0) / tau2, -1.0 / tau2, 0.0],
            [0.0, 0.0, 0.0],
        ]
    )
    flow = _expm(augmented * h)
    return (
        float(flow[0, 0]),
        float(flow[0, 1]),
        float(flow[1, 0]),
        float(flow[1, 1]),
        float(flow[0, 2]),
        float(flow[1, 2]),
    )


def _expm(matrix: np.ndarray) -> np.ndarray:
    """Matrix exponential of a small matrix by scaling and squaring a Taylor series.

    The scaled matrix has norm <= 0.5, where 20 terms reach machine precision.
    """
    norm = float(np.abs(matrix).sum(axis=1).max())
    squarings = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scaled = matrix / 2.0**squarings
    term = np.eye(len(matrix))
    result = term.copy()
    for k in range(1, 21):
        term = term @ scaled / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result
