"""nao-walk's rhythm measure: the period and swings of a recorded walk, checked on synthetic
trajectories of known period and amplitude, and on a real recorded episode's figure."""

from __future__ import annotations

import math

import numpy as np
import pytest

from metaopt_problems.nao_walk.episode import DRIVEN_JOINTS
from metaopt_problems.nao_walk.rhythm import describe, rhythm


def _trajectory(period_s: float, hip_amplitude_deg: float, seconds: float = 12.0) -> dict:
    """A walk whose left hip swings sinusoidally (server angle llj3 = -paper hip), knee and
    ankle at twice and half the hip's amplitude, commanded 3x what is measured."""
    time = np.arange(0.0, seconds, 0.02)
    wave = np.radians(hip_amplitude_deg) * np.sin(2 * np.pi * time / period_s)
    measured = {"llj3": -wave, "llj4": 2 * wave, "llj5": -0.5 * wave}
    trajectory = {"time": time}
    for joint in DRIVEN_JOINTS:
        angle = measured.get(joint, np.zeros_like(time))
        trajectory[f"{joint}_angle"] = angle
        trajectory[f"{joint}_target"] = 3 * angle
    return trajectory


@pytest.mark.parametrize("period", [0.08, 0.4, 1.0])  # quarter periods on the 20 ms grid
def test_period_and_swings_of_a_known_sine(period: float) -> None:
    walk = rhythm(_trajectory(period, 4.0))
    assert walk.period == pytest.approx(period, rel=0.02)
    assert walk.hip_swing == pytest.approx(8.0, rel=0.01)  # peak to peak
    assert walk.knee_swing == pytest.approx(16.0, rel=0.01)
    assert walk.ankle_swing == pytest.approx(4.0, rel=0.01)
    assert walk.hip_target_swing == pytest.approx(24.0, rel=0.01)
    assert f"period {period:.2f} s" in describe(walk)


def test_a_still_or_short_walk_has_no_period() -> None:
    assert math.isnan(rhythm(_trajectory(0.5, 0.1)).period)  # 0.2 deg swing: no rhythm
    assert math.isnan(rhythm(_trajectory(0.5, 4.0, seconds=2.5)).period)  # 0.5 s after settling
    assert "no rhythm" in describe(rhythm(_trajectory(0.5, 0.1)))
    assert all(math.isnan(v) for v in vars(rhythm(_trajectory(0.5, 4.0, seconds=1.0))).values())


def test_the_joint_angle_figure_names_the_rhythm_of_a_real_walk() -> None:
    from metaopt.plugins import registry

    problem = registry().problem("nao-walk").factory(backend="ode", duration=6.0)
    try:
        x = problem.space.lower + 0.5 * (problem.space.upper - problem.space.lower)
        result = problem.runner.run(problem.gait(x), record=True)
        title = problem.figures(x, 0)["joint_angles"]._suptitle.get_text()
    finally:
        problem.close()
    assert describe(rhythm(result.trajectory)) in title
