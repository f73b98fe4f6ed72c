"""The Problem interface: a space, a sense, and a pure evaluate(x, seed)."""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from metaopt.params import Param, resolve
from metaopt.space import Space

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from metaopt.assessment.robustness import PerturbationTable


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

    #: True where ``screen`` gives a cheaper evaluation whose fitness the full one can only
    #: worsen (``metaopt run --screen``); problems that set it implement ``screen`` and
    #: ``complete``. A property where it depends on the problem's settings.
    screens: bool = False

    def screen(self, x: np.ndarray, seed: int) -> Evaluation:
        """Optional: the cheap part of x's evaluation with seed, whose fitness is an optimistic
        bound (the full evaluation's is never better), so a run that ranks candidates can skip
        the rest for those already out of its ranks (e.g. nao-walk's worst over engines, walked
        first on the faster engines). Problems without one raise NotImplementedError."""
        raise NotImplementedError("has no cheaper bound on its fitness")

    def complete(self, x: np.ndarray, seed: int, screened: Evaluation) -> Evaluation:
        """The full evaluation of x with seed after ``screen`` gave ``screened``: equal to
        ``evaluate(x, seed)``, reusing what the screen computed where it can."""
        return self.evaluate(x, seed)

    def prepare(self) -> None:  # noqa: B027 - optional hook, empty by default
        """Optional: the set-up that evaluations share (importing an engine, building a model),
        done before an evaluation's time limit starts, so that no limit counts it and no
        import is cut short. Called before every evaluation: cheap once done."""

    def close(self) -> None:  # noqa: B027 - optional hook, empty by default
        """Release engines, files or other resources; called once when a run ends."""

    def figures(self, x: np.ndarray, seed: int) -> dict[str, Figure]:
        """Optional: matplotlib figures of candidate x evaluated with seed (e.g. a robot's joint
        angles over time), by file stem; ``metaopt report`` saves them beside the convergence
        figure. Problems without figures of their own raise NotImplementedError."""
        raise NotImplementedError("draws no figures of its own")

    def video(
        self,
        x: np.ndarray,
        seed: int,
        frame: Callable[[np.ndarray], None],
        size: tuple[int, int],
        fps: int,
    ) -> None:
        """Optional: evaluate candidate x with seed and pass ``fps`` images per simulated second
        to ``frame``, each (height, width, 3) uint8 RGB for size = (width, height); ``metaopt
        replay --video`` encodes them. Problems that cannot show one raise NotImplementedError."""
        raise NotImplementedError("cannot show a video")


@dataclass(frozen=True)
class StoredCandidate:
    """A candidate a problem plugin keeps as data (e.g. nao-walk's stored gaits): the problem
    parameters it was found with, its decision vector, and the seed it was evaluated with."""

    params: dict[str, Any]
    x: np.ndarray
    seed: int


@dataclass(frozen=True)
class ProblemInfo:
    """How a plugin announces a problem: its name, what it is, its parameters, a factory.

    ``factory(**params)`` receives every declared parameter (defaults filled in, validated).
    ``default_budget`` is the number of evaluations a run gets when the user names none.
    Optional: ``perturbations``, the standard table ``metaopt robustness`` evaluates a
    candidate over; ``stored_candidates()``, the candidates it keeps as data, by name.
    """

    name: str
    summary: str
    factory: Callable[..., Problem]
    params: tuple[Param, ...] = ()
    description: str = ""
    default_budget: int = 1000
    perturbations: PerturbationTable | None = None
    stored_candidates: Callable[[], Mapping[str, StoredCandidate]] | None = None

    def checked_params(self, given: Mapping[str, Any]) -> dict[str, Any]:
        """``given`` resolved against the declarations, once a problem built from it has
        accepted it: the problem's own checks (which no single declaration can make) refuse bad
        settings before anything is stored."""
        params = resolve(self.params, dict(given), self.name)
        self.factory(**params).close()
        return params
