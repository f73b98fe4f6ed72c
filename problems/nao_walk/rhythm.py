"""A walk's rhythm: the dominant period and the swing of the leg joints of a recorded episode.

The paper reports its best gait's period (0.1 s); these numbers say what a found gait does, in
the paper's angle convention (figures.paper_angles), after the first SETTLE_S seconds of
walking (episode.py), when the start-up transient has passed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .episode import SETTLE_S

MIN_SWING_DEG = 0.5
"""A hip swing smaller than this (peak to peak) has no period worth naming."""

MIN_SAMPLES = 50
"""Control steps (1 s) needed after SETTLE_S for a period."""


@dataclass(frozen=True)
class Rhythm:
    """Peak-to-peak swings (degrees) of the left leg's measured and commanded angles, and the
    dominant period (s) of its measured hip angle; NaN where the walk gives too little."""

    period: float
    hip_swing: float
    knee_swing: float
    ankle_swing: float
    hip_target_swing: float
    knee_target_swing: float
    ankle_target_swing: float


def rhythm(trajectory: dict[str, np.ndarray], control_step: float = 0.02) -> Rhythm:
    """The rhythm of a recorded walk (EpisodeRunner.run(..., record=True))."""
    from .figures import paper_angles  # the angle convention lives with the figures

    keep = trajectory["time"] > SETTLE_S
    measured = paper_angles(trajectory, "angle")[keep]
    targets = paper_angles(trajectory, "target")[keep]
    if len(measured) == 0:
        return Rhythm(*(math.nan,) * 7)
    swing, target_swing = np.ptp(measured[:, :3], axis=0), np.ptp(targets[:, :3], axis=0)
    period = math.nan
    hip = measured[:, 0]
    if len(hip) >= MIN_SAMPLES and swing[0] >= MIN_SWING_DEG:
        spectrum = np.abs(np.fft.rfft(hip - hip.mean()))
        frequencies = np.fft.rfftfreq(len(hip), control_step)
        period = float(1.0 / frequencies[1 + int(np.argmax(spectrum[1:]))])
    return Rhythm(period, *map(float, swing), *map(float, target_swing))


def describe(walk: Rhythm) -> str:
    """One line for a figure's title: the period and the hip and knee swings."""
    period = "no rhythm" if math.isnan(walk.period) else f"period {walk.period:.2f} s"
    return (
        f"{period}; swing hip {walk.hip_swing:.1f}° (commanded {walk.hip_target_swing:.1f}°), "
        f"knee {walk.knee_swing:.1f}° ({walk.knee_target_swing:.1f}°)"
    )
