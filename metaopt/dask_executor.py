"""Evaluations on a Dask distributed cluster: an existing one (--scheduler ADDRESS) or a
LocalCluster of worker processes started here.

Dask re-runs a task whose worker vanished; metaopt allows that once (the scheduler's
``allowed-failures``, for clusters it starts) and stores the task as failed after that. A time
limit on Dask abandons the evaluation (its result is ignored); the worker finishes it anyway.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future

from metaopt.errors import ConfigError
from metaopt.executors import EvaluationTask, Executor, Outcome, evaluate_task


class DaskExecutor(Executor):
    """Submit each evaluation as a Dask task; results come back as concurrent Futures."""

    def __init__(self, workers: int, address: str | None) -> None:
        import dask
        from distributed import Client, LocalCluster

        self._cluster = None
        try:
            if address is None:
                with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
                    self._cluster = LocalCluster(
                        n_workers=workers,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=None,
                        host="127.0.0.1",
                    )
                self._client = Client(self._cluster)
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
        self._timers: list[threading.Timer] = []

    def submit(self, task: EvaluationTask) -> Future:
        result: Future = Future()
        key = f"metaopt-eval-{task.index}-{task.seed}"
        dask_future = self._client.submit(evaluate_task, task, key=key, pure=False)

        def settle(done) -> None:
            if result.done():
                return
            try:
                result.set_result(done.result())
            except Exception as error:  # KilledWorker, CancelledError, lost connection
                reason = f"Dask task failed: {type(error).__name__}: {error}"
                result.set_result(Outcome(task.index, None, error=reason))

        dask_future.add_done_callback(settle)
        if task.time_limit is not None:
            timer = threading.Timer(task.time_limit, self._abandon, (task, result, dask_future))
            timer.daemon = True
            timer.start()
            self._timers.append(timer)
        return result

    @staticmethod
    def _abandon(task: EvaluationTask, result: Future, dask_future) -> None:
        if not result.done():
            reason = f"EvaluationTimeout: exceeded the time limit of {task.time_limit:g} s"
            result.set_result(Outcome(task.index, None, error=reason, wall_time=task.time_limit))
            dask_future.cancel()

    def shutdown(self) -> None:
        for timer in self._timers:
            timer.cancel()
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()
