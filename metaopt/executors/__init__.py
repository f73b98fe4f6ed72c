"""Where evaluations run: the Executor interface and the serial executor (base), local worker
processes that survive their workers (process_pool), and a Dask distributed cluster
(dask_cluster). The run loop knows only the interface; executor plugins announce the rest.

An executor plugin needs only the names imported here: ``from metaopt.executors import
Executor, ExecutorInfo``."""

from metaopt.executors.base import (
    EvaluationTask,
    EvaluationTimeout,
    Executor,
    ExecutorInfo,
    Outcome,
    SerialExecutor,
)

__all__ = [
    "EvaluationTask",
    "EvaluationTimeout",
    "Executor",
    "ExecutorInfo",
    "Outcome",
    "SerialExecutor",
]
