"""nao-walk's standard perturbation table (docs/robustness.md): the worlds a gait is tried in
by ``metaopt robustness``. Change a cell, and the version, together."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, cast

from metaopt.assessment.robustness import Perturbation, PerturbationTable

if TYPE_CHECKING:
    from metaopt.problem import Problem

    from .plugin import NaoWalk

#: Every cell runs at this background noise (friction within ±2 %, a 5 mm/s push as walking
#: starts, 0.1° of hip sensor error), so that N seeds are N different episodes of a chaotic
#: walk: the table's figures are statistics, not single trajectories.
BACKGROUND_NOISE = 0.1


#: The push cells' impulse, N·s (about 0.22 m/s on the 4.6 kg robot); worlds=pushes draws
#: pushes of this size too.
PUSH_IMPULSE = 1.0


def unlimited_friction(problem: Problem) -> str | None:
    """Why a friction cell changes nothing on the problem's engine (a nao-walk on one): its
    ground friction is unlimited (ODE's default, the paper's server), which no scale changes;
    None otherwise."""
    walk = cast("NaoWalk", problem)
    (engine,) = walk.engines
    if math.isinf(walk.physics_on[engine].friction):
        return "its ground friction is unlimited (the server's): no coefficient to scale"
    return None


#: The parameters that make an evaluation draw its world; a world drawn is walked without them.
UNSAMPLED = {"worlds": "none", "world_cells": "", "cell_durations": ""}


#: Every cell starts from the gait's parameters with these perturbations at their nominal
#: values, so that a gait searched in a perturbed world (a push, a latency, a heavier robot,
#: sampled worlds) is tried in the table's worlds, not in its own plus each cell's.
NOMINAL_WORLD = {"friction_scale": 1.0, "mass_scale": 1.0, "push": 0.0, "latency": 0,
                 **UNSAMPLED}  # fmt: skip


STANDARD_TABLE = PerturbationTable(
    # nao-walk-3: every cell starts from the nominal world (NOMINAL_WORLD); nao-walk-2 started
    # from the gait's own perturbations, and left the friction cells out where the friction is
    # unlimited (on ODE, by default), as nao-walk-3 does; nao-walk-1 ran them there, repeating
    # the nominal world
    version="nao-walk-3",
    cells=(
        Perturbation("nominal", "the gait's own settings, unperturbed"),
        Perturbation("friction x0.7", "ground friction x0.7", scale={"friction_scale": 0.7},
                     inert=unlimited_friction),
        Perturbation("friction x1.3", "ground friction x1.3", scale={"friction_scale": 1.3},
                     inert=unlimited_friction),
        Perturbation("mass x0.9", "every body's mass and inertia x0.9",
                     scale={"mass_scale": 0.9}),
        Perturbation("mass x1.1", "every body's mass and inertia x1.1",
                     scale={"mass_scale": 1.1}),
        Perturbation("servo gain x0.8", "joint servo gain x0.8", scale={"servo_gain": 0.8}),
        Perturbation("servo gain x1.2", "joint servo gain x1.2", scale={"servo_gain": 1.2}),
        Perturbation("push forward", "1 N·s forward on the torso at t = 6 s",
                     set={"push": PUSH_IMPULSE, "push_direction": 0.0, "push_time": 6.0}),
        Perturbation("push sideways", "1 N·s to the left on the torso at t = 6 s",
                     set={"push": PUSH_IMPULSE, "push_direction": 90.0, "push_time": 6.0}),
        Perturbation("latency 1", "the controller senses one control step (20 ms) late",
                     set={"latency": 1}),
        Perturbation("noise 0.5", "nao-walk's seed-drawn noise at 0.5 instead of the "
                     "background 0.1", set={"noise": 0.5}),
    ),
    # time_to_fall (added after nao-walk-3's first tables, which lack it; its cells are
    # unchanged): the median over the episodes that fell of the seconds they walked first
    metrics=("speed", "|drift|", "fell", "flight", "time_to_fall"),
    common={**NOMINAL_WORLD, "noise": BACKGROUND_NOISE, "measure_flight": True},
    only_when={"time_to_fall": "fell"},
)  # fmt: skip
