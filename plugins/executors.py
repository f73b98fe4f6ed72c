"""The built-in executors: serial (default), local processes, and Dask distributed."""

from __future__ import annotations

from metaopt import hookimpl
from metaopt.executors.base import Executor, ExecutorInfo, SerialExecutor


def _serial(workers: int, address: str | None) -> Executor:
    return SerialExecutor()


def _processes(workers: int, address: str | None) -> Executor:
    from metaopt.executors.process_pool import ProcessExecutor

    return ProcessExecutor(workers)


def _dask(workers: int, address: str | None) -> Executor:
    from metaopt.executors.dask_cluster import DaskExecutor

    return DaskExecutor(workers, address)


@hookimpl
def metaopt_executors() -> list[ExecutorInfo]:
    """Announce serial, process and dask."""
    return [
        ExecutorInfo("serial", "one evaluation at a time in this process (default)", _serial),
        ExecutorInfo("process", "N local worker processes (--workers N)", _processes),
        ExecutorInfo(
            "dask",
            "Dask distributed: a LocalCluster of N workers, or --scheduler tcp://HOST:PORT",
            _dask,
        ),
    ]
