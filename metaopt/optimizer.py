"""The Optimizer interface: ask/tell, always minimizing, with a plain-JSON state."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from metaopt.params import Param
from metaopt.space import Space
from metaopt.storage.limits import MAX_STORED_INT


class Optimizer(ABC):
    """An ask/tell optimizer over a Space that minimizes.

    The run loop translates maximization and failed evaluations (+inf) before ``tell``.
    ``state_dict`` must capture everything, random generator included, as plain JSON types, so
    that ``load_state_dict`` on a freshly built optimizer continues bit for bit.
    """

    #: True when the optimizer can take results one at a time in any order (asynchronous mode).
    steady_state: bool = False

    def __init__(self, space: Space, seed: int) -> None:
        self.space = space
        self.rng = np.random.default_rng(seed)

    @property
    def batch_size(self) -> int:
        """How many candidates the optimizer prefers to be asked for at once."""
        return 1

    @property
    def initial_population(self) -> int:
        """How many candidates the optimizer draws at random before it learns from any (HS: the
        harmony memory); a warm start puts its points there (metaopt.warm_start)."""
        return self.batch_size

    @property
    def selected(self) -> int | None:
        """How many of a batch's best candidates its update reads, by their order and fitness
        (CMA-ES: its parents, mu): the others it only needs to know rank below them, so a run
        may tell them a bound (``metaopt run --screen``). None: every told fitness counts.
        Holds for batches of ``batch_size``."""
        return None

    def budget_warning(self, candidates: int) -> str | None:
        """Why a run that tells this optimizer ``candidates`` candidates would hardly be what
        the user meant (e.g. no more than its random initial population), or None."""
        return None

    @abstractmethod
    def ask(self, n: int) -> np.ndarray:
        """Propose n candidates, shape (n, dim), inside the space."""

    @abstractmethod
    def tell(self, candidates: np.ndarray, fitnesses: np.ndarray) -> None:
        """Learn from evaluated candidates (rows of ``candidates``), lower fitness is better."""

    @abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """The whole state as JSON-serialisable types (use rng_state for the generator)."""

    @abstractmethod
    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what state_dict returned."""

    def recommendation(self) -> np.ndarray | None:
        """The point the optimizer would answer with now other than its best evaluated one
        (CMA-ES: its distribution's mean, pycma's ``xfavorite``), inside the space; None where
        the best evaluated is its answer. On a noisy problem the best evaluated is the luckiest
        of many draws, a distribution's centre an average over them."""
        return None


def rng_state(rng: np.random.Generator) -> dict[str, Any]:
    """A numpy Generator's state as plain JSON (big ints are fine in JSON)."""
    return rng.bit_generator.state


def json_float(value: float) -> float | str:
    """A fitness for a plain-JSON state: finite floats as they are, inf and nan as strings that
    float() reads back (strict JSON has neither; a failed evaluation is told as +inf)."""
    return value if math.isfinite(value) else str(value)


def restore_rng(rng: np.random.Generator, state: dict[str, Any]) -> None:
    """Put a state from rng_state back into a Generator of the same bit generator."""
    rng.bit_generator.state = state


#: The most candidates a population or batch parameter takes: an optimizer's arrays are that
#: long, and a larger one is a slip that would fill memory.
MAX_POPULATION = 1_000_000


def population_param(name: str, default: int, help: str, low: int = 1) -> Param:
    """A count of candidates an optimizer holds or asks for at once (a population, a batch, a
    memory), at most MAX_POPULATION: its arrays are that long, and a larger one is a slip."""
    return Param(
        name,
        int,
        default,
        f"{help}; at most {MAX_POPULATION:,} (more would fill memory)",
        low=low,
        high=MAX_POPULATION,
    )


#: The most evaluations a run's budget or an optimizer's ``budget`` parameter takes: the run
#: store keeps no larger integer, and a budget past it is a slip no run would spend.
MAX_BUDGET = MAX_STORED_INT


def budget_param(default: int = 10000) -> Param:
    """The ``budget`` parameter every optimizer declares: how many evaluations it will be told.

    ``metaopt run`` and ``metaopt.create_optimizer``/``minimize`` set it to the run's budget
    unless the user gives one, so an optimizer with a schedule (IHS's bandwidth, the GA's
    mutation step) spans the run; an optimizer without one accepts it and may ignore it.
    """
    return Param(
        "budget",
        int,
        default,
        "evaluations it will be told, initial ones included: schedules span them (metaopt run "
        "sets the run's budget unless given; past it they stay at their end)",
        low=1,
        high=MAX_BUDGET,
    )


@dataclass(frozen=True)
class OptimizerInfo:
    """How a plugin announces an optimizer: its name, what it is, its parameters, a factory.

    ``factory(space, seed, **params)`` receives every declared parameter (defaults filled in,
    validated) and returns a ready Optimizer. Every optimizer declares ``budget``
    (``budget_param()``), so generic code can tell any optimizer how long its run is; the
    conformance kit (metaopt.testing) checks it.
    """

    name: str
    summary: str
    factory: Callable[..., Optimizer]
    params: tuple[Param, ...] = ()
    description: str = ""
