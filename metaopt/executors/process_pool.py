"""Local worker processes that survive their workers: a dead worker's task is retried once on a
fresh process and then failed with the reason, and a worker found dead when given a task (it
died idle) is replaced, the task going to the next free one untried; a task past its time limit
is stopped by killing its worker, and a worker whose task its own alarm stopped is replaced too
(the stop may have cut an import short). The limit counts from the end of the problem's set-up,
which the worker reports. Each worker runs one task at a time, so a death is always traced to
its task."""

from __future__ import annotations

import collections
import contextlib
import multiprocessing
import threading
import time
from concurrent.futures import Future
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait

from metaopt.executors.base import (
    EvaluationTask,
    Executor,
    Outcome,
    evaluate_task,
    prepared_problem,
    release_problems,
)

#: How often the manager thread looks at the clock when nothing else happens (time limits).
POLL_INTERVAL = 0.05
#: What a worker sends when its problem is set up and the task's timed evaluation begins.
STARTED = "started"


def _worker_main(connection: Connection) -> None:
    """A worker process: evaluate tasks until told to stop (None) or the pipe closes."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    try:
        while True:
            task = connection.recv()
            if task is None:
                break
            with contextlib.suppress(Exception):  # a set-up error is evaluate_task's to report
                prepared_problem(task)
            connection.send(STARTED)  # the time limit counts from here
            connection.send(evaluate_task(task))
    except (EOFError, OSError):
        pass
    finally:
        release_problems()


@dataclass
class _Job:
    task: EvaluationTask
    future: Future
    attempt: int = 1


class _Worker:
    """One worker process, its pipe, and the job it is running."""

    def __init__(self, context: multiprocessing.context.BaseContext) -> None:
        self.connection, child = context.Pipe()
        self.process = context.Process(target=_worker_main, args=(child,), daemon=True)
        self.process.start()
        child.close()
        self.job: _Job | None = None
        #: when the job's timed evaluation began (None: its problem is still being set up)
        self.started: float | None = None

    def start(self, job: _Job) -> None:
        """Send the job's task; the job is this worker's only once sent, so a send that fails
        (OSError: the pipe broke, the process died idle) leaves the worker without it."""
        self.connection.send(job.task)
        self.job, self.started = job, None

    def kill(self) -> None:
        """Kill the process (if it still runs), wait for it, then close its pipe and the Process
        object (its sentinel's descriptor): a worker is replaced, never reused."""
        self.process.kill()
        self.process.join()
        self.connection.close()
        self.process.close()


class ProcessExecutor(Executor):
    """N local worker processes (spawned, so no engine state is inherited by fork)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._context = multiprocessing.get_context("spawn")
        self._lock = threading.Lock()
        self._queue: collections.deque[_Job] = collections.deque()
        self._pool = [_Worker(self._context) for _ in range(workers)]
        # submit() writes here to wake the manager at once instead of at its next poll.
        self._wake_reader, self._wake_writer = self._context.Pipe(duplex=False)
        self._stopping = False
        self._manager = threading.Thread(target=self._manage, name="metaopt-pool", daemon=True)
        self._manager.start()

    def submit(self, task: EvaluationTask) -> Future:
        future: Future = Future()
        with self._lock:
            self._queue.append(_Job(task, future))
        self._wake_writer.send_bytes(b"")
        return future

    def _manage(self) -> None:
        while not self._stopping:
            self._assign()
            busy = [w for w in self._pool if w.job is not None]
            watched = [w.connection for w in busy] + [w.process.sentinel for w in busy]
            ready = wait([self._wake_reader, *watched], timeout=POLL_INTERVAL)
            while self._wake_reader.poll():
                self._wake_reader.recv_bytes()
            for worker in busy:
                if worker.connection in ready:
                    self._collect(worker)
                elif worker.process.sentinel in ready or not worker.process.is_alive():
                    self._replace_dead(worker)
                else:
                    self._enforce_time_limit(worker)

    def _assign(self) -> None:
        """Give each idle worker the next waiting job."""
        for worker in list(self._pool):
            if worker.job is None and (job := self._next_job()) is not None:
                self._start(worker, job)

    def _next_job(self) -> _Job | None:
        """Take the job first in line off the queue (None when none waits)."""
        with self._lock:
            return self._queue.popleft() if self._queue else None

    def _start(self, worker: _Worker, job: _Job) -> None:
        """Hand the job to an idle worker. One whose pipe is broken (it died idle: killed from
        outside, the OOM killer) is replaced as one that died under its task, and the job,
        which it never ran, goes back first in line with its attempt unspent."""
        try:
            worker.start(job)
        except OSError:
            self._replace_dead(worker)
            with self._lock:
                self._queue.appendleft(job)

    def _collect(self, worker: _Worker) -> None:
        try:
            outcome = worker.connection.recv()
        except (EOFError, OSError):
            self._replace_dead(worker)
            return
        if outcome == STARTED:
            worker.started = time.monotonic()
            return
        job, worker.job = worker.job, None
        if outcome.timed_out:  # stopped mid-evaluation, maybe mid-import: start afresh
            worker.kill()
            self._pool[self._pool.index(worker)] = _Worker(self._context)
        job.future.set_result(outcome)

    def _replace_dead(self, worker: _Worker) -> None:
        job = worker.job
        code = worker.process.exitcode
        worker.kill()
        self._pool[self._pool.index(worker)] = _Worker(self._context)
        if job is None:
            return
        if job.attempt == 1:
            with self._lock:
                self._queue.appendleft(_Job(job.task, job.future, attempt=2))
            return
        reason = f"worker process died twice on this candidate (exit code {code})"
        job.future.set_result(Outcome(job.task.index, None, error=reason))

    def _enforce_time_limit(self, worker: _Worker) -> None:
        job = worker.job
        limit = job.task.time_limit if job else None
        if limit is None or worker.started is None or time.monotonic() - worker.started <= limit:
            return
        worker.job = None
        worker.kill()
        self._pool[self._pool.index(worker)] = _Worker(self._context)
        reason = f"EvaluationTimeout: exceeded the time limit of {limit:g} s (worker stopped)"
        job.future.set_result(Outcome(job.task.index, None, error=reason, wall_time=limit))

    def shutdown(self) -> None:
        """Stop the manager and the workers (a busy one is killed after 2 s), cancel what
        waits, and close every pipe, so no descriptor outlives the pool; a second call (the
        run's, then its caller's) does nothing."""
        if self._stopping:
            return
        self._stopping = True
        self._wake_writer.send_bytes(b"")
        self._manager.join()
        for worker in self._pool:
            if worker.job is None:
                with contextlib.suppress(OSError):
                    worker.connection.send(None)
        for worker in self._pool:
            worker.process.join(timeout=2)
            worker.kill()  # only one still busy is killed; every pipe and process is closed
        for job in self._queue:
            job.future.cancel()
        self._wake_reader.close()
        self._wake_writer.close()
