"""Running an experiment's grid: every cell and seed is run, resumed, or skipped when its run
already finished, so re-running an experiment only does what is left."""

from __future__ import annotations

import contextlib
import multiprocessing
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass
from multiprocessing.synchronize import Event as EventType

from metaopt.comparison.experiment import Cell, Experiment
from metaopt.errors import ConfigError
from metaopt.executors.base import EvaluationTask, Executor
from metaopt.optimizer import OptimizerInfo
from metaopt.plugins import Registry, registry
from metaopt.running import Progress, RunSpec, resume, run, stop_on_sigterm
from metaopt.running.launch import stored_settings
from metaopt.space import Space
from metaopt.storage.experiment_store import ExperimentStore
from metaopt.storage.run_store import RunRecord

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
    members = [(cell, seed) for cell in experiment.cells() for seed in experiment.seeds]
    done: list[CellSeed] = []
    executor: Executor | None = None
    try:
        for cell, seed in members:
            finished = _finished_member(experiment, store, plugins, cell, seed)
            if finished is not None:
                done.append(finished)
                continue
            executor = executor or make_executor()
            label = f"[{len(done) + 1}/{len(members)}] {_describe(cell, seed)}"
            with watch(label) as progress:
                done.append(
                    _run_member(
                        experiment, store, plugins, cell, seed, _KeptOpen(executor), progress
                    )
                )
    finally:
        if executor is not None:
            executor.shutdown()
    return done


def run_experiment_in_parallel(
    experiment: Experiment,
    store: ExperimentStore,
    jobs: int,
    finished: Callable[[CellSeed, int, int], None],
) -> list[CellSeed]:
    """Run what is left of ``experiment`` with ``jobs`` runs at a time, each in a process of its
    own and serial inside, so that every run depends only on its seed and ends exactly as when
    the runs go one after another. ``finished(member, done, total)`` is told of each member as it
    ends (skipped ones first).

    Checks as run_experiment does before anything starts. Ctrl-C stops every run (each stores
    what finished and is marked interrupted, to be resumed by the next compare) and raises
    KeyboardInterrupt.
    """
    members = [(cell, seed) for cell in experiment.cells() for seed in experiment.seeds]
    done: list[CellSeed] = []
    plugins = registry()
    # This process keeps the one connection it has: a second one opened and closed here would
    # drop its POSIX locks on the file while the workers write (SQLite's known hazard).
    for cell, seed in members:
        skipped = _finished_member(experiment, store, plugins, cell, seed)
        if skipped is not None:
            done.append(skipped)
            finished(skipped, len(done), len(members))
    skipped_keys = {(d.cell.key, d.seed) for d in done}
    left = [(c, s) for c, s in members if (c.key, s) not in skipped_keys]
    if not left:
        return done
    context = multiprocessing.get_context("spawn")  # no engine or SQLite state forked along
    stop = context.Event()
    workers = min(jobs, len(left))
    with ProcessPoolExecutor(workers, context, _keep_stop_event, (stop,)) as pool:
        futures = [
            pool.submit(_run_member_in_process, experiment, str(store.path), cell, seed)
            for cell, seed in left
        ]
        try:
            with stop_on_sigterm():  # stopped like Ctrl-C, not left with its workers running
                for future in as_completed(futures):
                    done.append(future.result())
                    finished(done[-1], len(done), len(members))
        except BaseException:
            stop.set()
            _stop_runs(pool, futures)
            raise
    return done


def _stop_runs(pool: ProcessPoolExecutor, futures: list[Future]) -> None:
    """Stop the runs under way as Ctrl-C stops one: each stores what it finished and marks
    itself interrupted (metaopt.running); the runs not started are cancelled."""
    for future in futures:
        future.cancel()
    # no public API lists a pool's worker processes; SIGTERM, not SIGINT, which a process
    # started in the background ignores (and its spawned workers with it)
    for process in list(pool._processes.values()):
        if process.is_alive():
            process.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


#: In a --jobs worker process: set when the comparison is being stopped.
_stop_event: EventType | None = None


def _keep_stop_event(stop: EventType) -> None:
    """A --jobs worker's initializer: keep the event that says the comparison stops."""
    global _stop_event
    _stop_event = stop


def _run_member_in_process(experiment: Experiment, db_path: str, cell: Cell, seed: int) -> CellSeed:
    """One member, run (or resumed) serially in this worker process with its own store; none
    once the comparison is stopping (a member already queued to this worker)."""
    if _stop_event is not None and _stop_event.is_set():
        raise KeyboardInterrupt(f"{_describe(cell, seed)}: not started, the comparison stopped")
    with ExperimentStore(db_path) as store:
        return _run_member(experiment, store, registry(), cell, seed, None, None)


def _finished_member(
    experiment: Experiment, store: ExperimentStore, plugins: Registry, cell: Cell, seed: int
) -> CellSeed | None:
    """The member as 'skipped' when its run finished; None when it is still to run. A stored
    run made from another definition is a ConfigError."""
    record = store.member(experiment.name, cell.key, seed)
    if record is None:
        return None
    optimizer_info = plugins.optimizer(cell.optimizer.name)
    _check_same(record, experiment.spec(cell, seed), optimizer_info, experiment.name, cell, seed)
    return CellSeed(cell, seed, record.id, "skipped") if record.status == "finished" else None


def _run_member(
    experiment: Experiment,
    store: ExperimentStore,
    plugins: Registry,
    cell: Cell,
    seed: int,
    executor: Executor | None,
    progress: Progress | None,
) -> CellSeed:
    """Run the member, or resume its unfinished run."""
    optimizer_info = plugins.optimizer(cell.optimizer.name)
    problem_info = plugins.problem(experiment.problem)
    record = store.member(experiment.name, cell.key, seed)
    if record is None:
        with store.joining(experiment.name, cell.key, seed):
            spec = experiment.spec(cell, seed)
            result = run(spec, optimizer_info, problem_info, store, progress, executor)
        return CellSeed(cell, seed, result.run_id, "ran")
    result = resume(record.id, store, optimizer_info, problem_info, progress, executor)
    return CellSeed(cell, seed, result.run_id, "resumed")


def _describe(cell: Cell, seed: int) -> str:
    setting = f" [{cell.setting}]" if cell.setting else ""
    return f"{cell.optimizer.label}{setting} seed {seed}"


def _check_same(
    record: RunRecord,
    spec: RunSpec,
    optimizer_info: OptimizerInfo,
    experiment: str,
    cell: Cell,
    seed: int,
) -> None:
    """ConfigError when the stored member run was made from a different definition; the spec's
    settings are compared as its run stores them (a warm start's start points fixed)."""
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
        "settings": _settings_as_stored(record, spec, optimizer_info),
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


def _settings_as_stored(
    record: RunRecord, spec: RunSpec, optimizer_info: OptimizerInfo
) -> dict[str, object]:
    """The spec's settings as run() would have stored them on the stored run's space (a warm
    start's start_points 0 is the optimizer's initial population), to compare like with like."""
    settings = asdict(spec.settings)
    if settings == record.settings:
        return settings
    # Another space or optimizer refused: the definitions differ, which the caller reports.
    with contextlib.suppress(ConfigError):
        settings = asdict(stored_settings(spec, optimizer_info, Space.from_json(record.space)))
    return settings
