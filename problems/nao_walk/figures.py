"""The paper's figures of one walk (Figs. 6-10): joint angles, lateral drift, torso height.

Drawn from a recorded episode (EpisodeRunner.run(..., record=True)); angles in the paper's
convention (controller.paper_angles_deg: hip = -lj3, knee = +lj4, ankle = -lj5, degrees).
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from .controller import paper_angles_deg
from .episode import DRIVEN_JOINTS, EpisodeResult
from .rhythm import describe, rhythm

#: Panels of the joint-angle figure: (label, paper figure, column of paper_angles_deg for the
#: left leg; the right leg's is 3 further).
JOINT_PANELS = (("hip", 6, 0), ("knee", 7, 1), ("ankle", 8, 2))
LEFT_COLOUR, RIGHT_COLOUR = "tab:blue", "tab:orange"
TIME_LABEL = "time since walking began (s)"


def paper_angles(trajectory: dict[str, np.ndarray], kind: str) -> np.ndarray:
    """(steps, 6) angles in degrees, paper convention, of the recorded ``kind`` ("target" or
    "angle") of DRIVEN_JOINTS: left hip, knee, ankle, right hip, knee, ankle."""
    server = np.column_stack([trajectory[f"{joint}_{kind}"] for joint in DRIVEN_JOINTS])
    return np.array([paper_angles_deg(row) for row in server]).reshape(-1, 6)


def walk_figures(result: EpisodeResult, engine: str) -> dict[str, Figure]:
    """joint_angles (Figs. 6-8), drift (Fig. 9) and torso_height (Fig. 10) of a recorded walk."""
    if result.trajectory is None:
        raise ValueError("walk_figures needs an episode run with record=True")
    trajectory = result.trajectory
    outcome = f"{result.distance:.2f} m forward, drift {result.drift:+.3f} m" + (
        f", fell after {result.time_walked:.1f} s" if result.fell else ""
    )
    return {
        "joint_angles": _joint_angles(
            trajectory, f"Joint angles ({engine}; {outcome})\n{describe(rhythm(trajectory))}"
        ),
        "drift": _over_time(
            trajectory, "y", "lateral position Y of the torso (m)",
            f"Lateral drift, Fig. 9 ({engine}; {outcome})",
        ),
        "torso_height": _over_time(
            trajectory, "z", "torso centre height Z (m)",
            f"Torso height, Fig. 10 ({engine}; {outcome})",
        ),
    }  # fmt: skip


def _joint_angles(trajectory: dict[str, np.ndarray], title: str) -> Figure:
    time = trajectory["time"]
    targets = paper_angles(trajectory, "target")
    measured = paper_angles(trajectory, "angle")
    figure = Figure(figsize=(6.4, 7.2), layout="constrained")
    axes = figure.subplots(3, 1, sharex=True)
    for ax, (joint, paper_figure, column) in zip(axes, JOINT_PANELS):
        for side, offset, colour in (("left", 0, LEFT_COLOUR), ("right", 3, RIGHT_COLOUR)):
            ax.plot(time, targets[:, column + offset], color=colour, lw=1.2,
                    label=f"{side} target (CPG)")  # fmt: skip
            ax.plot(time, measured[:, column + offset], color=colour, lw=0.8, ls="--",
                    label=f"{side} measured")  # fmt: skip
        ax.set_ylabel(f"{joint} (deg)")
        ax.set_title(f"{joint}, Fig. {paper_figure}", fontsize="medium")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize="small", ncols=2)
    axes[-1].set_xlabel(TIME_LABEL)
    figure.suptitle(f"{title}\npaper convention: negative = flexion", fontsize="medium")
    return figure


def _over_time(trajectory: dict[str, np.ndarray], column: str, label: str, title: str) -> Figure:
    figure = Figure(figsize=(6.4, 3.6), layout="constrained")
    ax = figure.subplots()
    ax.plot(trajectory["time"], trajectory[column], color="tab:green", lw=1.2)
    ax.set_xlabel(TIME_LABEL)
    ax.set_ylabel(label)
    ax.set_title(title, fontsize="medium")
    ax.grid(alpha=0.3)
    return figure
