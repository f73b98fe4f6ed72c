"""Re-evaluating a candidate on the same problem settings or changed ones: a stored run's best
(``RUN``), another of its candidates (``RUN:NUMBER``), its optimizer's recommendation
(``RUN:recommended``), or a candidate a problem plugin keeps as data (``NAME``, e.g. a nao-walk
gait)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from metaopt.assessment.candidates import check_run_target, space_of, stored_candidate_named
from metaopt.assessment.recommendation import RECOMMENDED, recommended_point
from metaopt.errors import ConfigError, StoreError
from metaopt.executors.base import (
    EvaluationTask,
    Executor,
    Outcome,
    adopt_problem,
    evaluate_task,
    release_problems,
)
from metaopt.params import resolve
from metaopt.plugins import Registry
from metaopt.problem import ProblemInfo
from metaopt.resampling import aggregate_samples
from metaopt.seeding import EvaluationSeeds
from metaopt.space import Space
from metaopt.storage.run_store import CandidateRecord, RunRecord, RunStore


@dataclass(frozen=True)
class ReplaySource:
    """What a replay evaluates again: a candidate, the problem parameters and the (index,
    seed) of each evaluation it was scored with, and what it scored then (a candidate a
    problem keeps as data has no stored score: fitness None, no metrics)."""

    label: str
    problem: str
    problem_params: dict[str, Any]
    x: np.ndarray
    samples: list[tuple[int, int]]
    aggregate: str = "mean"
    fitness: float | None = None
    metrics: dict[str, float] | None = None
    #: the space the candidate was found in (a run's, as stored); None: its problem's, built
    #: with problem_params
    space: Space | None = None

    @property
    def seed(self) -> int:
        """The first sample's seed: the episode a figure or video of the candidate shows."""
        return self.samples[0][1]


@dataclass
class Replay:
    """The stored candidate beside its re-evaluation (with resampling: every sample again
    with its own seed, aggregated alike)."""

    source: ReplaySource
    problem_params: dict[str, Any]
    replayed: Outcome


def stored_candidate(store: RunStore, target: int | str) -> tuple[RunRecord, CandidateRecord]:
    """The run and candidate that ``target`` names: ``RUN`` (the run's best, by its aggregate
    when it resampled) or ``RUN:NUMBER`` (its candidate NUMBER, as ``metaopt robustness --top``
    labels them); StoreError when there is none."""
    run_id, _, number = str(target).partition(":")
    run = store.run(run_id)
    if number:
        if not number.isdigit():
            raise StoreError(f"a candidate is RUN:NUMBER, e.g. 3:120; got {target!r}")
        return run, store.candidate(run, int(number))
    best = store.best_candidate(run)
    if best is None:
        raise StoreError(f"run {run.id} has no successful evaluation to replay")
    return run, best


def run_source(store: RunStore, target: int | str) -> ReplaySource:
    """``target``'s candidate in the store (as stored_candidate finds it), to replay; for
    ``RUN:recommended``, the run's recommendation with the seeds of the run's best, so the two
    are compared in the same worlds."""
    run_id, _, number = str(target).partition(":")
    if number == RECOMMENDED:
        run, best = stored_candidate(store, run_id)
        return ReplaySource(
            f"run {run.id}, recommended by {run.optimizer} (not evaluated by the run; with "
            f"the seeds of its best, candidate {best.number})",
            run.problem, run.problem_params, recommended_point(run),
            [(e.index, e.seed) for e in best.samples], best.aggregate,
            space=Space.from_json(run.space),
        )  # fmt: skip
    run, best = stored_candidate(store, target)
    return ReplaySource(
        f"run {run.id}, {best.describe()}",
        run.problem,
        run.problem_params,
        np.asarray(best.x),
        [(e.index, e.seed) for e in best.samples],
        best.aggregate,
        best.fitness,
        best.metrics,
        Space.from_json(run.space),
    )


def find_source(target: str, plugins: Registry, db_path: str) -> ReplaySource:
    """``target`` to replay: a candidate an installed problem keeps as data (``NAME``, with the
    parameters and seed it was recorded with), else ``RUN`` or ``RUN:NUMBER`` in the store at
    db_path; ConfigError naming what is accepted otherwise."""
    named = stored_candidate_named(target, plugins.problems)
    if named is not None:
        candidate, _, seed = named
        return ReplaySource(
            f"stored candidate {target}", candidate.problem, candidate.params, candidate.x,
            [(0, seed)],
        )  # fmt: skip
    check_run_target(target, plugins.problems, db_path)
    with RunStore(db_path) as store:
        return run_source(store, target)


def replay_params(
    run: RunRecord | ReplaySource, plugins: Registry, overrides: dict[str, Any]
) -> tuple[ProblemInfo, dict[str, Any]]:
    """A run's (or a replay source's) problem and its stored parameters with ``overrides``
    applied and checked (ConfigError where they change the candidate's space: check_space)."""
    info = plugins.problem(run.problem)
    declared = {p.name for p in info.params}
    for name in overrides:
        if name not in declared:
            raise ConfigError(
                f"problem {run.problem!r} has no parameter {name!r}; "
                f"accepted: {', '.join(sorted(declared)) or 'none'}"
            )
    params = resolve(info.params, {**run.problem_params, **overrides}, info.name)
    if overrides:  # the candidate's space, unless changed: a vector means nothing in another
        stored = run.space if isinstance(run, ReplaySource) else Space.from_json(run.space)
        if stored is None:
            stored = space_of(info, resolve(info.params, run.problem_params, info.name))
        check_space(overrides, stored, space_of(info, params))
    return info, params


def check_space(changes: Mapping[str, Any], candidate: Space, changed: Space) -> None:
    """ConfigError where parameter ``changes`` turn the ``candidate``'s space into another
    (other variables or bounds): its vector would be evaluated as a point it is not."""
    given = " ".join(f"--set {name}={value}" for name, value in changes.items())
    keep = "accepted: changes that keep the candidate's variables and their bounds"
    if changed.dim != candidate.dim:
        raise ConfigError(
            f"{given} changes the space to {_variables(changed)}; the candidate has "
            f"{_variables(candidate)}; {keep}"
        )
    if changed.names != candidate.names:
        raise ConfigError(
            f"{given} changes the variables to ({_names(changed)}); the candidate's are "
            f"({_names(candidate)}); {keep}"
        )
    for new, old in zip(changed.variables, candidate.variables, strict=True):
        if (new.lower, new.upper) != (old.lower, old.upper):
            raise ConfigError(
                f"{given} changes {new.name}'s bounds to [{new.lower:g}, {new.upper:g}]; the "
                f"candidate's are [{old.lower:g}, {old.upper:g}]; {keep}"
            )


def _variables(space: Space) -> str:
    """'2 variables (x0, x1)', '1 variable (x0)'."""
    return f"{space.dim} variable{'s' if space.dim != 1 else ''} ({_names(space)})"


def _names(space: Space) -> str:
    """A space's variable names, the first four then '...' where there are more."""
    return ", ".join(space.names[:4]) + (", ..." if space.dim > 4 else "")


def replay_candidate(source: ReplaySource, plugins: Registry, overrides: dict[str, Any]) -> Replay:
    """Evaluate ``source``'s candidate again with its seeds.

    ``overrides`` changes problem parameters (e.g. ``{"backend": "pybullet"}``); everything else
    is as stored.
    """
    info, params = replay_params(source, plugins, overrides)
    problem = info.factory(**params)
    try:
        with adopt_problem(info.factory, params, problem):
            outcomes = [
                evaluate_task(EvaluationTask(index, source.x, seed, info.factory, params))
                for index, seed in source.samples
            ]
    finally:
        problem.close()
    return Replay(source, params, _combined(outcomes, source.aggregate))


def _combined(outcomes: list[Outcome], aggregate: str) -> Outcome:
    """The samples' outcomes as one: aggregated, or the first failure."""
    failed = next((o for o in outcomes if o.fitness is None), None)
    if failed is not None:
        return failed
    fitness, metrics = aggregate_samples(
        [o.fitness for o in outcomes], [o.metrics for o in outcomes], aggregate
    )
    wall = sum(o.wall_time for o in outcomes)
    return Outcome(outcomes[0].index, fitness, metrics, wall_time=wall)


@dataclass
class SeedReplay:
    """The stored candidate beside its re-evaluations with fresh seeds."""

    source: ReplaySource
    problem_params: dict[str, Any]
    outcomes: list[Outcome]


def replay_seeds(
    source: ReplaySource,
    plugins: Registry,
    overrides: dict[str, Any],
    seeds: int,
    seed: int,
    executor: Executor,
) -> SeedReplay:
    """Evaluate ``source``'s candidate with ``seeds`` evaluation seeds drawn from ``seed``
    (not the one it was found with): on a noisy problem, what the candidate does rather than
    what one episode did. ``overrides`` as for replay_candidate."""
    if seeds < 1:
        raise ConfigError(f"seeds must be at least 1, got {seeds}")
    info, params = replay_params(source, plugins, overrides)
    info.factory(**params).close()  # a problem refusing its parameters says so before work
    draw = EvaluationSeeds(seed)
    futures = [
        executor.submit(EvaluationTask(i, source.x, draw(i), info.factory, params))
        for i in range(seeds)
    ]
    try:
        outcomes = [future.result() for future in futures]
    finally:
        release_problems()
    return SeedReplay(source, params, outcomes)
