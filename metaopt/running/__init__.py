"""Running an optimizer on a problem: the run loop asks the optimizer, has an executor evaluate,
stores every evaluation, tells the results, and owns budget, seeds, checkpoints, progress and
interruption.

Optimizers and problems never touch processes, files or the terminal; this package does,
through an Executor, a RunStore and an optional Progress observer. ``spec`` says what a run is,
``launch`` starts, checks and resumes one, ``session`` is the loop itself, ``signals`` how a run
is stopped from outside.

Modes: ``sync`` asks a fixed batch, evaluates it (on any executor), and tells the results in
index order, so a run depends only on its seed and settings. ``async`` keeps every worker busy:
a steady-state optimizer is asked for a new candidate whenever one finishes; faster, but the
order of results (and so the run) depends on timing.
"""

from metaopt.running.launch import check_resume, check_run, resume, run
from metaopt.running.signals import RunInterrupted, stop_on_sigterm
from metaopt.running.spec import (
    COMMON_SEEDS,
    MAX_TIME_STOP,
    MODES,
    Progress,
    RunResult,
    RunSettings,
    RunSpec,
    common_seeds_mode,
)

__all__ = [
    "COMMON_SEEDS",
    "MAX_TIME_STOP",
    "MODES",
    "Progress",
    "RunInterrupted",
    "RunResult",
    "RunSettings",
    "RunSpec",
    "check_resume",
    "check_run",
    "common_seeds_mode",
    "resume",
    "run",
    "stop_on_sigterm",
]
