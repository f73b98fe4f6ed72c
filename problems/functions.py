"""Classic benchmark functions (sphere, rastrigin, rosenbrock, ackley, griewank, schwefel).

Each function is its own problem name with a ``dim`` parameter, its customary bounds and a known
optimum fitness of 0. They are cheap to evaluate, which makes them the reference for testing
optimizers and for measuring the framework's own overhead.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from metaopt import Evaluation, Param, Problem, ProblemInfo, Sense, Space, hookimpl

#: argmax of x·sin(√|x|) on [-500, 500] and its value: Schwefel 2.26's minimizer per variable and
#: the offset (the "418.9829" of the usual 418.9829·d form, to full precision so the minimum is 0).
SCHWEFEL_ARGMIN = 420.9687463599821
SCHWEFEL_OFFSET = 418.98288727243374


def sphere(x: np.ndarray) -> float:
    """Σ x_i²; unimodal and separable."""
    return float(np.dot(x, x))


def rastrigin(x: np.ndarray) -> float:
    """10·d + Σ (x_i² − 10·cos 2πx_i); a regular grid of local minima."""
    return float(10.0 * x.size + np.dot(x, x) - 10.0 * np.cos(2.0 * np.pi * x).sum())


def rosenbrock(x: np.ndarray) -> float:
    """Σ 100·(x_{i+1} − x_i²)² + (1 − x_i)²; a narrow curved valley."""
    head, tail = x[:-1], x[1:]
    return float((100.0 * (tail - head * head) ** 2 + (1.0 - head) ** 2).sum())


def ackley(x: np.ndarray) -> float:
    """−20·exp(−0.2·√mean x²) − exp(mean cos 2πx) + 20 + e; a nearly flat outer region."""
    mean_square = np.dot(x, x) / x.size
    mean_cos = np.cos(2.0 * np.pi * x).sum() / x.size
    return float(-20.0 * np.exp(-0.2 * np.sqrt(mean_square)) - np.exp(mean_cos) + 20.0 + np.e)


def griewank(x: np.ndarray) -> float:
    """1 + Σ x_i²/4000 − Π cos(x_i/√i); many shallow local minima over a wide bowl."""
    scale = np.sqrt(np.arange(1.0, x.size + 1.0))
    return float(1.0 + np.dot(x, x) / 4000.0 - np.prod(np.cos(x / scale)))


def schwefel(x: np.ndarray) -> float:
    """418.9829·d − Σ x_i·sin(√|x_i|); deceptive, the minimum far from the next best minima."""
    return float(SCHWEFEL_OFFSET * x.size - np.dot(x, np.sin(np.sqrt(np.abs(x)))))


@dataclass(frozen=True)
class FunctionSpec:
    """One benchmark function: its formula, customary bounds and where its minimum (0) lies.

    ``min_dim`` is the fewest variables the formula is meaningful for (Rosenbrock couples
    neighbours, so it needs two).
    """

    name: str
    function: Callable[[np.ndarray], float]
    lower: float
    upper: float
    argmin: float
    summary: str
    min_dim: int = 1


FUNCTIONS: tuple[FunctionSpec, ...] = (
    FunctionSpec("sphere", sphere, -5.12, 5.12, 0.0, "Sphere: sum of squares, unimodal"),
    FunctionSpec(
        "rastrigin", rastrigin, -5.12, 5.12, 0.0, "Rastrigin: highly multimodal, regular grid"
    ),
    FunctionSpec(
        "rosenbrock", rosenbrock, -5.0, 10.0, 1.0, "Rosenbrock: narrow curved valley", min_dim=2
    ),
    FunctionSpec("ackley", ackley, -32.768, 32.768, 0.0, "Ackley: flat outer region, deep centre"),
    FunctionSpec("griewank", griewank, -600.0, 600.0, 0.0, "Griewank: wide bowl, many minima"),
    FunctionSpec(
        "schwefel", schwefel, -500.0, 500.0, SCHWEFEL_ARGMIN, "Schwefel 2.26: deceptive, multimodal"
    ),
)


class BenchmarkFunction(Problem):
    """A benchmark function in ``dim`` variables x0..x{dim-1}, minimized, optimum fitness 0."""

    sense = Sense.MINIMIZE
    key_metrics = ()
    optimum = 0.0

    def __init__(self, spec: FunctionSpec, dim: int) -> None:
        self.spec = spec
        self.space = Space.from_bounds([spec.lower] * dim, [spec.upper] * dim)

    @property
    def argmin(self) -> np.ndarray:
        """Where the optimum lies."""
        return np.full(self.space.dim, self.spec.argmin)

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        """The function's value at x; deterministic, so the seed is unused."""
        return Evaluation(fitness=self.spec.function(np.asarray(x, dtype=float)), metrics={})


def _info(spec: FunctionSpec) -> ProblemInfo:
    dim = Param("dim", int, 10, "number of variables", low=spec.min_dim)
    return ProblemInfo(
        name=spec.name,
        summary=spec.summary,
        factory=partial(BenchmarkFunction, spec),
        params=(dim,),
        description=(
            f"{spec.function.__doc__} Bounds [{spec.lower:g}, {spec.upper:g}] in every variable; "
            f"minimum 0 at x_i = {spec.argmin:g}."
        ),
    )


@hookimpl
def metaopt_problems() -> list[ProblemInfo]:
    """One problem per benchmark function."""
    return [_info(spec) for spec in FUNCTIONS]
