"""Re-evaluating a stored run's best candidate, on the same problem settings or changed ones."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from metaopt.errors import ConfigError, StoreError
from metaopt.executors import (
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
from metaopt.store import CandidateRecord, RunRecord, RunStore


@dataclass
class Replay:
    """The stored best candidate beside its re-evaluation (with resampling: every sample again
    with its own seed, aggregated alike)."""

    run: RunRecord
    stored: CandidateRecord
    problem_params: dict[str, Any]
    replayed: Outcome


def stored_best(store: RunStore, run_id: int | str) -> tuple[RunRecord, CandidateRecord]:
    """Run ``run_id`` and its best candidate (StoreError when it has no successful one)."""
    run = store.run(run_id)
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


def replay_best(
    store: RunStore, run_id: int | str, plugins: Registry, overrides: dict[str, Any]
) -> Replay:
    """Evaluate run ``run_id``'s best candidate again with its seeds.

    ``overrides`` changes problem parameters (e.g. ``{"backend": "pybullet"}``); everything else
    is as stored with the run.
    """
    run, best = stored_best(store, run_id)
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
    run_id: int | str,
    plugins: Registry,
    overrides: dict[str, Any],
    seeds: int,
    seed: int,
    executor: Executor,
) -> SeedReplay:
    """Evaluate run ``run_id``'s best candidate with ``seeds`` evaluation seeds drawn from
    ``seed`` (not the one it was found with): on a noisy problem, what the candidate does
    rather than what one episode did. ``overrides`` as for replay_best."""
    if seeds < 1:
        raise ConfigError(f"seeds must be at least 1, got {seeds}")
    run, best = stored_best(store, run_id)
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
