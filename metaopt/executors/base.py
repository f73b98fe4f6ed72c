"""Where evaluations run: the Executor interface, the evaluation task, and the serial executor.

An executor takes EvaluationTasks and returns concurrent.futures Futures of Outcomes, whatever
runs them (this process, local worker processes, a Dask cluster, or an executor an outside
plugin adds through the ``metaopt_executors`` hook). Problems are built once per worker
process from their factory and parameters and reused for every task (heavy set-up such as a
physics model or a cached lock phase happens once per worker).
"""

from __future__ import annotations

import json
import math
import signal
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from concurrent.futures import Future, InvalidStateError
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from metaopt.problem import Evaluation, Problem


@dataclass(frozen=True)
class EvaluationTask:
    """One evaluation to run: which problem (factory + parameters), which candidate, which seed."""

    index: int
    x: np.ndarray
    seed: int
    factory: Callable[..., Problem]
    params: dict[str, Any]
    time_limit: float | None = None
    #: problem_key(factory, params), when the sender has it already (saves a JSON encoding per
    #: task); empty: computed where the task runs.
    problem_key: str = ""
    #: "evaluate" (the whole evaluation), "screen" (only its cheap part, Problem.screen) or
    #: "complete" (the rest after a screen that gave ``screened``, Problem.complete)
    phase: str = "evaluate"
    screened: Evaluation | None = None


@dataclass
class Outcome:
    """What came back: the fitness and metrics, or the error that made the evaluation fail."""

    index: int
    fitness: float | None
    metrics: dict[str, float] = field(default_factory=dict)
    error: str | None = None
    wall_time: float = 0.0
    #: a screen's bound stands in for the fitness (None): the full evaluation was not needed
    #: (metaopt run --screen); metrics hold the screen's, and the bound as SCREEN_BOUND
    screened: bool = False

    @property
    def timed_out(self) -> bool:
        """Stopped by its time limit (the process that ran it may hold a half-done import)."""
        return self.error is not None and self.error.startswith(EvaluationTimeout.__name__)


#: The metric a screened evaluation stores its bound in (the fitness its full evaluation could
#: not have bettered).
SCREEN_BOUND = "screen_bound"


def settle(future: Future, outcome: Outcome) -> None:
    """Give a task's future its outcome, unless it settled meanwhile: its caller or shutdown
    cancelled it, or its time limit passed, as the outcome came (a settled future refuses a
    result, and one caller's cancel must not stop the executor)."""
    with suppress(InvalidStateError):
        future.set_result(outcome)


def wake_if_cancelled(future: Future) -> None:
    """Wake the wait()ers of a cancelled task's future: cancel() alone leaves it CANCELLED, never
    notified, so wait() and as_completed() would block on it for ever. Called from the future's
    done callback, which runs once, in the thread whose cancel succeeded first: the one place
    it is notified."""
    if future.cancelled():
        future.set_running_or_notify_cancel()


class EvaluationTimeout(Exception):
    """An evaluation ran past its time limit."""


_problems: dict[str, Problem] = {}


def problem_key(factory: Callable[..., Problem], params: dict[str, Any]) -> str:
    """The per-process cache key of a problem built by factory(**params)."""
    name = (
        f"{getattr(factory, '__module__', '?')}.{getattr(factory, '__qualname__', repr(factory))}"
    )
    return f"{name}:{json.dumps(params, sort_keys=True)}"


@contextmanager
def adopt_problem(
    factory: Callable[..., Problem], params: dict[str, Any], problem: Problem
) -> Iterator[None]:
    """While inside, in-process evaluations reuse this already built problem (the run loop's
    own) instead of building a second one; its owner closes it."""
    key = problem_key(factory, params)
    _problems[key] = problem
    try:
        yield
    finally:
        if _problems.get(key) is problem:
            del _problems[key]


def release_problems() -> None:
    """Close and forget every problem this process built (end of a run, worker shutdown)."""
    while _problems:
        _, problem = _problems.popitem()
        problem.close()


def prepared_problem(task: EvaluationTask) -> Problem:
    """The task's problem in this process, built on first use and prepared (Problem.prepare),
    so the task's time limit counts only the evaluation itself."""
    key = task.problem_key or problem_key(task.factory, task.params)
    problem = _problems.get(key)
    if problem is None:
        problem = _problems[key] = task.factory(**task.params)
    problem.prepare()
    return problem


def evaluate_task(task: EvaluationTask) -> Outcome:
    """Run one task in this process: a raised error or a non-finite fitness becomes a failure."""
    start = time.perf_counter()
    try:
        problem = prepared_problem(task)
        with _alarm(task.time_limit):
            evaluation = _run_phase(problem, task)
        fitness = float(evaluation.fitness)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as error:  # one candidate's failure must not end the run
        reason = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
        return Outcome(task.index, None, error=reason, wall_time=time.perf_counter() - start)
    wall = time.perf_counter() - start
    if not math.isfinite(fitness):
        return Outcome(task.index, None, error=f"fitness is {fitness}", wall_time=wall)
    return Outcome(task.index, fitness, dict(evaluation.metrics), wall_time=wall)


def _run_phase(problem: Problem, task: EvaluationTask) -> Evaluation:
    """The part of the evaluation the task asks for (EvaluationTask.phase)."""
    if task.phase == "screen":
        return problem.screen(task.x, task.seed)
    if task.phase == "complete":
        assert task.screened is not None, "a complete task carries its screen's evaluation"
        return problem.complete(task.x, task.seed, task.screened)
    return problem.evaluate(task.x, task.seed)


class _alarm:
    """Raise EvaluationTimeout after ``seconds`` (main thread of a Unix process only)."""

    def __init__(self, seconds: float | None) -> None:
        usable = seconds and hasattr(signal, "setitimer") and _in_main_thread()
        self.seconds = seconds if usable else None

    def __enter__(self) -> None:
        if self.seconds:
            self._previous = signal.signal(signal.SIGALRM, self._expire)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)

    def __exit__(self, *exc_info: object) -> None:
        if self.seconds:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self._previous)

    def _expire(self, signum: int, frame: object) -> None:
        raise EvaluationTimeout(f"exceeded the time limit of {self.seconds:g} s")


def _in_main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


class Executor(ABC):
    """Runs EvaluationTasks; ``workers`` of them at a time."""

    #: How many tasks run at once.
    workers: int = 1
    #: Seconds it took to start (worker processes, a cluster), set by whoever built it; a run
    #: counts them in its wall time.
    startup_time: float = 0.0
    #: The address of a page showing the workers as they run, where the executor serves one
    #: (a local Dask cluster's dashboard); None otherwise.
    dashboard: str | None = None
    #: The package (with its version bound) that page needs to show the workers, where it is
    #: not installed: until then the page is a placeholder; None when nothing is missing.
    dashboard_needs: str | None = None

    @property
    def capacity(self) -> int:
        """Tasks to keep in flight so no worker waits (async mode); more than ``workers`` where
        handing a task over takes a round trip."""
        return self.workers

    @abstractmethod
    def submit(self, task: EvaluationTask) -> Future:
        """Start a task; the Future's result is its Outcome, a failed one included. Only an
        executor broken for good fails it with concurrent.futures.BrokenExecutor instead (and
        raises it from later submits), which ends the run as failed rather than leave it
        waiting; and one shut down, where the task would never run, raises RuntimeError (as
        concurrent.futures does) rather than return a future that never settles."""

    def shutdown(self) -> None:  # noqa: B027 - nothing to free for in-process executors
        """Stop workers; unfinished tasks are abandoned."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.shutdown()


class SerialExecutor(Executor):
    """Evaluates each task in this process as it is submitted (the default)."""

    workers = 1

    def submit(self, task: EvaluationTask) -> Future:
        future: Future = Future()
        future.set_result(evaluate_task(task))
        return future


@dataclass(frozen=True)
class ExecutorInfo:
    """How a plugin announces an executor: ``factory(workers, address) -> Executor``.

    ``address`` is the --scheduler value (None when not given); executors that run locally
    ignore it.
    """

    name: str
    summary: str
    factory: Callable[[int, str | None], Executor]
