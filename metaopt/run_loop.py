"""The run loop: asks the optimizer, evaluates, stores, reports progress, and owns the budget.

Optimizers and problems never touch processes, files or the terminal; this module does, through
a RunStore and an optional Progress observer.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from metaopt.errors import ConfigError
from metaopt.optimizer import Optimizer, OptimizerInfo
from metaopt.params import resolve
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense
from metaopt.seeding import EvaluationSeeds
from metaopt.store import RunStore
from metaopt.versions import environment_versions

CHECKPOINT_INTERVAL = 1.0


class Progress(Protocol):
    """What the run loop tells an observer (the CLI's progress bar) as a run goes on."""

    def start(self, total: int, done: int) -> None:
        """The run starts (or resumes) with ``done`` of ``total`` evaluations behind it."""

    def update(self, done: int, best: float | None) -> None:
        """``done`` evaluations are finished; ``best`` is the best fitness so far."""


@dataclass
class RunSpec:
    """Everything that defines a run: plugins, their parameters, budget and seed."""

    optimizer: str
    problem: str
    budget: int
    seed: int
    optimizer_params: dict[str, Any] = field(default_factory=dict)
    problem_params: dict[str, Any] = field(default_factory=dict)


@dataclass
class RunResult:
    """What a finished (or interrupted) run reports."""

    run_id: int
    status: str
    evaluations: int
    failed: int
    best_fitness: float | None
    best_x: np.ndarray | None
    best_metrics: dict[str, float]
    wall_time: float
    names: tuple[str, ...]
    key_metrics: tuple[str, ...]


@dataclass
class _Best:
    """Best successful evaluation so far, in the optimizer's (minimizing) terms."""

    score: float = math.inf
    fitness: float | None = None
    x: np.ndarray | None = None
    metrics: dict[str, float] = field(default_factory=dict)


def evaluate_safely(problem: Problem, x: np.ndarray, seed: int) -> tuple[Evaluation | None, str]:
    """Run problem.evaluate; a raised error or a non-finite fitness becomes (None, reason)."""
    try:
        evaluation = problem.evaluate(x, seed)
        fitness = float(evaluation.fitness)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as error:  # a plugin's failure on one candidate must not end the run
        return None, f"{type(error).__name__}: {error}"
    if not math.isfinite(fitness):
        return None, f"fitness is {fitness}"
    evaluation.fitness = fitness
    return evaluation, ""


def run(
    spec: RunSpec,
    optimizer_info: OptimizerInfo,
    problem_info: ProblemInfo,
    store: RunStore,
    progress: Progress | None = None,
) -> RunResult:
    """Run spec.optimizer on spec.problem for spec.budget evaluations, storing each one.

    Parameters are validated against the plugins' declarations first (ConfigError on bad input).
    Ctrl-C marks the run 'interrupted' (everything finished is stored) and re-raises.
    """
    if spec.budget < 1:
        raise ConfigError(f"budget must be a positive number of evaluations, got {spec.budget}")
    given = dict(spec.optimizer_params)
    if any(p.name == "budget" for p in optimizer_info.params):
        given.setdefault("budget", spec.budget)  # schedules (e.g. IHS) follow the run's budget
    optimizer_params = resolve(optimizer_info.params, given, optimizer_info.name)
    problem_params = resolve(problem_info.params, spec.problem_params, problem_info.name)
    problem = problem_info.factory(**problem_params)
    try:
        optimizer = optimizer_info.factory(problem.space, spec.seed, **optimizer_params)
        run_id = store.create_run(
            optimizer=optimizer_info.name,
            optimizer_params=optimizer_params,
            problem=problem_info.name,
            problem_params=problem_params,
            seed=spec.seed,
            budget=spec.budget,
            sense=Sense(problem.sense).value,
            space=problem.space.to_json(),
            versions=environment_versions(),
        )
        return _loop(run_id, spec, optimizer, problem, store, progress)
    finally:
        problem.close()


def _loop(
    run_id: int,
    spec: RunSpec,
    optimizer: Optimizer,
    problem: Problem,
    store: RunStore,
    progress: Progress | None,
) -> RunResult:
    sign = -1.0 if Sense(problem.sense) is Sense.MAXIMIZE else 1.0
    evaluation_seed = EvaluationSeeds(spec.seed)
    best = _Best()
    done = told = failed = 0
    started = time.perf_counter()
    last_checkpoint = started
    if progress is not None:
        progress.start(spec.budget, done)
    status, message = "failed", None
    try:
        while done < spec.budget:
            batch = optimizer.ask(min(optimizer.batch_size, spec.budget - done))
            scores = np.empty(len(batch))
            for row, x in enumerate(batch):
                seed = evaluation_seed(done)
                tick = time.perf_counter()
                evaluation, error = evaluate_safely(problem, x, seed)
                wall = time.perf_counter() - tick
                if evaluation is None:
                    failed += 1
                    scores[row] = math.inf
                    store.add_evaluation(run_id, done, x, None, None, error, seed, wall)
                else:
                    score = sign * evaluation.fitness
                    scores[row] = score
                    if score < best.score:
                        best = _Best(score, evaluation.fitness, x.copy(), evaluation.metrics)
                    store.add_evaluation(
                        run_id, done, x, evaluation.fitness, evaluation.metrics, None, seed, wall
                    )
                done += 1
            optimizer.tell(batch, scores)
            told = done
            now = time.perf_counter()
            if now - last_checkpoint >= CHECKPOINT_INTERVAL:
                store.flush(checkpoint=(run_id, told, optimizer.state_dict()))
                last_checkpoint = now
            if progress is not None:
                progress.update(done, best.fitness)
        status = "finished"
    except KeyboardInterrupt:
        status, message = "interrupted", "stopped by the user"
        raise
    except BaseException as error:
        message = f"{type(error).__name__}: {error}"
        raise
    finally:
        wall_time = time.perf_counter() - started
        # The state matches the evaluations told so far; later ones are stored but untold.
        store.flush(checkpoint=(run_id, told, optimizer.state_dict()))
        store.finish_run(run_id, status, wall_time, message)
    return RunResult(
        run_id=run_id,
        status=status,
        evaluations=done,
        failed=failed,
        best_fitness=best.fitness,
        best_x=best.x,
        best_metrics=best.metrics,
        wall_time=wall_time,
        names=problem.space.names,
        key_metrics=tuple(problem.key_metrics),
    )
