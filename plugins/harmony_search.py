"""Harmony Search (HS): steady-state improvisation from a harmony memory, with four pitch rules.

Geem, Kim and Loganathan (2001). The harmony memory holds ``hms`` solutions. The first ``hms``
candidates (every candidate asked while the memory is not yet full) are uniform random points
in the bounds; their evaluations fill the memory and count toward the run's budget. Each later
candidate (a *harmony*) is improvised variable by variable: with probability ``hmcr`` the value
of a random memory row is taken and then, with probability PAR, pitch-adjusted; otherwise a
uniform random value is drawn. A told harmony replaces the worst in memory only when strictly
better. ``ask(n)`` improvises n harmonies from the same memory; ``tell`` inserts them one by one.

Pitch adjustment (``pitch_adjust``):

- ``bandwidth`` (classic, Geem 2001): x + U(-1, 1) * bandwidth * (upper - lower).
- ``resample`` (Yazdi and Toroghi Haghighat, section 4): a new uniform value in the bounds.
- ``ihs`` (improved HS, Mahdavi, Fesanghary and Damangir 2007): as ``bandwidth``, but PAR
  rises linearly from ``par_min`` to ``par_max`` and the bandwidth falls exponentially from
  ``bandwidth_max`` to ``bandwidth_min`` over the ``budget - hms`` improvisations of the run.
  The default: its final step, 1e-5 of the range, gives the last digits the classic rule
  cannot (docs/optimizers.md has the comparison).
- ``ghs`` (global-best HS, Omran and Mahdavi 2008): the value of a random variable of the best
  harmony, with IHS's rising PAR. Bounds differ per variable, so such values are repaired.
  Copying a value from one variable to another helps only where the optimum has equal
  coordinates (every classic function's does: 0, 1 or 420.97 in each); on shifted optima, as
  in bbob, it misleads (docs/optimizers.md shows both).

Out-of-bound values are repaired by ``Space.repair`` (``repair``: clip or reflect).

Restarts (``restart_after``, off by default): once that many harmonies in a row have been told
without improving the memory's best, the memory is emptied and refilled with new random
points, as at the start, and the ``ihs``/``ghs`` schedules start again over the budget left.
Harmonies asked before the restart and told after it (the rest of a batch, or those in flight
in async mode) are left out of the new memory: they were improvised from the one emptied. A
memory that has converged on a poor region (a robot that stands still) otherwise stays there
for the rest of the run; the run keeps its best evaluation whatever the memory forgets.

Defaults (hms 20, hmcr 0.95, ihs with PAR 0.01 -> 0.99 and bandwidth 0.05 -> 1e-5) reach
about 2e-8 on the 10-D sphere ([-5.12, 5.12]) in 10,000 evaluations, and about 5e-6 on 10-D
Rastrigin. Before issue 17 the default was the classic rule with hmcr 0.9 (1.7e-4 and 1.0 on
those). For ``ihs`` and ``ghs`` the schedules span ``budget``, which the run loop,
``metaopt.minimize`` and ``metaopt.create_optimizer`` set to the run's budget.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from metaopt import (
    ConfigError,
    Optimizer,
    OptimizerInfo,
    Param,
    Space,
    budget_param,
    hookimpl,
    json_float,
    population_param,
    restore_rng,
    rng_state,
)
from metaopt.space import repair_param

PITCH_ADJUSTMENTS = ("bandwidth", "resample", "ihs", "ghs")
#: Variants whose PAR follows the par_min -> par_max schedule.
SCHEDULED_PAR = ("ihs", "ghs")
#: Values of each kind (memory row, random value, pitch step...) drawn per block of
#: improvisations, whatever the dimension: a block holds BLOCK_VALUES // dim improvisations.
BLOCK_VALUES = 8192
#: Values of harmonies built ahead from the memory at most (PREPARED_VALUES // dim harmonies).
PREPARED_VALUES = 256


class HarmonySearch(Optimizer):
    """Steady-state Harmony Search over a box; minimizes.

    Per-call numpy overhead dominates on small vectors, so the random choices of a block of
    improvisations (which memory row or random value feeds each variable, and the pitch step)
    are drawn at once, and harmonies are built several at a time by a gather from a flat pool
    holding the memory, a copy of the best harmony and the block's random values, until the
    memory changes. The state keeps the generator state at which the current block was drawn
    and the position in it; loading redraws the block.
    """

    steady_state = True

    def __init__(
        self,
        space: Space,
        seed: int,
        *,
        hms: int,
        hmcr: float,
        par: float,
        bandwidth: float,
        pitch_adjust: str,
        par_min: float,
        par_max: float,
        bandwidth_min: float,
        bandwidth_max: float,
        budget: int,
        restart_after: int,
        repair: str,
    ) -> None:
        super().__init__(space, seed)
        if par_min > par_max:
            raise ConfigError(f"hs: par_min ({par_min}) must not exceed par_max ({par_max})")
        if bandwidth_min > bandwidth_max:
            raise ConfigError(
                f"hs: bandwidth_min ({bandwidth_min}) must not exceed "
                f"bandwidth_max ({bandwidth_max})"
            )
        if pitch_adjust not in PITCH_ADJUSTMENTS:
            raise ConfigError(f"hs: unknown pitch_adjust {pitch_adjust!r}")
        self.hms = hms
        self.hmcr = hmcr
        self.par = par
        self.bandwidth = bandwidth
        self.pitch_adjust = pitch_adjust
        self.par_min = par_min
        self.par_max = par_max
        self.bandwidth_min = bandwidth_min
        self.bandwidth_max = bandwidth_max
        self.budget = budget
        self.restart_after = restart_after
        self.repair = repair

        # Resampling only ever yields memory values or random values inside the bounds.
        self._may_leave_bounds = pitch_adjust != "resample"
        dim = space.dim
        self._block_size = max(16, BLOCK_VALUES // dim)
        self._most_prepared = max(1, PREPARED_VALUES // dim)
        self._prepare_size = 1
        # Flat pool: memory rows, then a copy of the best harmony, then the block's random values.
        self._best_start = hms * dim
        self._random_start = self._best_start + dim
        self._pool = np.zeros(self._random_start + self._block_size * dim)
        self._memory = self._pool[: self._best_start].reshape(hms, dim)
        self._fitness = np.full(hms, np.inf)
        self._filled = 0
        self._worst = 0
        self._worst_fitness = math.inf
        self._best = 0
        self._improvisations = 0
        self._told = 0
        # Harmonies told in a row without improving the memory's best, and restarts so far.
        self._stalled = 0
        self._restarts = 0
        # After a restart, the random points asked since, the only candidates that refill the
        # memory; None before the first restart (a warm start's points fill it as asked ones do).
        self._refill: list[np.ndarray] | None = None
        # The ihs/ghs schedules run over schedule_length improvisations from schedule_start.
        self._schedule_start = 0
        self._schedule_length = self._run_schedule_length()
        # The current block: where each value of each harmony comes from, and its pitch step.
        self._source = np.empty((0, dim), dtype=np.intp)
        self._step: np.ndarray | None = None
        self._position = 0
        self._block_rng_state: dict[str, Any] | None = None
        self._random_source = self._random_start + np.arange(self._block_size * dim).reshape(
            self._block_size, dim
        )
        # Harmonies built ahead for block positions [start, end); emptied when memory changes.
        self._prepared = np.empty((0, dim))
        self._prepared_start = self._prepared_end = 0

    def budget_warning(self, candidates: int) -> str | None:
        """A budget that only fills the memory is random search."""
        if candidates > self.hms:
            return None
        return (
            f"hms {self.hms} is not smaller than the budget's {candidates} candidates: the run "
            "only fills the harmony memory at random, no harmony is improvised (lower hms or "
            "raise --budget)"
        )

    @property
    def initial_population(self) -> int:
        """The random harmonies that fill the memory: hms."""
        return self.hms

    @property
    def harmony_memory(self) -> np.ndarray:
        """A copy of the filled memory rows, shape (filled, dim)."""
        return self._memory[: self._filled].copy()

    @property
    def harmony_fitness(self) -> np.ndarray:
        """A copy of the fitnesses of the filled memory rows."""
        return self._fitness[: self._filled].copy()

    @property
    def improvisations(self) -> int:
        """How many harmonies have been improvised (random initial points not counted)."""
        return self._improvisations

    def _run_schedule_length(self) -> int:
        """Improvisations the ihs/ghs schedules span when the run never restarts: NI."""
        return max(self.budget - self.hms, 1)

    @property
    def restarts(self) -> int:
        """How many times the memory has been refilled at random (restart_after)."""
        return self._restarts

    def par_at(self, improvisation: np.ndarray | int) -> np.ndarray:
        """PAR used by the improvisation(s) with this 0-based index."""
        improvisation = np.asarray(improvisation, dtype=float)
        if self.pitch_adjust not in SCHEDULED_PAR:
            return np.full(improvisation.shape, self.par)
        return self.par_min + (self.par_max - self.par_min) * self._progress(improvisation)

    def bandwidth_at(self, improvisation: np.ndarray | int) -> np.ndarray:
        """Bandwidth (fraction of each variable's range) of the improvisation(s) with this index.

        Only the bandwidth and ihs variants move values by a bandwidth.
        """
        improvisation = np.asarray(improvisation, dtype=float)
        if self.pitch_adjust != "ihs":
            return np.full(improvisation.shape, self.bandwidth)
        ratio = self.bandwidth_min / self.bandwidth_max
        return self.bandwidth_max * ratio ** self._progress(improvisation)

    def _progress(self, improvisation: np.ndarray) -> np.ndarray:
        """Mahdavi's gn / NI: 1/NI for the first improvisation (of the run, or since the last
        restart), 1 from the last one on."""
        return np.minimum((improvisation - self._schedule_start + 1.0) / self._schedule_length, 1.0)

    def ask(self, n: int) -> np.ndarray:
        """Random points while the memory fills, then n harmonies improvised from the memory."""
        if self._filled < self.hms:
            points = self.space.sample(self.rng, n)
            if self._refill is not None:
                self._refill.extend(points.copy())
            return points
        harmonies = self._improvise(n)
        while len(harmonies) < n:
            harmonies = np.concatenate([harmonies, self._improvise(n - len(harmonies))])
        return harmonies

    def _improvise(self, count: int) -> np.ndarray:
        """Up to count harmonies: the next prepared ones of the current block."""
        if self._position == len(self._source):
            self._draw_block(first=self._improvisations)
        if self._position == self._prepared_end:
            self._prepare(count)
        start = self._position
        end = min(start + count, self._prepared_end)
        offset = start - self._prepared_start
        self._position = end
        self._improvisations += end - start
        return self._prepared[offset : offset + end - start]

    def _prepare(self, count: int) -> None:
        """Build the block's next harmonies at once; they stay valid until the memory changes.

        Gather, pitch step and repair act value by value, so a harmony is the same whether it
        is built alone or with others; building several per numpy call saves the call overhead.
        How many are built ahead doubles while they get used and shrinks when the memory
        changes first (early in a run most harmonies enter the memory).
        """
        start = self._position
        end = min(start + max(count, self._prepare_size), len(self._source))
        self._prepare_size = min(2 * self._prepare_size, self._most_prepared)
        harmonies = self._pool[self._source[start:end]]
        if self._step is not None:
            harmonies += self._step[start:end]
        if self._may_leave_bounds:
            harmonies = self.space.repair(harmonies, self.repair)
        self._prepared, self._prepared_start, self._prepared_end = harmonies, start, end

    def _draw_block(self, first: int) -> None:
        """Draw the random choices of the block of improvisations starting at index first."""
        self._block_rng_state = rng_state(self.rng)
        rng, size, dim = self.rng, self._block_size, self.space.dim
        indices = np.arange(first, first + size)
        # One uniform decides both: below hmcr*PAR pitch-adjusted memory, below hmcr memory.
        decision = rng.random((size, dim))
        considered = decision < self.hmcr
        pitched = decision < self.hmcr * self.par_at(indices)[:, None]
        memory_source = rng.integers(0, self.hms, (size, dim)) * dim + np.arange(dim)
        self._pool[self._random_start :] = self.space.sample(rng, size).ravel()
        random_source = self._random_source
        source = np.where(considered, memory_source, random_source)
        self._step = None
        if self.pitch_adjust == "resample":
            source = np.where(pitched, random_source, source)
        elif self.pitch_adjust == "ghs":
            best_source = self._best_start + rng.integers(0, dim, (size, dim))
            source = np.where(pitched, best_source, source)
        else:
            scale = self.bandwidth_at(indices)[:, None] * self.space.width
            step = (2.0 * rng.random((size, dim)) - 1.0) * scale
            self._step = np.where(pitched, step, 0.0)
        self._source = source
        self._position = self._prepared_end = 0

    def tell(self, candidates: np.ndarray, fitnesses: np.ndarray) -> None:
        """Fill the memory, then let each candidate replace the worst harmony if strictly better;
        restart once restart_after candidates in a row have not improved the best."""
        fitness_values = np.asarray(fitnesses, dtype=float).ravel().tolist()
        if len(candidates) != len(fitness_values):
            raise ValueError(f"{len(candidates)} candidates but {len(fitness_values)} fitnesses")
        for index, fitness in enumerate(fitness_values):
            self._told += 1
            if self._filled < self.hms:
                if self._asked_since_restart(candidates[index]):
                    self._fill(candidates[index], fitness)
                continue
            if self.restart_after:
                self._stalled = 0 if fitness < self._fitness[self._best] else self._stalled + 1
            if fitness < self._worst_fitness:
                self._replace_worst(candidates[index], fitness)
            if self.restart_after and self._stalled >= self.restart_after:
                self._restart()

    def _restart(self) -> None:
        """Empty the memory (it refills with random points) and restart the schedules over the
        budget left; the current block of choices is dropped, its schedule values being stale."""
        self._restarts += 1
        self._refill = []
        self._filled = self._stalled = 0
        self._fitness[:] = np.inf
        self._schedule_start = self._improvisations
        self._schedule_length = max(self.budget - self._told - self.hms, 1)
        self._drop_block()
        self._block_rng_state = None

    def _asked_since_restart(self, candidate: np.ndarray) -> bool:
        """Whether a told candidate may refill the memory: any before the first restart, after
        one only the random points asked since (each once)."""
        if self._refill is None:
            return True
        for position, point in enumerate(self._refill):
            if np.array_equal(point, candidate):
                del self._refill[position]
                return True
        return False

    def _drop_block(self) -> None:
        """Forget the current block of choices and the harmonies built from it."""
        self._source = np.empty((0, self.space.dim), dtype=np.intp)
        self._step = None
        self._position = self._prepared_end = 0

    def _fill(self, candidate: np.ndarray, fitness: float) -> None:
        # NaN would never compare worse than anything and so would stay in memory for good.
        self._memory[self._filled] = candidate
        self._forget_prepared()
        self._fitness[self._filled] = math.inf if math.isnan(fitness) else fitness
        self._filled += 1
        if self._filled == self.hms:
            if self._refill is not None:
                self._refill = []  # points asked beyond the memory's size refill nothing
            self._best = int(self._fitness.argmin())
            self._update_worst()
            self._copy_best()

    def _replace_worst(self, candidate: np.ndarray, fitness: float) -> None:
        self._memory[self._worst] = candidate
        self._forget_prepared()
        self._fitness[self._worst] = fitness
        if fitness < self._fitness[self._best]:
            self._best = self._worst
            self._copy_best()
        self._update_worst()

    def _forget_prepared(self) -> None:
        """The memory changed: drop the harmonies built from the old one."""
        self._prepare_size = max(1, self._position - self._prepared_start)
        self._prepared_end = self._position

    def _update_worst(self) -> None:
        self._worst = int(self._fitness.argmax())
        self._worst_fitness = float(self._fitness[self._worst])

    def _copy_best(self) -> None:
        self._pool[self._best_start : self._random_start] = self._memory[self._best]

    def state_dict(self) -> dict[str, Any]:
        """Memory, fitnesses, counters and generator states as plain JSON types."""
        return {
            "memory": self._memory[: self._filled].tolist(),
            "fitness": [json_float(f) for f in self._fitness[: self._filled].tolist()],
            "best": self._best,
            "improvisations": self._improvisations,
            "told": self._told,
            "stalled": self._stalled,
            "restarts": self._restarts,
            "refill": None if self._refill is None else [p.tolist() for p in self._refill],
            "schedule": [self._schedule_start, self._schedule_length],
            "block_rng": self._block_rng_state,
            "block_position": self._position,
            "rng": rng_state(self.rng),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a state_dict; the current block is redrawn from its saved generator state."""
        filled = len(state["memory"])
        if filled > self.hms or (filled and len(state["memory"][0]) != self.space.dim):
            raise ConfigError("hs: saved harmony memory does not fit this hms and space")
        self._filled = filled
        self._fitness[:] = math.inf
        if filled:
            self._memory[:filled] = state["memory"]
            self._fitness[:filled] = [float(f) for f in state["fitness"]]
        self._best = state["best"]
        if filled == self.hms:
            self._update_worst()
            self._copy_best()
        self._improvisations = state["improvisations"]
        # States saved before restarts existed: no restart yet, schedules over the budget.
        self._told = state.get("told", filled + self._improvisations)
        self._stalled = state.get("stalled", 0)
        self._restarts = state.get("restarts", 0)
        refill = state.get("refill")  # states saved before it: any told candidate refills
        self._refill = None if refill is None else [np.array(p, dtype=float) for p in refill]
        self._schedule_start, self._schedule_length = state.get(
            "schedule", (0, self._run_schedule_length())
        )
        self._drop_block()
        self._block_rng_state = state["block_rng"]
        if self._block_rng_state is not None:
            position = state["block_position"]
            restore_rng(self.rng, self._block_rng_state)
            self._draw_block(first=self._improvisations - position)
            self._position = self._prepared_end = position
        restore_rng(self.rng, state["rng"])


PARAMS = (
    population_param(
        "hms", 20, "harmony memory size: how many solutions are kept (10-30 is usual)"
    ),
    Param(
        "hmcr",
        float,
        0.95,
        "harmony memory considering rate: chance a value comes from memory, not at random",
        low=0.0,
        high=1.0,
    ),
    Param(
        "par",
        float,
        0.3,
        "pitch adjusting rate: chance a memory value is adjusted (bandwidth, resample)",
        low=0.0,
        high=1.0,
    ),
    Param(
        "bandwidth",
        float,
        0.01,
        "largest pitch step, as a fraction of each variable's range (bandwidth variant)",
        low=0.0,
        high=1.0,
        low_open=True,
    ),
    Param(
        "pitch_adjust",
        str,
        "ihs",
        "bandwidth: classic step within the bandwidth; resample: new random value (the "
        "paper); ihs: improved HS, rising PAR and shrinking bandwidth; ghs: value from the best",
        choices=PITCH_ADJUSTMENTS,
    ),
    Param("par_min", float, 0.01, "PAR at the start (ihs, ghs)", low=0.0, high=1.0),
    Param("par_max", float, 0.99, "PAR at the end of the budget (ihs, ghs)", low=0.0, high=1.0),
    Param(
        "bandwidth_min",
        float,
        1e-5,
        "bandwidth at the end of the budget, fraction of the range (ihs)",
        low=0.0,
        high=1.0,
        low_open=True,
    ),
    Param(
        "bandwidth_max",
        float,
        0.05,
        "bandwidth at the start, fraction of the range (ihs)",
        low=0.0,
        high=1.0,
        low_open=True,
    ),
    budget_param(),
    Param(
        "restart_after",
        int,
        0,
        "restart: after this many harmonies in a row that do not improve the memory's best, "
        "refill the memory at random and restart the ihs/ghs schedules (0: never)",
        low=0,
    ),
    repair_param("how values pushed past a bound come back: clip to it or reflect off it"),
)


@hookimpl
def metaopt_optimizers() -> list[OptimizerInfo]:
    """Announce the Harmony Search optimizer."""
    return [
        OptimizerInfo(
            name="hs",
            summary="Harmony Search (Geem 2001), steady state; classic, paper, IHS and GHS pitch",
            factory=HarmonySearch,
            params=PARAMS,
            description=__doc__ or "",
        )
    ]
