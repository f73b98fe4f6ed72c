"""The Problem interface: a space, a sense, and a pure evaluate(x, seed)."""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from metaopt.params import Param
from metaopt.space import Space


class Sense(str, enum.Enum):
    """Whether a problem's fitness is to be minimized or maximized."""

    MINIMIZE = "minimize"
    MAXIMIZE = "maximize"


@dataclass
class Evaluation:
    """What one evaluation returns: the fitness and named scalar metrics (distance, fell, ...)."""

    fitness: float
    metrics: dict[str, float] = field(default_factory=dict)


class Problem(ABC):
    """An objective over a Space.

    ``evaluate`` must be a pure function of ``(x, seed)``: the same inputs give the same
    Evaluation in any process. It may raise EvaluationError (or return NaN) for a candidate it
    cannot evaluate; the run loop then stores that evaluation as failed and goes on.
    """

    space: Space
    sense: Sense = Sense.MINIMIZE
    #: Metrics worth showing in result tables, in display order.
    key_metrics: tuple[str, ...] = ()
    #: Known optimum fitness, when there is one (benchmark functions).
    optimum: float | None = None

    @abstractmethod
    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        """Evaluate one candidate (a 1-D array in space order)."""

    def close(self) -> None:  # noqa: B027 - optional hook, empty by default
        """Release engines, files or other resources; called once when a run ends."""


@dataclass(frozen=True)
class ProblemInfo:
    """How a plugin announces a problem: its name, what it is, its parameters, a factory.

    ``factory(**params)`` receives every declared parameter (defaults filled in, validated).
    ``default_budget`` is the number of evaluations a run gets when the user names none.
    """

    name: str
    summary: str
    factory: Callable[..., Problem]
    params: tuple[Param, ...] = ()
    description: str = ""
    default_budget: int = 1000
