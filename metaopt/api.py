"""metaopt from Python: minimize or maximize a function, and build any optimizer by name.

``minimize(f, bounds, optimizer="hs", budget=2000, seed=1)`` runs the same loop as ``metaopt
run`` (seeds, failed evaluations, budget, target) on a plain Python function and returns a Result
with the best point, its fitness and the history of every evaluation; with ``store=PATH`` the run
is also kept in that run store, where ``metaopt runs``, ``show`` and ``report`` find it.
With ``bound=g``, a cheap function that f(x) can never beat, each generation is screened
(``metaopt run --screen``): f runs only where g says the candidate can still rank among those
the optimizer's update reads. ``create_optimizer(name, bounds, seed=..., budget=...)`` builds a
registered optimizer with its declared defaults filled in and validated, for ask/tell loops of
one's own.
"""

from __future__ import annotations

import secrets
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from metaopt.errors import ConfigError
from metaopt.optimizer import Optimizer
from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense
from metaopt.reporting.convergence import convergence
from metaopt.running import RunSettings, RunSpec, run
from metaopt.space import Space, Variable
from metaopt.storage.run_store import IN_MEMORY, RunStore

#: What bounds may be: a Space, (lower, upper) pairs, or {variable name: (lower, upper)}.
Bounds = Space | Sequence[tuple[float, float]] | Mapping[str, tuple[float, float]]


@dataclass(frozen=True)
class History:
    """Every evaluation of a run, in order: the candidate, its fitness (NaN where it failed or
    was screened) and the best fitness so far."""

    x: np.ndarray  #: shape (evaluations, dim)
    fitness: np.ndarray
    best: np.ndarray
    #: True where only the bound ran (``bound=``): f was not called, fitness is NaN
    screened: np.ndarray


@dataclass(frozen=True)
class Result:
    """What minimize and maximize return."""

    x: np.ndarray  #: the best point found
    fitness: float  #: f(x)
    evaluations: int  #: evaluations made (fewer than the budget when the target was reached)
    failed: int  #: evaluations where f raised or returned NaN or an infinity
    screened: int  #: evaluations where only the bound ran (``bound=``), f was not called
    history: History
    seed: int  #: the run's seed (drawn at random when none was given)
    run_id: int | None  #: the run's id in the store, None when the run was not stored


def as_space(bounds: Bounds) -> Space:
    """A Space from a Space, (lower, upper) pairs (variables x0, x1, ...) or {name: (lower,
    upper)}; ConfigError saying which form is accepted otherwise."""
    if isinstance(bounds, Space):
        return bounds
    try:
        if isinstance(bounds, Mapping):
            pairs, names = list(bounds.values()), list(bounds)
        else:
            pairs = list(bounds)
            names = [f"x{i}" for i in range(len(pairs))]
        variables = [Variable(str(n), float(lo), float(hi)) for n, (lo, hi) in zip(names, pairs)]
    except (TypeError, ValueError):
        raise ConfigError(
            "bounds must be a Space, a sequence of (lower, upper) pairs or a mapping "
            "{name: (lower, upper)}"
        ) from None
    return Space(variables)


def create_optimizer(
    name: str,
    bounds: Bounds,
    *,
    seed: int = 0,
    budget: int | None = None,
    **params: Any,
) -> Optimizer:
    """The registered optimizer ``name`` over ``bounds``, its declared defaults filled in and
    ``params`` validated (ConfigError naming what is accepted, with close names).

    ``budget`` is the number of evaluations it will be told; every optimizer declares it (see
    metaopt.budget_param) and schedules over it (IHS's bandwidth, the GA's mutation step), so
    give it whenever the run's length is known. Left out, the declared default is used.
    """
    info = registry().optimizer(name)
    given = dict(params)
    if budget is not None and any(p.name == "budget" for p in info.params):
        given["budget"] = budget
    return info.factory(as_space(bounds), seed, **resolve(info.params, given, name))


class _FunctionProblem(Problem):
    """A Python function of x (a 1-D array) as a Problem, screened by ``bound`` where one is
    given; the evaluation seed is not used."""

    def __init__(
        self,
        f: Callable[[np.ndarray], float],
        space: Space,
        sense: Sense,
        bound: Callable[[np.ndarray], float] | None = None,
    ) -> None:
        self.f, self.space, self.sense, self.bound = f, space, sense, bound

    @property
    def screens(self) -> bool:
        """With a bound: minimize's and maximize's ``bound=`` screens each generation."""
        return self.bound is not None

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        return Evaluation(float(self.f(x)))

    def screen(self, x: np.ndarray, seed: int) -> Evaluation:
        assert self.bound is not None, "screened only with a bound (screens)"
        return Evaluation(float(self.bound(x)))


def minimize(
    f: Callable[[np.ndarray], float],
    bounds: Bounds,
    optimizer: str = "hs",
    *,
    budget: int = 1000,
    seed: int | None = None,
    target: float | None = None,
    max_time: float | None = None,
    store: str | Path | None = None,
    start: Sequence[float] | Sequence[Sequence[float]] | None = None,
    start_spread: float = 0.05,
    bound: Callable[[np.ndarray], float] | None = None,
    **params: Any,
) -> Result:
    """Minimize f(x) over the box ``bounds`` with ``budget`` evaluations of f.

    ``params`` are the optimizer's parameters (``metaopt list``). The run stops early once a
    fitness at or below ``target`` is found, or once it has run ``max_time`` seconds. With
    ``start`` (a point inside the bounds, or a sequence of points) the optimizer's random
    initial population is that point and points drawn within ±``start_spread`` of each range
    around it (around each point in turn: a warm start, metaopt.warm_start). f may raise or
    return NaN for a point it cannot evaluate: that evaluation counts as failed and the run
    goes on (RunFailed, naming the first error, when the first ten or all of them fail).
    With ``store`` the run is kept in that run store under the problem name
    ``python:<function name>``.

    ``bound`` (a function of x never above f(x), cheaper to compute) screens every generation:
    f runs best bound first, and only on candidates that can still rank among those the
    optimizer's update reads; the others are told their bound, which changes none of its steps
    (optimizers with ``selected``, such as cmaes; docs/scaling.md). RunFailed if f(x) ever
    comes out below bound(x).
    """
    settings = _settings(target, max_time, start, start_spread)
    return _optimize(
        f, bounds, optimizer, Sense.MINIMIZE, budget, seed, settings, store, params, bound
    )


def _settings(
    target: float | None,
    max_time: float | None,
    start: Sequence[float] | Sequence[Sequence[float]] | None,
    start_spread: float,
) -> RunSettings:
    """minimize's and maximize's stopping target, time limit and warm start as run settings."""
    points = None if start is None else np.atleast_2d(np.asarray(start, dtype=float)).tolist()
    return RunSettings(target=target, max_time=max_time, start=points, start_spread=start_spread)


def maximize(
    f: Callable[[np.ndarray], float],
    bounds: Bounds,
    optimizer: str = "hs",
    *,
    budget: int = 1000,
    seed: int | None = None,
    target: float | None = None,
    max_time: float | None = None,
    store: str | Path | None = None,
    start: Sequence[float] | Sequence[Sequence[float]] | None = None,
    start_spread: float = 0.05,
    bound: Callable[[np.ndarray], float] | None = None,
    **params: Any,
) -> Result:
    """As minimize, for the largest f(x); ``target`` stops the run at or above it, and
    ``bound`` is never below f(x)."""
    settings = _settings(target, max_time, start, start_spread)
    return _optimize(
        f, bounds, optimizer, Sense.MAXIMIZE, budget, seed, settings, store, params, bound
    )


def _optimize(
    f: Callable[[np.ndarray], float],
    bounds: Bounds,
    optimizer: str,
    sense: Sense,
    budget: int,
    seed: int | None,
    settings: RunSettings,
    store: str | Path | None,
    params: dict[str, Any],
    bound: Callable[[np.ndarray], float] | None,
) -> Result:
    if not callable(f):
        raise ConfigError(f"f must be a function of x, got {type(f).__name__}")
    if bound is not None and not callable(bound):
        raise ConfigError(f"bound must be a function of x or None, got {type(bound).__name__}")
    problem = _FunctionProblem(f, as_space(bounds), sense, bound)
    settings = replace(settings, screen=problem.screens)
    name = f"python:{getattr(f, '__qualname__', type(f).__name__)}"
    problem_info = ProblemInfo(name, "a Python function", factory=lambda: problem)
    spec = RunSpec(
        optimizer=optimizer,
        problem=name,
        budget=budget,
        seed=secrets.randbelow(2**31) if seed is None else seed,
        optimizer_params=params,
        settings=settings,
    )
    optimizer_info = registry().optimizer(optimizer)
    if store is None:  # kept while its evaluations are read: it lives in this connection
        with RunStore(IN_MEMORY) as run_store:
            result = run(spec, optimizer_info, problem_info, run_store)
            records = list(run_store.evaluations(result.run_id))
    else:  # run() opens it once every setting has passed: a refused run leaves no file
        result = run(spec, optimizer_info, problem_info, store)
        with RunStore(store) as run_store:
            records = list(run_store.evaluations(result.run_id))
    fitness = np.array([np.nan if r.fitness is None else r.fitness for r in records])
    history = History(
        x=np.array([r.x for r in records]),
        fitness=fitness,
        best=convergence(fitness, sense is Sense.MAXIMIZE).best,
        screened=np.array([r.status == "screened" for r in records], dtype=bool),
    )
    return Result(
        x=result.best_x,
        fitness=float(result.best_fitness),
        evaluations=result.evaluations,
        failed=result.failed,
        screened=result.screened,
        history=history,
        seed=spec.seed,
        run_id=None if store is None else result.run_id,
    )
