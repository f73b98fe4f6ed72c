"""Re-evaluating a stored run's best candidate (or another one, ``RUN:NUMBER``), on the same
problem settings or changed ones."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

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
from metaopt.storage.run_store import CandidateRecord, RunRecord, RunStore


@dataclass
class Replay:
    """The stored best candidate beside its re-evaluation (with resampling: every sample again
    with its own seed, aggregated alike)."""

    run: RunRecord
    stored: CandidateRecord
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


def replay_params(
    run: RunRecord, plugins: Registry, overrides: dict[str, Any]
) -> tuple[ProblemInfo, dict[str, Any]]:
    """The run's problem and its stored parameters with ``overrides`` applied and checked."""
    info = plugins.problem(run.problem)
    declared = {p.name for p in info.params}
    for name in overrides:
        if name not in declared:
            raise ConfigError(
                f"problem {run.problem!r} has no parameter {name!r}; "
                f"accepted: {', '.join(sorted(declared)) or 'none'}"
            )
    return info, resolve(info.params, {**run.problem_params, **overrides}, info.name)


def replay_candidate(
    store: RunStore, target: int | str, plugins: Registry, overrides: dict[str, Any]
) -> Replay:
    """Evaluate ``target``'s candidate (a run's best, or ``RUN:NUMBER``) again with its seeds.

    ``overrides`` changes problem parameters (e.g. ``{"backend": "pybullet"}``); everything else
    is as stored with the run.
    """
    run, best = stored_candidate(store, target)
    info, params = replay_params(run, plugins, overrides)
    problem = info.factory(**params)
    try:
        with adopt_problem(info.factory, params, problem):
            outcomes = [
                evaluate_task(
                    EvaluationTask(e.index, np.asarray(best.x), e.seed, info.factory, params)
                )
                for e in best.samples
            ]
    finally:
        problem.close()
    return Replay(run, best, params, _combined(outcomes, best.aggregate))


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
    """The stored best evaluation beside its re-evaluations with fresh seeds."""

    run: RunRecord
    stored: CandidateRecord
    problem_params: dict[str, Any]
    outcomes: list[Outcome]


def replay_seeds(
    store: RunStore,
    target: int | str,
    plugins: Registry,
    overrides: dict[str, Any],
    seeds: int,
    seed: int,
    executor: Executor,
) -> SeedReplay:
    """Evaluate ``target``'s candidate (as replay_candidate) with ``seeds`` evaluation seeds
    drawn from ``seed`` (not the one it was found with): on a noisy problem, what the
    candidate does rather than what one episode did. ``overrides`` as for replay_candidate."""
    if seeds < 1:
        raise ConfigError(f"seeds must be at least 1, got {seeds}")
    run, best = stored_candidate(store, target)
    info, params = replay_params(run, plugins, overrides)
    info.factory(**params).close()  # a problem refusing its parameters says so before work
    draw = EvaluationSeeds(seed)
    x = np.asarray(best.x)
    futures = [
        executor.submit(EvaluationTask(i, x, draw(i), info.factory, params)) for i in range(seeds)
    ]
    try:
        outcomes = [future.result() for future in futures]
    finally:
        release_problems()
    return SeedReplay(run, best, params, outcomes)
