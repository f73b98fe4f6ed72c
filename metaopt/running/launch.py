"""Starting a run (checked before anything is stored), checking one without starting it, and
resuming a stored one from its last checkpoint."""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from metaopt.errors import ConfigError, SettingWarning
from metaopt.executors.base import Executor, SerialExecutor, adopt_problem
from metaopt.optimizer import Optimizer, OptimizerInfo
from metaopt.params import resolve
from metaopt.problem import Problem, ProblemInfo, Sense
from metaopt.running.session import Session
from metaopt.running.spec import MAX_TIME_STOP, Progress, RunResult, RunSettings, RunSpec
from metaopt.space import Space
from metaopt.storage.run_store import RunRecord, RunStore
from metaopt.versions import environment_versions
from metaopt.warm_start import check_start


def run(
    spec: RunSpec,
    optimizer_info: OptimizerInfo,
    problem_info: ProblemInfo,
    store: RunStore | str | Path,
    progress: Progress | None = None,
    executor: Executor | None = None,
) -> RunResult:
    """Run spec.optimizer on spec.problem for spec.budget evaluations, storing each one in
    ``store`` (a RunStore, or the path of one, opened only once every check has passed, so
    that refused settings leave no new file behind).

    Parameters are validated against the plugins' declarations first (ConfigError on bad input).
    Ctrl-C or SIGTERM marks the run 'interrupted' and raises RunInterrupted.
    """
    prepared = _prepared(spec, optimizer_info, problem_info)
    try:
        with _opened(store) as opened:
            _warn(prepared.warnings)  # once the store opened: a refused run only says why
            return _stored_run(prepared, optimizer_info, problem_info, opened, progress, executor)
    finally:
        prepared.problem.close()


@contextmanager
def _opened(store: RunStore | str | Path) -> Iterator[RunStore]:
    """``store`` itself (its owner closes it), or the store at that path, closed after."""
    if isinstance(store, RunStore):
        yield store
        return
    with RunStore(store) as opened:
        yield opened


def _stored_run(
    prepared: _Prepared,
    optimizer_info: OptimizerInfo,
    problem_info: ProblemInfo,
    store: RunStore,
    progress: Progress | None,
    executor: Executor | None,
) -> RunResult:
    """The prepared run, created in the store and executed."""
    spec, problem = prepared.spec, prepared.problem
    run_id = store.create_run(
        optimizer=optimizer_info.name,
        optimizer_params=prepared.optimizer_params,
        problem=problem_info.name,
        problem_params=prepared.problem_params,
        seed=spec.seed,
        budget=spec.budget,
        sense=Sense(problem.sense).value,
        space=problem.space.to_json(),
        settings=asdict(spec.settings),
        versions=environment_versions(),
    )
    store.claim(run_id)
    session = Session(
        run_id, spec, prepared.optimizer, problem, problem_info, store,
        prepared.problem_params,
    )  # fmt: skip
    with adopt_problem(problem_info.factory, prepared.problem_params, problem):
        return session.execute(executor or SerialExecutor(), progress)


def check_run(spec: RunSpec, optimizer_info: OptimizerInfo, problem_info: ProblemInfo) -> None:
    """Make every check run() makes before it stores anything (settings, the problem and the
    optimizer built from them, the warm start, the mode), and nothing else: ConfigError on the
    first bad one, so that a long script can refuse a later run's settings before it starts."""
    prepared = _prepared(spec, optimizer_info, problem_info)
    prepared.problem.close()
    _warn(prepared.warnings)


@dataclass(frozen=True)
class _Prepared:
    """What a run builds before it stores anything."""

    spec: RunSpec  # with its start points fixed
    problem: Problem  # open: the caller closes it
    optimizer: Optimizer
    optimizer_params: dict[str, Any]
    problem_params: dict[str, Any]
    warnings: tuple[str, ...]  # settings that pass but are hardly what was meant


def _warn(notes: tuple[str, ...]) -> None:
    """Each of a prepared run's warnings, as a SettingWarning from the caller of run()."""
    for note in notes:
        warnings.warn(note, SettingWarning, stacklevel=3)


def _prepared(spec: RunSpec, optimizer_info: OptimizerInfo, problem_info: ProblemInfo) -> _Prepared:
    """The spec checked, and the problem and optimizer built from it (ConfigError on bad input;
    the problem is closed when a later check fails), with the warnings the settings deserve,
    to be given only once nothing refuses the run."""
    spec.settings.check(spec.budget)
    optimizer_params = _optimizer_params(spec, optimizer_info)
    problem_params = resolve(problem_info.params, spec.problem_params, problem_info.name)
    problem = problem_info.factory(**problem_params)
    try:
        optimizer = optimizer_info.factory(problem.space, spec.seed, **optimizer_params)
        notes = []
        unfit = optimizer.budget_warning(spec.budget // spec.settings.resample)
        if unfit is not None:
            notes.append(f"{optimizer_info.name}: {unfit}")
        if spec.settings.common_seeds == "batch" and spec.settings.batch_size(optimizer) == 1:
            notes.append(
                f"{optimizer_info.name} asks one candidate per batch: with common seeds per "
                "batch every candidate still meets seeds of its own; give --batch N for N "
                "candidates to share them, or use --common-seeds run"
            )
        spec = _with_start_points(spec, problem.space, optimizer)
        if spec.settings.screen:
            _check_screening(spec, optimizer_info.name, optimizer, problem_info.name, problem)
        if spec.settings.mode == "async" and not optimizer.steady_state:
            raise ConfigError(
                f"optimizer {optimizer_info.name!r} is generational, not steady-state: it "
                "cannot run in async mode; use --mode sync (e.g. with --workers N)"
            )
    except BaseException:
        problem.close()
        raise
    return _Prepared(spec, problem, optimizer, optimizer_params, problem_params, tuple(notes))


def _optimizer_params(spec: RunSpec, optimizer_info: OptimizerInfo) -> dict[str, Any]:
    """The spec's optimizer parameters resolved as the run stores them: a ``budget`` parameter
    defaults to the candidates the run will tell (schedules such as IHS span them)."""
    given = dict(spec.optimizer_params)
    if any(p.name == "budget" for p in optimizer_info.params):
        given.setdefault("budget", spec.budget // spec.settings.resample)
    return resolve(optimizer_info.params, given, optimizer_info.name)


def stored_settings(spec: RunSpec, optimizer_info: OptimizerInfo, space: Space) -> RunSettings:
    """The settings run() stores for ``spec`` on ``space`` (its warm start's start points fixed
    as _with_start_points fixes them), so that a stored run can be told from another spec's."""
    if spec.settings.start is None or spec.settings.start_points:
        return spec.settings  # nothing for the run to fix: no optimizer built
    optimizer = optimizer_info.factory(space, spec.seed, **_optimizer_params(spec, optimizer_info))
    return _with_start_points(spec, space, optimizer).settings


def _check_screening(
    spec: RunSpec, optimizer_name: str, optimizer: Optimizer, problem_name: str, problem: Problem
) -> None:
    """ConfigError unless the problem has a screen and the optimizer ranks whole batches."""
    if not problem.screens:
        raise ConfigError(
            f"problem {problem_name!r} with these settings has no cheaper bound to screen "
            "with (its docs say which settings give one); run without --screen"
        )
    if optimizer.selected is None:
        raise ConfigError(
            f"optimizer {optimizer_name!r} reads every candidate's fitness, so none can be "
            "left screened; screening needs one whose update reads only its best ranks, "
            "such as cmaes"
        )
    if spec.settings.batch not in (0, optimizer.batch_size):
        raise ConfigError(
            f"--screen ranks the optimizer's own batch ({optimizer.batch_size} for "
            f"{optimizer_name}); leave --batch out or give {optimizer.batch_size}"
        )


def _with_start_points(spec: RunSpec, space: Space, optimizer: Optimizer) -> RunSpec:
    """The spec with its warm start checked against the space and its number of start points
    fixed (the optimizer's initial population when 0), so that a resume draws the same ones."""
    settings = spec.settings
    if settings.start is None:
        return spec
    for point in settings.start:
        check_start(space, point)
    count = settings.start_points or optimizer.initial_population
    if count < len(settings.start):
        given = "asked for" if settings.start_points else "the optimizer's initial population"
        raise ConfigError(
            f"{len(settings.start)} points to start from but {count} start points ({given}); "
            "start from fewer points or ask for at least as many start points"
        )
    return replace(spec, settings=replace(settings, start_points=count))


def check_resume(run_id: int | str, store: RunStore, budget: int | None = None) -> RunRecord:
    """The stored run resume() would continue, or the ConfigError it would refuse it with (a
    finished run without a larger budget, a budget not above the evaluations made): checked
    before any worker starts."""
    record = store.run(run_id)
    if budget is not None:
        made = store.evaluation_counts(record.id).stored
        if budget <= made:
            raise ConfigError(
                f"budget must be more than the {made} evaluations run {record.id} has made "
                f"(evaluations in all, not more), got {budget}"
            )
    stopped_early = (record.message or "").startswith(MAX_TIME_STOP)
    if record.status == "finished" and not stopped_early and budget is None:
        raise ConfigError(
            f"run {record.id} already finished; nothing to resume (a larger budget continues "
            "a run that spent its budget)"
        )
    return record


def resume(
    run_id: int | str,
    store: RunStore,
    optimizer_info: OptimizerInfo,
    problem_info: ProblemInfo,
    progress: Progress | None = None,
    executor: Executor | None = None,
    max_time: float | None = None,
    budget: int | None = None,
) -> RunResult:
    """Continue a stored run that did not finish, that stopped at its max time with budget
    left, or (given a larger ``budget``) that spent its budget, from its last checkpoint;
    ``max_time`` and ``budget`` replace the stored ones (stored with the run). ``budget`` need
    only exceed the evaluations made, so a run stopped early can be given N more: its count
    plus N, below its stored budget too.

    In sync mode evaluations stored after the checkpoint are reused, not recomputed, so the
    resumed run ends exactly where an uninterrupted one would (one given the time or budget at
    once), but for an optimizer whose schedule spans its budget (its ``budget`` parameter stays
    the one it started with: past it the schedule stays at its end).
    """
    record = check_resume(run_id, store, budget)
    if max_time is not None:
        record.settings = {**record.settings, "max_time": max_time}
    if budget is not None:
        record.budget = budget
    RunSettings(**record.settings).check(record.budget)
    # A parameter a plugin declared after the run was stored takes its default, as a replay's do.
    optimizer_params = resolve(optimizer_info.params, record.optimizer_params, optimizer_info.name)
    problem_params = resolve(problem_info.params, record.problem_params, problem_info.name)
    spec = RunSpec(
        optimizer=record.optimizer,
        problem=record.problem,
        budget=record.budget,
        seed=record.seed,
        optimizer_params=optimizer_params,
        problem_params=problem_params,
        settings=RunSettings(**record.settings),
    )
    problem = problem_info.factory(**problem_params)
    try:
        optimizer = optimizer_info.factory(problem.space, record.seed, **optimizer_params)
        checkpoint = record.checkpoint or {"state": None, "told_below": 0, "told_extra": []}
        if checkpoint["state"] is not None:
            optimizer.load_state_dict(checkpoint["state"])
        store.claim(record.id)  # refused while another live process runs it
        store.mark_running(record.id, record.settings, record.budget)
        session = Session(record.id, spec, optimizer, problem, problem_info, store, problem_params)
        session.restore(record, checkpoint)
        with adopt_problem(problem_info.factory, problem_params, problem):
            return session.execute(executor or SerialExecutor(), progress)
    finally:
        problem.close()
