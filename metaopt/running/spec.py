"""What a run is: its settings (scheduling, seeds, stopping), the spec that names its plugins,
budget and seed, the result it reports, and the progress observer it informs."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from metaopt.errors import ConfigError
from metaopt.optimizer import MAX_BUDGET, MAX_POPULATION, Optimizer
from metaopt.resampling import AGGREGATES

MODES = ("sync", "async")
#: who shares seeds (common random numbers): nobody, every candidate of the run, or of a batch
COMMON_SEEDS = ("off", "run", "batch")


def common_seeds_mode(stored: bool | str) -> str:
    """The common-seeds setting as one of COMMON_SEEDS: runs stored before "batch" existed
    hold True (the run's seeds) or False (off)."""
    if isinstance(stored, bool):
        return "run" if stored else "off"
    return stored


class Progress(Protocol):
    """What the run loop tells an observer (the CLI's progress bar) as a run goes on."""

    def start(self, total: int, done: int) -> None:
        """The run starts (or resumes) with ``done`` of ``total`` evaluations behind it."""

    def update(self, done: int, best: float | None) -> None:
        """``done`` evaluations are finished; ``best`` is the best fitness so far."""


#: Start points past the budget are never evaluated, and a run stores its optimizer's initial
#: population as its start points even where the budget is smaller (resumes must accept it):
#: more than the budget's candidates is refused only past this, where it is a slip, not a
#: population (each is a row of the problem's width in memory).
MAX_START_POINTS = 1_000_000
#: how the message of a run that stopped at its max time begins (it can be resumed for more)
MAX_TIME_STOP = "stopped at its max time"


@dataclass
class RunSettings:
    """How evaluations are scheduled; stored with the run so a resume continues alike."""

    mode: str = "sync"
    #: sync mode: candidates asked per batch (0 = the optimizer's preferred batch size).
    batch: int = 0
    #: evaluations per candidate, each with its own seed; the fitness is aggregated.
    resample: int = 1
    aggregate: str = "mean"
    #: seconds an evaluation may take before it is stopped and stored as failed (None = no limit)
    time_limit: float | None = None
    #: common random numbers (docs/scaling.md): "run" gives every candidate the same resample
    #: seeds, "batch" every candidate of a sync batch (fresh seeds per batch), "off" (the
    #: default) each evaluation a seed of its own. Runs stored as True/False read as run/off.
    common_seeds: str = "off"
    #: stop once a fitness this good is found: at or below it (minimize), at or above (maximize)
    target: float | None = None
    #: seconds of wall time (from this start or resume, the workers' start-up included) after
    #: which no more candidates are asked: the batch in flight finishes and the run ends
    #: finished, its budget unspent (None = no limit). In sync mode the evaluations done are
    #: the first ones of the same run (seed, budget) given more time.
    max_time: float | None = None
    #: warm start (metaopt.warm_start): the run's first start_points candidates are these
    #: points and points drawn within ±start_spread of each range around them in turn, in
    #: place of the optimizer's first asks (0 points = the optimizer's initial population);
    #: None = none. One point may be given flat (as runs stored before several could be).
    start: list[list[float]] | None = None
    start_spread: float = 0.05
    start_points: int = 0
    #: where the start points came from (stored candidates' names, runs), for people
    start_from: str | None = None
    #: screen every candidate first (Problem.screen, a cheap optimistic bound) and complete
    #: only those that can still enter the ranks the optimizer's update reads
    #: (Optimizer.selected); the others are told their bound and stored as 'screened'
    screen: bool = False

    def __post_init__(self) -> None:
        self.common_seeds = common_seeds_mode(self.common_seeds)
        if self.start is not None and all(isinstance(v, int | float) for v in self.start):
            self.start = [list(self.start)]

    def batch_size(self, optimizer: Optimizer) -> int:
        """Candidates asked per sync batch: the given batch, or the optimizer's own."""
        return self.batch or optimizer.batch_size

    def check(self, budget: int) -> None:
        """ConfigError naming the bad setting, or a budget outside 1 to MAX_BUDGET."""
        if not 1 <= budget <= MAX_BUDGET:
            raise ConfigError(
                f"budget must be a positive number of evaluations, at most {MAX_BUDGET} (a "
                f"run store keeps 64-bit integers), got {budget}"
            )
        if self.mode not in MODES:
            raise ConfigError(f"unknown mode {self.mode!r}; accepted: {', '.join(MODES)}")
        if self.aggregate not in AGGREGATES:
            raise ConfigError(f"unknown aggregate {self.aggregate!r}; accepted: mean, median")
        if not 0 <= self.batch <= MAX_POPULATION:
            raise ConfigError(
                f"batch must be 0 (the optimizer's own) to {MAX_POPULATION:,} (more would fill "
                f"memory), got {self.batch}"
            )
        if self.resample < 1:
            raise ConfigError(f"resample must be at least 1, got {self.resample}")
        if self.common_seeds not in COMMON_SEEDS:
            raise ConfigError(
                f"unknown common seeds {self.common_seeds!r}; accepted: {', '.join(COMMON_SEEDS)}"
            )
        if self.common_seeds == "batch" and self.mode != "sync":
            raise ConfigError(
                "common seeds per batch are shared by the candidates of a sync batch: "
                "run in sync mode (no --mode async), or use --common-seeds run"
            )
        if budget < self.resample:
            raise ConfigError(
                f"budget {budget} is smaller than resample {self.resample}: "
                "not one candidate could be evaluated"
            )
        if self.time_limit is not None and not self.time_limit > 0:
            raise ConfigError(f"time limit must be positive seconds, got {self.time_limit}")
        if self.target is not None and not math.isfinite(self.target):
            raise ConfigError(f"target must be a finite fitness, got {self.target}")
        if self.max_time is not None and not 0 < self.max_time < math.inf:
            raise ConfigError(f"max time must be positive, finite seconds, got {self.max_time}")
        if not 0.0 <= self.start_spread <= 1.0:
            raise ConfigError(
                f"start spread must be a share of each range in [0, 1], got {self.start_spread}"
            )
        if self.screen and (self.mode != "sync" or self.resample != 1):
            raise ConfigError(
                "screening ranks a whole batch at once: it runs in sync mode with one "
                "evaluation per candidate (no --resample, no --mode async)"
            )
        if self.start_points < 0:
            raise ConfigError(
                f"start points must be 0 (the optimizer's initial population) or more, "
                f"got {self.start_points}"
            )
        candidates = budget // self.resample
        if self.start_points > max(candidates, MAX_START_POINTS):
            raise ConfigError(
                f"{self.start_points} start points are more than the {candidates} candidates "
                f"the budget evaluates (budget {budget}, resample {self.resample}) and more "
                f"than {MAX_START_POINTS}; ask for at most {max(candidates, MAX_START_POINTS)} "
                f"(the run evaluates only the first {candidates})"
            )


@dataclass
class RunSpec:
    """Everything that defines a run: plugins, their parameters, budget, seed and scheduling."""

    optimizer: str
    problem: str
    budget: int
    seed: int
    optimizer_params: dict[str, Any] = field(default_factory=dict)
    problem_params: dict[str, Any] = field(default_factory=dict)
    settings: RunSettings = field(default_factory=RunSettings)


@dataclass
class RunResult:
    """What a finished (or interrupted) run reports. With resampling, fitness and metrics are
    the best candidate's aggregates."""

    run_id: int
    status: str
    evaluations: int
    failed: int
    #: evaluations of which only the screen ran (``RunSettings.screen``), told their bound
    screened: int
    best_fitness: float | None
    best_x: np.ndarray | None
    best_metrics: dict[str, float]
    wall_time: float
    names: tuple[str, ...]
    key_metrics: tuple[str, ...]
