"""The metaopt optimizer ``pycma``: CMA-ES from the ``cma`` package, with restarts.

CMA-ES (Hansen and Ostermeier 2001) samples each generation of ``popsize`` candidates from a
multivariate normal distribution and moves its mean, step size and covariance towards the better
ones. This plugin wraps ``cma.CMAEvolutionStrategy`` in metaopt's ask/tell contract:

- Space: CMA-ES runs on [0, 1]^dim, mapped linearly onto the space's box, with cma's own
  ``bounds`` handling (BoundTransform), so every candidate lies inside the bounds. ``sigma0`` is
  therefore a fraction of each variable's range; each (re)start begins at a uniform random point.
- Batches: ``batch_size`` is the population size. ``ask(n)`` serves candidates of the current
  generation in order, sampling more from the same distribution when n runs past it. Results must
  be told in the order asked. Once the first ``popsize`` results of a generation are in, CMA-ES
  updates; results of any extra candidates of that generation are then ignored.
- Failed evaluations: cma needs finite values, so +inf (and NaN) is replaced by a penalty worse
  than every finite fitness seen so far in the run: worst + |worst| + 1 (1 before any is seen).
- Restarts: when cma's own termination criteria fire (tolx, tolfun, stagnation, ...), CMA-ES
  restarts from a new random point with the same population size, until the budget is spent.
- Randomness: every normal sample comes from a numpy Generator seeded with the run's seed (cma's
  ``randn`` option), never from numpy's global generator, so cma's ``seed`` option (where 0 means
  "from the clock") is not used.
- State: cma's strategy object is not JSON. The state is the run's seed and the log of every
  ask size and told fitness; loading replays the log on a fresh strategy, which cma, being
  deterministic given its random numbers, follows bit for bit. The log grows with the run (one
  number per evaluation) and a load costs one CMA-ES update per generation: milliseconds per
  hundred generations. It also records the cma version: another version may follow the log
  differently, so loading refuses a state written under another one.
"""

from __future__ import annotations

import math
import sys
from collections import deque
from typing import Any

import cma
import numpy as np

from metaopt import ConfigError, Optimizer, OptimizerInfo, Param, Space, budget_param, hookimpl

#: Options that keep cma silent, free of files and of numpy's global generator.
QUIET = {
    "verbose": -9,
    "verb_disp": 0,
    "verb_log": 0,
    "signals_filename": "",
    "seed": math.nan,
}


class CmaEs(Optimizer):
    """CMA-ES on the unit cube mapped to the space; see the module docstring."""

    def __init__(
        self, space: Space, seed: int, *, sigma0: float, popsize: int, budget: int
    ) -> None:
        # CMA-ES restarts until the run stops, however long it is: the budget changes nothing.
        super().__init__(space, seed)
        self.seed = seed
        self.sigma0 = sigma0
        self.popsize = popsize
        self._begin()

    def _begin(self) -> None:
        """Start the run afresh: generator, log, queue and first strategy."""
        self.rng = np.random.default_rng(self.seed)
        #: Every ask size (int) and told batch (list, None for a failed evaluation), in order.
        self._log: list[int | list[float | None]] = []
        #: Asked, not yet told: (generation number, candidate in the space), oldest first.
        self._pending: deque[tuple[int, np.ndarray]] = deque()
        self._worst = -math.inf
        self._generation = -1
        self._restart()

    def _restart(self) -> None:
        """A new strategy from a uniform random point of the unit cube."""
        options = {**QUIET, "bounds": [0.0, 1.0], "randn": self._randn}
        if self.popsize:
            options["popsize"] = self.popsize
        self._es = cma.CMAEvolutionStrategy(self.rng.random(self.space.dim), self.sigma0, options)
        self._next_generation()

    def _randn(self, *shape: int) -> np.ndarray:
        return self.rng.standard_normal(shape)

    def _next_generation(self) -> None:
        self._generation += 1
        #: The generation's samples in the unit cube, how many were served, their results.
        self._samples: list[np.ndarray] = []
        self._served = 0
        self._results: list[float | None] = []

    @property
    def batch_size(self) -> int:
        """The population size of CMA-ES (cma's default, 4 + 3 ln dim, when popsize is 0)."""
        return int(self._es.popsize)

    def ask(self, n: int) -> np.ndarray:
        """The next n candidates of the current generation, sampling more when n runs past it."""
        self._log.append(n)
        batch = np.empty((n, self.space.dim))
        for row in range(n):
            if self._served == len(self._samples):
                self._samples += self._es.ask()
            unit = np.clip(self._samples[self._served], 0.0, 1.0)
            self._served += 1
            batch[row] = self.space.lower + unit * self.space.width
            self._pending.append((self._generation, batch[row].copy()))
        return batch

    def tell(self, candidates: np.ndarray, fitnesses: np.ndarray) -> None:
        """Results of the oldest pending candidates, in ask order; CMA-ES updates per generation."""
        values = [float(f) if math.isfinite(f) else None for f in np.asarray(fitnesses, float)]
        if len(values) > len(self._pending):
            raise ValueError(f"pycma: told {len(values)} results, {len(self._pending)} pending")
        told = [self._pending[i] for i in range(len(values))]
        expected = np.array([candidate for _, candidate in told]).reshape(-1, self.space.dim)
        if not np.array_equal(np.asarray(candidates, dtype=float), expected):
            raise ValueError(
                "pycma: the told candidates are not the oldest asked ones; tell results in the "
                "order their candidates were asked"
            )
        self._log.append(values)
        for (generation, _), value in zip(told, values):
            self._pending.popleft()
            if value is not None:
                self._worst = max(self._worst, value)
            if generation == self._generation:  # else an extra of an updated generation
                self._results.append(value)
                if len(self._results) == self._es.popsize:
                    self._update()

    def _update(self) -> None:
        """Tell cma the generation, failures penalised; restart when it has converged."""
        penalty = 1.0 if self._worst == -math.inf else self._worst + abs(self._worst) + 1.0
        penalty = min(penalty, sys.float_info.max)
        values = [penalty if v is None else v for v in self._results]
        self._es.tell(self._samples[: len(values)], values)
        if self._es.stop():
            self._restart()
        else:
            self._next_generation()

    def state_dict(self) -> dict[str, Any]:
        """The seed, the ask/tell log (replayed on load) and the cma version, as plain JSON."""
        return {"seed": self.seed, "cma_version": cma.__version__, "log": list(self._log)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Replay the log on a fresh strategy; refuse a state written with another cma version."""
        if state["cma_version"] != cma.__version__:
            raise ConfigError(
                f"pycma: this state was written with cma {state['cma_version']} but cma "
                f"{cma.__version__} is installed; install cma=={state['cma_version']} to resume"
            )
        self.seed = state["seed"]
        self._begin()
        for entry in state["log"]:
            if isinstance(entry, int):
                self.ask(entry)
            else:
                told = np.array([c for _, c in list(self._pending)[: len(entry)]])
                self.tell(told, np.array([math.inf if v is None else v for v in entry]))


PARAMS = (
    Param(
        "sigma0",
        float,
        0.3,
        "initial step size, as a fraction of each variable's range",
        low=0.0,
        high=1.0,
        low_open=True,
    ),
    Param("popsize", int, 0, "candidates per generation; 0: cma's default, 4 + 3 ln(dim)", low=0),
    budget_param(),
)


@hookimpl
def metaopt_optimizers() -> list[OptimizerInfo]:
    """Announce pycma."""
    return [
        OptimizerInfo(
            name="pycma",
            summary="CMA-ES (the cma package) with restarts; bounds by cma's BoundTransform",
            factory=CmaEs,
            params=PARAMS,
            description=__doc__ or "",
        )
    ]
