"""Local worker processes that survive their workers: a dead worker's task is retried once on a
fresh process and then failed with the reason, and a worker found dead when given a task (it
died idle) is replaced, the task going to the next free one untried (if the dead one never
answered, it may never start: the task spends an attempt); a task past its time limit
is stopped by killing its worker, and a worker whose task its own alarm stopped is replaced too
(the stop may have cut an import short). The limit counts from the end of the problem's set-up,
which the worker reports. Each worker runs one task at a time, so a death is always traced to
its task. A task is pickled when submitted, an outcome before it is sent back: one that does
not pickle fails its task alone, at once; so does an outcome the parent cannot unpickle (a class
it cannot import, a load that raises), its worker serving on. Any other error in the manager
thread breaks the pool: every task waiting or running fails with BrokenExecutor naming it, and
so does every later submit, so no caller waits for ever; nor after shutdown, which cancels
every unsettled task."""

from __future__ import annotations

import collections
import contextlib
import multiprocessing
import threading
import time
from concurrent.futures import BrokenExecutor, Future, InvalidStateError
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection, wait
from multiprocessing.reduction import ForkingPickler

from metaopt.executors.base import (
    EvaluationTask,
    Executor,
    Outcome,
    evaluate_task,
    prepared_problem,
    release_problems,
    settle,
    wake_if_cancelled,
)

#: How often the manager thread looks at the clock when nothing else happens (time limits).
POLL_INTERVAL = 0.05
#: What a worker sends when its problem is set up and the task's timed evaluation begins.
STARTED = "started"
#: Seconds shutdown gives idle workers, told to stop, to close their problems and exit.
IDLE_GRACE = 2.0
#: Seconds shutdown gives a busy worker to end on SIGTERM before it is killed.
TERMINATE_GRACE = 0.2


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
            connection.send_bytes(_outcome_payload(task, evaluate_task(task)))
    except (EOFError, OSError):
        pass
    finally:
        release_problems()


def _outcome_payload(task: EvaluationTask, outcome: Outcome) -> memoryview:
    """The outcome pickled for the pipe, or, where it does not pickle (a metric that refuses),
    the task's failure saying so: the task fails alone and the worker lives on."""
    try:
        return ForkingPickler.dumps(outcome)
    except Exception as error:
        reason = f"the outcome could not be sent back: {type(error).__name__}: {error}"
        failure = Outcome(task.index, None, error=reason, wall_time=outcome.wall_time)
        return ForkingPickler.dumps(failure)


@dataclass
class _Job:
    task: EvaluationTask
    future: Future
    #: the task as pickled for a worker's pipe (Connection.recv unpickles it there)
    payload: memoryview
    attempt: int = 1


class _Worker:
    """One worker process, its pipe, and the job it is running."""

    def __init__(self, context: multiprocessing.context.BaseContext) -> None:
        self.connection, child = context.Pipe()
        try:
            self.process = context.Process(target=_worker_main, args=(child,), daemon=True)
            self.process.start()
        except BaseException:  # no process to own the pipe (too many open files, say)
            self.connection.close()
            raise
        finally:
            child.close()
        self.job: _Job | None = None
        #: when the job's timed evaluation began (None: its problem is still being set up)
        self.started: float | None = None
        #: whether it has ever answered: one found dead before that may not start at all
        self.answered = False

    def start(self, job: _Job) -> None:
        """Send the job's task; the job is this worker's only once sent, so a send that fails
        (OSError: the pipe broke, the process died idle) leaves the worker without it."""
        self.connection.send_bytes(job.payload)
        self.job, self.started = job, None

    def kill(self) -> int | None:
        """Kill the process (if it still runs), wait for it, then close its pipe and the Process
        object (its sentinel's descriptor): a worker is replaced, never reused. Returns its exit
        code, read after the wait: before it, a process that just died may not be reaped."""
        self.process.kill()
        self.process.join()
        code = self.process.exitcode
        self.connection.close()
        self.process.close()
        return code


class ProcessExecutor(Executor):
    """N local worker processes (spawned, so no engine state is inherited by fork)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._context = multiprocessing.get_context("spawn")
        self._lock = threading.Lock()
        self._queue: collections.deque[_Job] = collections.deque()
        #: every future submitted and not yet settled, whether it waits or runs
        self._unsettled: set[Future] = set()
        #: what every task and submit fails with once the manager thread failed (None: serving)
        self._broken: BrokenExecutor | None = None
        self._stopping = False
        self._pool: list[_Worker] = []
        # A failure here (a worker that cannot start, no thread left) stops and closes what
        # had started before it propagates: no process or pipe outlives a pool never built.
        with contextlib.ExitStack() as undo:
            for _ in range(workers):
                worker = _Worker(self._context)
                undo.callback(worker.kill)
                self._pool.append(worker)
            # submit() writes here to wake the manager at once instead of at its next poll.
            self._wake_reader, self._wake_writer = self._context.Pipe(duplex=False)
            undo.callback(self._wake_reader.close)
            undo.callback(self._wake_writer.close)
            self._manager = threading.Thread(target=self._manage, name="metaopt-pool", daemon=True)
            self._manager.start()
            undo.pop_all()

    def submit(self, task: EvaluationTask) -> Future:
        """Queue the task for the next free worker; one that does not pickle fails at once,
        a broken pool (its manager thread failed) raises BrokenExecutor, and a pool shut down
        raises RuntimeError (as concurrent.futures does): its task would never run. Cancelling
        the future does not stop a running task: the pool never marks futures running, so the
        cancel of an unsettled one always succeeds, and its worker's outcome is dropped; a
        caller blocked in wait() or as_completed() on it is woken at once."""
        future: Future = Future()
        try:
            payload = ForkingPickler.dumps(task)
        except Exception as error:  # a lambda or local function, an object that refuses
            payload, refusal = None, error
        with self._lock:  # held by shutdown as it stops: no task is queued after it
            if self._stopping:
                raise RuntimeError("cannot submit after shutdown")
            if payload is None:
                future.set_result(Outcome(task.index, None, error=_unpicklable(refusal)))
                return future
            future.add_done_callback(self._forget)
            if self._broken is not None:
                raise self._broken
            self._unsettled.add(future)
            self._queue.append(_Job(task, future, payload))
        self._wake_writer.send_bytes(b"")
        return future

    def _forget(self, future: Future) -> None:
        """Drop a settled future from those a failure of the manager thread fails; a cancelled
        one's wait()ers are woken at once, not when the manager reaches it."""
        with self._lock:
            self._unsettled.discard(future)
        wake_if_cancelled(future)

    def _manage(self) -> None:
        """The manager thread: serve until shut down. An error of its own (a replacement
        worker that cannot start, a bug), a SystemExit too, breaks the pool rather than end
        the thread silently and leave tasks waiting."""
        try:
            self._serve()
        except BaseException as error:
            self._break(error)

    def _break(self, error: BaseException) -> None:
        """Fail every unsettled task, and every later submit, with BrokenExecutor naming the
        error; the workers are left for shutdown to stop."""
        broken = BrokenExecutor(
            f"the process pool stopped: its manager thread failed with "
            f"{type(error).__name__}: {error}"
        )
        broken.__cause__ = error
        with self._lock:
            self._broken = broken
            unsettled = list(self._unsettled)
        for future in unsettled:
            with contextlib.suppress(InvalidStateError):  # cancelled by its caller meanwhile
                future.set_exception(broken)

    def _serve(self) -> None:
        """Assign queued jobs, collect outcomes, replace dead workers and enforce time limits
        until shutdown."""
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
        """Take the job first in line off the queue, passing over those whose caller cancelled
        them (None when none waits)."""
        with self._lock:
            while self._queue:
                job = self._queue.popleft()
                if not job.future.cancelled():
                    return job
            return None

    def _start(self, worker: _Worker, job: _Job) -> None:
        """Hand the job to an idle worker. One whose pipe is broken is replaced. If it had
        answered before (it died idle: killed from outside, the OOM killer), the job, which it
        never ran, goes back first in line with its attempt unspent; if it never answered, the
        job spends an attempt as under a death, so workers that die as they start end in the
        job's failure, not in workers started for ever."""
        try:
            worker.start(job)
        except OSError:
            if worker.answered:  # it never ran the job: first in line again, attempt unspent
                with self._lock:
                    self._queue.appendleft(job)
            else:  # it may never start: the job is charged with its death
                worker.job = job
            self._replace_dead(worker)

    def _collect(self, worker: _Worker) -> None:
        """Read the worker's message: that its task's evaluation began, or the task's outcome.
        Reading the bytes and unpickling them are apart: a pipe that fails means the worker
        died, while bytes that do not unpickle here (a class the parent cannot import, a load
        that raises) are a bad outcome, failing its task alone; the worker, idle, serves on."""
        try:
            payload = worker.connection.recv_bytes()
        except (EOFError, OSError):
            self._replace_dead(worker)
            return
        worker.answered = True
        try:
            outcome = ForkingPickler.loads(payload)
        except BaseException as error:  # a load's (EOFError, SystemExit too): not the pipe's
            reason = f"the outcome could not be read back: {type(error).__name__}: {error}"
            # its wall time as the parent saw it: from the start of the timed evaluation (a
            # worker always reports that start before the outcome)
            wall = time.monotonic() - worker.started
            outcome = Outcome(worker.job.task.index, None, error=reason, wall_time=wall)
        if outcome == STARTED:
            worker.started = time.monotonic()
            return
        job, worker.job = worker.job, None
        settle(job.future, outcome)
        if outcome.timed_out:  # stopped mid-evaluation, maybe mid-import: start afresh
            self._renew(worker)

    def _renew(self, worker: _Worker) -> int | None:
        """Kill the worker and start a fresh one instead (a worker is never reused): the old
        one's pipe and process are freed first, and it leaves the pool before, so a fresh one
        that cannot start leaves no closed worker there for shutdown. Returns the old one's
        exit code."""
        self._pool.remove(worker)
        code = worker.kill()
        self._pool.append(_Worker(self._context))
        return code

    def _replace_dead(self, worker: _Worker) -> None:
        job = worker.job
        code = self._renew(worker)
        if job is None:
            return
        if job.attempt == 1:
            with self._lock:
                self._queue.appendleft(replace(job, attempt=2))
            return
        reason = f"worker process died twice on this candidate (exit code {code})"
        settle(job.future, Outcome(job.task.index, None, error=reason))

    def _enforce_time_limit(self, worker: _Worker) -> None:
        job = worker.job
        limit = job.task.time_limit if job else None
        if limit is None or worker.started is None or time.monotonic() - worker.started <= limit:
            return
        worker.job = None
        reason = f"EvaluationTimeout: exceeded the time limit of {limit:g} s (worker stopped)"
        settle(job.future, Outcome(job.task.index, None, error=reason, wall_time=limit))
        self._renew(worker)

    def shutdown(self) -> None:
        """Stop the manager and the workers, an idle one told to (it closes its problems), a
        busy one terminated at once (killed if it outlives TERMINATE_GRACE), so shutdown takes
        no longer with more busy workers; close every pipe, so no descriptor outlives the pool.
        Every unsettled task is cancelled: what waits, as concurrent.futures' shutdown with
        cancel_futures does, and what ran too, since its worker is stopped and its outcome will
        never come (its caller gets CancelledError; one blocked in wait() or as_completed() is
        woken). An interrupt mid-way (a second Ctrl-C) still kills every worker and cancels
        every task. A later submit raises RuntimeError; a second call (the run's, then its
        caller's) does nothing."""
        with self._lock:
            if self._stopping:
                return
            self._stopping = True
        try:
            self._wake_writer.send_bytes(b"")
            self._manager.join()
            self._let_workers_end()
        finally:
            with self._lock:
                unsettled = list(self._unsettled)
            for future in unsettled:
                future.cancel()  # it succeeds (never marked running); _forget wakes its waiters
            self._manager.join()  # already ended, or about to: it stops at its next poll
            for worker in self._pool:
                worker.kill()  # only one still running is killed; each pipe and process is closed
            self._wake_reader.close()
            self._wake_writer.close()

    def _let_workers_end(self) -> None:
        """Tell each idle worker to stop (it closes its problems) and terminate each busy one,
        then wait for them together: an idle one up to IDLE_GRACE, a busy one TERMINATE_GRACE."""
        now = time.monotonic()
        for worker in self._pool:
            if worker.job is None:
                with contextlib.suppress(OSError):
                    worker.connection.send(None)
            else:
                worker.process.terminate()
        for worker in self._pool:  # the manager is stopped: each worker's job is fixed now
            grace = IDLE_GRACE if worker.job is None else TERMINATE_GRACE
            worker.process.join(timeout=max(0.0, now + grace - time.monotonic()))


def _unpicklable(error: Exception) -> str:
    """The failure of a task that cannot be sent to a worker process: it does not pickle."""
    return (
        f"the task cannot be sent to a worker process, it does not pickle "
        f"({type(error).__name__}: {error}); a problem's factory and parameters must pickle: "
        "a module-level class or function, or functools.partial of one"
    )
