"""Evaluations on a Dask distributed cluster: an existing one (--scheduler ADDRESS) or a
LocalCluster of worker processes started here.

A task whose worker vanished is handed to Dask once more (on a LocalCluster started here Dask
itself does not retry, ``allowed-failures`` 0), then stored as failed. At most a few tasks
per live worker thread are handed to Dask at a time (the rest wait here), so a worker that
dies takes down little besides the task it was running, and that is retried. A time limit
on Dask abandons the
evaluation (its result is ignored); the worker finishes it anyway. Shutdown cancels every
unsettled task, waiting here or handed to Dask, and a later submit raises RuntimeError.
"""

from __future__ import annotations

import collections
import importlib.util
import math
import threading
import time
from concurrent.futures import Future
from typing import TYPE_CHECKING

from metaopt.errors import ConfigError
from metaopt.executors.base import (
    EvaluationTask,
    Executor,
    Outcome,
    evaluate_task,
    settle,
    wake_if_cancelled,
)

if TYPE_CHECKING:
    import distributed

#: Tasks handed to Dask per worker thread: a Dask round trip takes milliseconds, so a few wait
#: ready on each worker and none idles between tasks.
PREFETCH = 4
#: Seconds after a lost worker during which hand-overs wait for live worker threads.
LOSS_WINDOW = 30.0


class DaskExecutor(Executor):
    """Submit each evaluation as a Dask task; results come back as concurrent Futures."""

    def __init__(self, workers: int, address: str | None) -> None:
        import dask
        from distributed import Client, LocalCluster

        self._cluster = None
        try:
            if address is None:
                with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
                    self._cluster = LocalCluster(
                        n_workers=workers,
                        threads_per_worker=1,
                        processes=True,
                        # None does not turn the dashboard off (dask/distributed#8136):
                        # a free loopback port, so two local runs never contend for 8787
                        dashboard_address="127.0.0.1:0",
                        host="127.0.0.1",
                    )
                self._client = Client(self._cluster)
                self.dashboard = self._cluster.dashboard_link
                if importlib.util.find_spec("bokeh") is None:  # Dask draws its pages with it
                    self.dashboard_needs = "bokeh>=3.1"
            else:
                self._client = Client(address, timeout=10)
        except (OSError, TimeoutError) as error:
            if self._cluster is not None:
                self._cluster.close()
            raise ConfigError(
                f"cannot reach the Dask scheduler at {address}: {error}; start one with "
                "`dask scheduler` and workers with `dask worker ADDRESS`"
            ) from None
        self.workers = max(1, sum(self._client.nthreads().values())) if address else workers
        #: each running task's time-limit timer by its Dask key, cancelled when the task settles
        self._timers: dict[str, threading.Timer] = {}
        self._changed = threading.Condition()
        self._waiting: collections.deque[tuple[EvaluationTask, Future, int]] = collections.deque()
        #: every future submitted and not yet settled, waiting here or handed to Dask
        self._unsettled: set[Future] = set()
        self._running = 0
        self._last_loss = -math.inf
        self._closing = False
        # Dask's callbacks run on its event loop, where submitting would deadlock: a thread
        # of our own hands tasks over instead.
        self._dispatcher = threading.Thread(target=self._hand_over, daemon=True)
        self._dispatcher.start()

    @property
    def capacity(self) -> int:
        return PREFETCH * self.workers

    def submit(self, task: EvaluationTask) -> Future:
        """Queue the task for the dispatcher to hand to Dask; an executor shut down raises
        RuntimeError (as concurrent.futures does): no dispatcher would hand its task over."""
        result: Future = Future()
        with self._changed:  # held by shutdown as it stops: no task is queued after it
            if self._closing:
                raise RuntimeError("cannot submit after shutdown")
            self._unsettled.add(result)
            result.add_done_callback(self._forget)
            self._waiting.append((task, result, 1))
            self._changed.notify()
        return result

    def _forget(self, result: Future) -> None:
        """Drop a settled future from those shutdown cancels; a cancelled one's wait()ers are
        woken."""
        with self._changed:
            self._unsettled.discard(result)
        wake_if_cancelled(result)

    def _hand_over(self) -> None:
        """Give Dask waiting tasks while fewer than PREFETCH per worker are there (running or
        queued on a worker), so each worker has its next task at hand; one its caller
        cancelled is passed over."""
        while True:
            with self._changed:
                while not self._closing and (
                    self._running >= PREFETCH * self.workers or not self._waiting
                ):
                    self._changed.wait()
                if self._closing:
                    return
                if self._recent_loss() and self._running >= self._live_threads():
                    self._changed.wait(0.05)  # a worker is being replaced: wait for it
                    continue
                task, result, attempt = self._waiting.popleft()
                if result.cancelled():
                    continue
                self._running += 1
            self._start(task, result, attempt)

    def _recent_loss(self) -> bool:
        """A worker was lost lately, so the cluster may be smaller until it is replaced."""
        return time.monotonic() - self._last_loss < LOSS_WINDOW

    def _live_threads(self) -> int:
        try:
            return sum(self._client.nthreads().values())
        except (OSError, TimeoutError):
            return 0

    def _start(self, task: EvaluationTask, result: Future, attempt: int) -> None:
        """Hand one task to Dask, with a timer for its time limit that lives only until the
        task settles (fast evaluations leave no sleeping timer threads behind)."""
        # A screened candidate's index is evaluated twice (screen, then complete): the phase
        # keeps the keys apart, since the cluster hands back a finished key's result.
        key = f"metaopt-{task.phase}-{task.index}-{task.seed}-{attempt}"
        dask_future = self._client.submit(evaluate_task, task, key=key, pure=False)
        if task.time_limit is not None:  # before on_done can run, so that it finds the timer
            timer = threading.Timer(
                task.time_limit, self._abandon, (key, task, result, dask_future)
            )
            timer.daemon = True
            with self._changed:
                self._timers[key] = timer
            timer.start()

        def on_done(done) -> None:
            self._stop_timer(key)  # this attempt is over: its time limit no longer applies
            try:
                outcome = done.result()
            except Exception as error:  # KilledWorker, CancelledError, lost connection
                if attempt == 1 and not result.done():
                    with self._changed:  # once more, on whichever worker is free
                        self._last_loss = time.monotonic()
                        self._running -= 1
                        self._waiting.appendleft((task, result, 2))
                        self._changed.notify()
                    return
                reason = f"Dask task failed twice: {type(error).__name__}: {error}"
                outcome = Outcome(task.index, None, error=reason)
            with self._changed:
                self._running -= 1
                self._changed.notify()
            settle(result, outcome)

        dask_future.add_done_callback(on_done)

    def _stop_timer(self, key: str) -> None:
        """Cancel and forget the time-limit timer of the task with this Dask key, if any."""
        with self._changed:
            timer = self._timers.pop(key, None)
        if timer is not None:
            timer.cancel()

    def _abandon(
        self, key: str, task: EvaluationTask, result: Future, dask_future: distributed.Future
    ) -> None:
        """The task ran past its time limit: fail it now and forget its (fired) timer; the
        worker finishes the evaluation, whose result is ignored."""
        with self._changed:
            self._timers.pop(key, None)
        if not result.done():
            reason = f"EvaluationTimeout: exceeded the time limit of {task.time_limit:g} s"
            settle(result, Outcome(task.index, None, error=reason, wall_time=task.time_limit))
            dask_future.cancel()

    def shutdown(self) -> None:
        """Stop handing tasks over, cancel the time-limit timers and every unsettled task,
        what waits here and what Dask has (the client's close abandons it: its result will
        never come), so its caller gets CancelledError, and one blocked in wait() or
        as_completed() is woken; close the client and the cluster started here. A later
        submit raises RuntimeError; a second call (the run's, then its caller's) does
        nothing. An interrupt mid-way (a second Ctrl-C) still cancels every task and closes
        the client and the cluster."""
        with self._changed:
            if self._closing:
                return
            self._closing = True
            self._changed.notify()
        try:
            self._dispatcher.join()
        finally:
            with self._changed:
                timers, self._timers = list(self._timers.values()), {}
                unsettled = list(self._unsettled)
                self._waiting.clear()
            for timer in timers:
                timer.cancel()
            for result in unsettled:
                result.cancel()  # it succeeds (never marked running); _forget wakes its waiters
            try:
                self._client.close()
            finally:
                if self._cluster is not None:
                    self._cluster.close()
