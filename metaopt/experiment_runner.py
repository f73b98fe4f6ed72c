"""Running an experiment's grid: every cell and seed is run, resumed, or skipped when its run
already finished, so re-running an experiment only does what is left."""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass

from metaopt.errors import ConfigError
from metaopt.executors import EvaluationTask, Executor
from metaopt.experiment import Cell, Experiment
from metaopt.experiment_store import ExperimentStore
from metaopt.plugins import Registry
from metaopt.run_loop import Progress, RunSpec, resume, run
from metaopt.store import RunRecord

#: Given a label, a context manager that yields the progress observer of one run.
WatchRun = Callable[[str], AbstractContextManager[Progress | None]]


@dataclass(frozen=True)
class CellSeed:
    """One seed of one cell, its run in the store and what was done to it this time: 'ran',
    'resumed' or 'skipped' (already finished)."""

    cell: Cell
    seed: int
    run_id: int
    action: str


class _KeptOpen(Executor):
    """An executor lent to one run: the run's shutdown leaves it running for the next run (its
    workers keep the problems they built); its owner shuts it down."""

    def __init__(self, executor: Executor) -> None:
        self.executor = executor
        self.workers = executor.workers

    @property
    def capacity(self) -> int:
        return self.executor.capacity

    def submit(self, task: EvaluationTask) -> Future:
        return self.executor.submit(task)


def run_experiment(
    experiment: Experiment,
    store: ExperimentStore,
    plugins: Registry,
    make_executor: Callable[[], Executor],
    watch: WatchRun,
) -> list[CellSeed]:
    """Run what is left of ``experiment``: new runs for missing seeds, resume for unfinished
    ones, one after another on one executor, made when the first run needs it and shut down
    at the end.

    A stored run whose definition differs from the experiment's (the file was edited under
    the same name) is a ConfigError rather than a silent mix. RunInterrupted propagates.
    """
    problem_info = plugins.problem(experiment.problem)
    cells = experiment.cells()
    total, done = len(cells) * len(experiment.seeds), []
    executor: Executor | None = None
    try:
        for cell in cells:
            optimizer_info = plugins.optimizer(cell.optimizer.name)
            for seed in experiment.seeds:
                record = store.member(experiment.name, cell.key, seed)
                if record is not None:
                    _check_same(record, experiment.spec(cell, seed), experiment.name, cell, seed)
                if record is not None and record.status == "finished":
                    done.append(CellSeed(cell, seed, record.id, "skipped"))
                    continue
                executor = executor or make_executor()
                lent = _KeptOpen(executor)
                with watch(f"[{len(done) + 1}/{total}] {_describe(cell, seed)}") as progress:
                    if record is None:
                        with store.joining(experiment.name, cell.key, seed):
                            spec = experiment.spec(cell, seed)
                            result = run(spec, optimizer_info, problem_info, store, progress, lent)
                        action = "ran"
                    else:
                        result = resume(
                            record.id, store, optimizer_info, problem_info, progress, lent
                        )
                        action = "resumed"
                done.append(CellSeed(cell, seed, result.run_id, action))
    finally:
        if executor is not None:
            executor.shutdown()
    return done


def _describe(cell: Cell, seed: int) -> str:
    setting = f" [{cell.setting}]" if cell.setting else ""
    return f"{cell.optimizer.label}{setting} seed {seed}"


def _check_same(record: RunRecord, spec: RunSpec, experiment: str, cell: Cell, seed: int) -> None:
    """ConfigError when the stored member run was made from a different definition."""
    stored = {
        "optimizer": record.optimizer,
        "budget": record.budget,
        "settings": record.settings,
        **{f"optimizer.{k}": record.optimizer_params.get(k) for k in spec.optimizer_params},
        **{f"problem.{k}": record.problem_params.get(k) for k in spec.problem_params},
    }
    wanted = {
        "optimizer": spec.optimizer,
        "budget": spec.budget,
        "settings": asdict(spec.settings),
        **{f"optimizer.{k}": v for k, v in spec.optimizer_params.items()},
        **{f"problem.{k}": v for k, v in spec.problem_params.items()},
    }
    changed = [f"{k} {stored[k]!r} -> {wanted[k]!r}" for k in wanted if stored[k] != wanted[k]]
    if changed:
        raise ConfigError(
            f"experiment {experiment!r}: {_describe(cell, seed)} is stored as run {record.id} "
            f"with other settings ({'; '.join(changed)}); give the experiment a new name or "
            "use another --db"
        )
