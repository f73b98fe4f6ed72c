"""The problem checks: a problem built from its declared parameters, evaluated at its space's
centre and at uniform samples, where every evaluation must be finite, well formed and a pure
function of (x, seed), in this process and (optionally) in a spawned one."""

from __future__ import annotations

import math
import numbers
import pickle
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from multiprocessing import get_context
from typing import Any

import numpy as np

from metaopt.plugins import registry
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense
from metaopt.seeding import EvaluationSeeds
from metaopt.space import Space
from metaopt.testing.common import (
    Check,
    ConformanceError,
    build,
    check_binds,
    check_declared_params,
    resolve_given,
    run_all,
    same,
)

#: Points each problem check evaluates: the space's centre and this many uniform samples.
PROBLEM_SAMPLES = 4


def check_problem(
    problem: str | ProblemInfo,
    params: Mapping[str, Any] | None = None,
    *,
    in_subprocess: bool = False,
) -> None:
    """Run every problem check (with ``in_subprocess``, also the spawned-process one)."""
    checks = problem_checks(problem, params, in_subprocess=in_subprocess)
    run_all(_problem_info(problem).name, checks)


def problem_checks(
    problem: str | ProblemInfo,
    params: Mapping[str, Any] | None = None,
    *,
    in_subprocess: bool = False,
) -> dict[str, Check]:
    """The problem checks by name; ``in_subprocess`` adds the (slower) spawned-process check."""
    info = _problem_info(problem)
    harness = _ProblemHarness(info, dict(params or {}))
    checks: dict[str, Check] = {
        "declared_params": partial(check_declared_params, info.params, info.name),
        "factory_keywords": harness.check_factory_keywords,
        "interface": harness.check_interface,
        "evaluate": harness.check_evaluate,
        "key_metrics": harness.check_key_metrics,
        "pure": harness.check_pure,
    }
    if in_subprocess:
        checks["pure_in_subprocess"] = harness.check_pure_in_subprocess
    return checks


def _problem_info(problem: str | ProblemInfo) -> ProblemInfo:
    return registry().problem(problem) if isinstance(problem, str) else problem


def _is_real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _evaluate_all(problem: Problem, points: np.ndarray, seeds: Sequence[int]) -> list[Evaluation]:
    results = []
    for x, seed in zip(points, seeds):
        argument = x.copy()
        try:
            result = problem.evaluate(argument, seed)
        except Exception as error:
            raise ConformanceError(
                f"evaluate(x, seed={seed}) raised {type(error).__name__}: {error} at x = "
                f"{x.tolist()}, a point inside the space; every point of the space should "
                "evaluate (raise EvaluationError only where it truly cannot)"
            ) from None
        if not same(argument, x):
            raise ConformanceError(
                "evaluate changed the x it was given; work on a copy (the run loop stores x)"
            )
        results.append(result)
    return results


def _evaluate_fresh(
    factory: Callable[..., Problem], values: dict[str, Any], points: list, seeds: list
) -> list[tuple[float, dict[str, float]]]:
    """Build the problem and evaluate; runs in a spawned process for the subprocess check."""
    problem = factory(**values)
    try:
        results = [problem.evaluate(np.array(x), seed) for x, seed in zip(points, seeds)]
    finally:
        problem.close()
    return [(r.fitness, r.metrics) for r in results]


class _ProblemHarness:
    """Builds the problem under test and evaluates the kit's points on it."""

    def __init__(self, info: ProblemInfo, given: dict[str, Any]) -> None:
        self.info = info
        self.given = given

    def values(self) -> dict[str, Any]:
        return resolve_given(self.info.params, self.given, self.info.name)

    def build(self) -> Problem:
        return build(self.info.factory, (), self.values(), Problem)

    def points(self, problem: Problem) -> tuple[np.ndarray, list[int]]:
        """The space's centre and uniform samples, with seeds as a run would give them."""
        space = problem.space
        centre = (space.lower + 0.5 * space.width)[None, :]
        samples = space.sample(np.random.default_rng(2024), PROBLEM_SAMPLES)
        seeds = EvaluationSeeds(1)
        return np.vstack([centre, samples]), [seeds(i) for i in range(1 + PROBLEM_SAMPLES)]

    def evaluations(self) -> tuple[np.ndarray, list[int], list[Evaluation]]:
        """The kit's points evaluated on a fresh problem (closed after)."""
        problem = self.build()
        try:
            self.check_space(problem)
            points, seeds = self.points(problem)
            return points, seeds, _evaluate_all(problem, points, seeds)
        finally:
            problem.close()

    def check_space(self, problem: Problem) -> None:
        if not isinstance(getattr(problem, "space", None), Space):
            raise ConformanceError(
                f"problem.space is {type(getattr(problem, 'space', None)).__name__}; set it to "
                "a metaopt.Space in __init__ (e.g. Space.from_bounds(lower, upper))"
            )

    def check_factory_keywords(self) -> None:
        """factory(**params) takes every declared parameter and builds a Problem."""
        check_binds(self.info.factory, (), self.values())
        self.build().close()

    def check_interface(self) -> None:
        """A Space, a Sense, key_metrics names, a finite optimum or None."""
        problem = self.build()
        try:
            self.check_space(problem)
            try:
                Sense(problem.sense)
            except ValueError:
                raise ConformanceError(
                    f"problem.sense is {problem.sense!r}; use Sense.MINIMIZE or Sense.MAXIMIZE"
                ) from None
            metrics = problem.key_metrics
            if isinstance(metrics, str) or not all(isinstance(m, str) for m in metrics):
                raise ConformanceError(
                    f"key_metrics is {metrics!r}; make it a tuple of metric names, "
                    "e.g. ('distance',)"
                )
            optimum = problem.optimum
            if optimum is not None and not (_is_real(optimum) and math.isfinite(optimum)):
                raise ConformanceError(
                    f"optimum is {optimum!r}; make it the known best fitness or None"
                )
        finally:
            problem.close()

    def check_evaluate(self) -> None:
        """Each kit point gives an Evaluation: finite float fitness, metrics of str -> float."""
        points, _, results = self.evaluations()
        for x, result in zip(points, results):
            at = f"at x = {x.tolist()}"
            if not isinstance(result, Evaluation):
                raise ConformanceError(
                    f"evaluate returned {type(result).__name__} {at}; return "
                    "metaopt.Evaluation(fitness, metrics)"
                )
            fitness = result.fitness
            if not _is_real(fitness):
                raise ConformanceError(
                    f"fitness is {type(fitness).__module__}.{type(fitness).__name__} "
                    f"{fitness!r} {at}; return a float (float(value))"
                )
            if not math.isfinite(fitness):
                raise ConformanceError(
                    f"fitness is {fitness!r} {at}, a point inside the space; return a finite "
                    "float (NaN and inf mark a failed evaluation)"
                )
            self.check_metrics(result.metrics, at)

    def check_metrics(self, metrics: Any, at: str) -> None:
        if not isinstance(metrics, dict):
            raise ConformanceError(
                f"metrics is {type(metrics).__name__} {at}; return a dict of name -> float"
            )
        for name, value in metrics.items():
            if not isinstance(name, str):
                raise ConformanceError(f"metric name {name!r} is not a str {at}")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConformanceError(
                    f"metric {name!r} is {type(value).__module__}.{type(value).__name__} "
                    f"{value!r} {at}; metric values must be Python floats (float(value)) so the "
                    "run store can write them as JSON"
                )

    def check_key_metrics(self) -> None:
        """Every name in key_metrics is among the metrics each evaluation returns."""
        problem = self.build()
        key_metrics = tuple(problem.key_metrics)
        problem.close()
        points, _, results = self.evaluations()
        for x, result in zip(points, results):
            missing = [m for m in key_metrics if m not in result.metrics]
            if missing:
                raise ConformanceError(
                    f"key_metrics names {missing} but evaluate returned only "
                    f"{sorted(result.metrics)} at x = {x.tolist()}; return every key metric, "
                    "or drop it from key_metrics"
                )

    def check_pure(self) -> None:
        """The same (x, seed) gives the same Evaluation again, in any order, on a fresh problem."""
        points, seeds, first = self.evaluations()
        problem = self.build()
        try:
            reverse = _evaluate_all(problem, points[::-1], seeds[::-1])[::-1]
            again = _evaluate_all(problem, points, seeds)
        finally:
            problem.close()
        for label, results in (("in reverse order", reverse), ("again", again)):
            for x, seed, a, b in zip(points, seeds, first, results):
                _requiresame(a.fitness, a.metrics, b.fitness, b.metrics, x, seed, label)

    def check_pure_in_subprocess(self) -> None:
        """A problem built by the factory in a spawned process evaluates exactly the same."""
        points, seeds, here = self.evaluations()
        try:
            pickle.dumps(self.info.factory)
        except Exception as error:
            raise ConformanceError(
                f"the factory cannot be pickled ({type(error).__name__}: {error}); process "
                "executors send it to their workers: use a module-level class or function, or "
                "functools.partial of one"
            ) from None
        with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
            job = pool.submit(
                _evaluate_fresh, self.info.factory, self.values(), points.tolist(), seeds
            )
            try:
                there = job.result()
            except Exception as error:
                raise ConformanceError(
                    f"in a spawned process, building the problem with the factory and "
                    f"evaluating raised {type(error).__name__}: {error}; a fresh process must "
                    "import and build it from the factory alone (no state set up elsewhere)"
                ) from None
        for x, seed, a, (fitness, metrics) in zip(points, seeds, here, there):
            _requiresame(a.fitness, a.metrics, fitness, metrics, x, seed, "in another process")


def _requiresame(
    fitness: Any, metrics: dict, other_fitness: Any, other_metrics: dict, x, seed, label: str
) -> None:
    if not (same(fitness, other_fitness) and _same_metrics(metrics, other_metrics)):
        raise ConformanceError(
            f"evaluate(x, seed={seed}) at x = {x.tolist()} gave fitness {fitness!r}, then "
            f"{other_fitness!r} {label} (metrics {metrics} vs {other_metrics}); evaluate must be "
            "a pure function of (x, seed): no counters, caches that change results, global "
            "random state or clock; draw noise from np.random.default_rng(seed)"
        )


def _same_metrics(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
