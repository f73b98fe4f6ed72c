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
from metaopt.seeding import EvaluationSeeds
from metaopt.store import EvaluationRecord, RunRecord, RunStore


@dataclass
class Replay:
    """The stored best evaluation beside its re-evaluation."""

    run: RunRecord
    stored: EvaluationRecord
    problem_params: dict[str, Any]
    replayed: Outcome


def stored_best(store: RunStore, run_id: int | str) -> tuple[RunRecord, EvaluationRecord]:
    """Run ``run_id`` and its best successful evaluation (StoreError when it has none)."""
    run = store.run(run_id)
    best = store.best_evaluation(run)
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
    """Evaluate run ``run_id``'s best candidate again with its seed.

    ``overrides`` changes problem parameters (e.g. ``{"backend": "pybullet"}``); everything else
    is as stored with the run.
    """
    run, best = stored_best(store, run_id)
    info, params = replay_params(run, plugins, overrides)
    problem = info.factory(**params)
    task = EvaluationTask(best.index, np.asarray(best.x), best.seed, info.factory, params)
    try:
        with adopt_problem(info.factory, params, problem):
            outcome = evaluate_task(task)
    finally:
        problem.close()
    return Replay(run, best, params, outcome)


@dataclass
class SeedReplay:
    """The stored best evaluation beside its re-evaluations with fresh seeds."""

    run: RunRecord
    stored: EvaluationRecord
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
