"""The ``metaopt`` command line: list, run, resume, runs, show, history, export, replay, compare,
report, new."""

from __future__ import annotations

import secrets
import shlex
import sys
import warnings
from concurrent.futures import BrokenExecutor
from pathlib import Path
from typing import Any

import click
from rich.text import Text

from metaopt.assessment.candidates import find_start
from metaopt.assessment.replay import find_source, replay_candidate, replay_seeds
from metaopt.cli.common import (
    BUDGET,
    build_executor,
    check_executor_options,
    check_store_path,
    console,
    db_option,
    errors,
    require_store,
    scheduling_options,
)
from metaopt.cli.compare import compare
from metaopt.cli.new import new
from metaopt.cli.output import format_option, output_file_option, print_records
from metaopt.cli.report import report, write_replay_video
from metaopt.cli.robustness import (
    robustness_command,
    robustness_rank_command,
    robustness_summary_command,
)
from metaopt.errors import ConfigError, MetaoptError, SettingWarning
from metaopt.optimizer import MAX_POPULATION
from metaopt.plugins import registry
from metaopt.problem import ProblemInfo
from metaopt.reporting import display
from metaopt.reporting.convergence import require_evaluations
from metaopt.reporting.history import run_history
from metaopt.reporting.plain import plain
from metaopt.reporting.recent import DEFAULT_WINDOW, recent_figures
from metaopt.resampling import AGGREGATES
from metaopt.running import (
    COMMON_SEEDS,
    MODES,
    RunInterrupted,
    RunResult,
    RunSettings,
    RunSpec,
    check_resume,
    check_run,
    resume,
    run,
)
from metaopt.settings import parse_problem_settings, split_settings
from metaopt.space import Space
from metaopt.storage.experiment_store import experiment_names
from metaopt.storage.export import FORMATS, export_run
from metaopt.storage.limits import MAX_STORED_INT
from metaopt.storage.run_store import RunStore
from metaopt.storage.whole_file import written_whole

#: what `run --max-time` and `resume --max-time` accept: seconds of wall time, above 0
MAX_TIME = {"type": click.FloatRange(min=0, min_open=True, max=1e9), "default": None,
            "metavar": "SECONDS"}  # fmt: skip

#: click 8.2+ raises this for a group called with no arguments (older versions exit at once).
_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


class MetaoptGroup(click.Group):
    """Every error the user can cause is one 'Error: ...' line on stderr: a MetaoptError
    (exit 2, or its own exit_code) and click's usage errors (exit 2, without the usage dump);
    a SettingWarning is one 'Warning: ...' line."""

    def main(self, *args: Any, standalone_mode: bool = True, **kwargs: Any) -> Any:
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            code = super().main(*args, standalone_mode=False, **kwargs)
        except _NO_ARGS_IS_HELP as error:  # `metaopt` alone: the help, as click shows it
            error.show()
            sys.exit(error.exit_code)
        except click.ClickException as error:
            hint = ""
            if isinstance(error, click.UsageError) and error.ctx is not None:
                hint = f" (see '{error.ctx.command_path} --help')"
            _error_line(f"{error.format_message()}{hint}")
            sys.exit(error.exit_code)
        except click.exceptions.Abort:
            errors.print("Aborted!")
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            with warnings.catch_warnings():
                warnings.showwarning = _warning_line
                return super().invoke(ctx)
        except MetaoptError as error:
            _error_line(str(error))
            sys.exit(getattr(error, "exit_code", 2))
        except BrokenExecutor as error:  # a fault of the workers, not of the input: exit 1
            _error_line(str(error))
            sys.exit(1)


def _error_line(message: str) -> None:
    """'Error: message' on one line, the message as it is (never read as rich markup)."""
    text = " ".join(message.splitlines())
    errors.print(Text.assemble(("Error:", "bold red"), " ", text))


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    """SettingWarnings as one line; anything else as Python shows it."""
    if issubclass(category, SettingWarning):
        errors.print(Text.assemble(("Warning:", "yellow"), " ", str(message)))
    else:
        errors.print(plain(warnings.formatwarning(message, category, filename, lineno, line)),
                     end="")  # fmt: skip


@click.group(cls=MetaoptGroup)
@click.version_option(package_name="metaopt")
def main() -> None:
    """metaopt: metaheuristic optimization with plugins."""


@main.command("list")
@click.argument("name", required=False)
def list_plugins(name: str | None) -> None:
    """Show the installed optimizers, problems and physics engines (or one plugin in full)."""
    plugins = registry()
    if name is None:
        for title, kind, table in (
            ("optimizers", "optimizer", plugins.optimizers),
            ("problems", "problem", plugins.problems),
            ("physics backends", "physics backend", plugins.physics_backends),
        ):
            sources = [plugins.source(kind, name) for name in table]
            console.print(display.plugin_overview(title, list(table.values()), sources))
        console.print("[dim]metaopt list NAME shows one in full with every parameter.[/]")
        return
    kind, info = plugins.any_kind(name)  # raises with close matches of every kind
    console.print(Text.assemble((info.name, "bold cyan"), f" ({kind}): {info.summary}"))
    if kind not in ("optimizer", "problem"):
        if getattr(info, "unavailable", None):
            console.print(plain(f"unavailable: {info.unavailable}"))
        return
    if info.description:
        console.print(plain(display.reflow(info.description)))
    if kind == "problem":
        console.print(f"default budget: {info.default_budget} evaluations")
    console.print(display.params_table("parameters", info.params))


@main.command("run")
@click.option("--optimizer", "-o", "optimizer_name", required=True, help="Optimizer name.")
@click.option("--problem", "-p", "problem_name", required=True, help="Problem name.")
@click.option(
    "--budget",
    type=BUDGET,
    default=None,
    help="Evaluations [problem's default].",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0, max=MAX_STORED_INT),
    default=None,
    help="Run seed [random, printed].",
)
@click.option(
    "--set",
    "settings",
    multiple=True,
    metavar="NAME=VALUE",
    help="A plugin parameter; qualify as optimizer.NAME or problem.NAME when both have it.",
)
@click.option(
    "--mode",
    type=click.Choice(MODES),
    default="sync",
    show_default=True,
    help="sync: reproducible batches; async: keep every worker busy (steady-state).",
)
@click.option(
    "--batch",
    type=click.IntRange(min=0, max=MAX_POPULATION),
    default=0,
    help="sync: candidates per batch [the optimizer's own; e.g. 1 for hs]; at most "
    f"{MAX_POPULATION:,} (more would fill memory).",
)
@click.option(
    "--resample",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Evaluations per candidate, each with its own seed.",
)
@click.option(
    "--aggregate",
    type=click.Choice(tuple(AGGREGATES)),
    default="mean",
    show_default=True,
    help="How resampled fitnesses combine.",
)
@click.option(
    "--common-seeds",
    type=click.Choice(COMMON_SEEDS),
    is_flag=False,
    flag_value="run",
    default="off",
    help="Common random numbers: every candidate on the same --resample seeds (run, what the bare "
    "flag means), or the candidates of each sync batch, fresh seeds per batch (batch).",
)
@click.option(
    "--screen",
    is_flag=True,
    help="Screen every candidate of a batch first (the problem's cheap bound on its fitness) and "
    "complete only those that can still rank among the ones the optimizer's update reads "
    "(cmaes; nao-walk with several engines and engine_score=worst).",
)
@click.option(
    "--time-limit",
    type=click.FloatRange(min=0, min_open=True, max=1e6),
    default=None,
    help="Seconds per evaluation before it is stopped and stored as failed.",
)
@click.option(
    "--max-time",
    help="Stop asking for candidates once the run has taken this long (the batch in flight "
    "finishes): it ends finished, its budget unspent (metaopt resume continues it). Not "
    "--time-limit, which bounds one evaluation.",
    **MAX_TIME,
)
@click.option(
    "--target",
    type=float,
    default=None,
    help="Stop once a fitness this good is found (at or below it; at or above when maximizing).",
)
@click.option(
    "--start-from",
    "start_from",
    multiple=True,
    metavar="RUN|RUN:CANDIDATE|RUN:recommended|NAME",
    help="Warm start: the first candidates are this run's best (in --db), one of its "
    "candidates (RUN:CANDIDATE), what its optimizer recommends (RUN:recommended: CMA-ES's "
    "mean), or a stored candidate, and points around it, instead of the "
    "optimizer's random ones. Repeat it to start from several, with points around each in "
    "turn (the optimizer then chooses among them).",
)
@click.option(
    "--start-spread",
    type=click.FloatRange(min=0, max=1),
    default=0.05,
    show_default=True,
    help="Warm start: half-width of the box the points are drawn in, share of each range.",
)
@click.option(
    "--start-points",
    type=click.IntRange(min=0),
    default=0,
    help="Warm start: how many candidates start there [the optimizer's initial population].",
)
@click.option(
    "--check",
    is_flag=True,
    help="Check every setting (the problem and optimizer built from them, the warm start) "
    "and exit: nothing is run or stored. A script that runs several runs checks them all "
    "first.",
)
@scheduling_options
@db_option
def run_command(
    optimizer_name: str,
    problem_name: str,
    budget: int | None,
    seed: int | None,
    settings: tuple[str, ...],
    mode: str,
    batch: int,
    resample: int,
    aggregate: str,
    common_seeds: str,
    screen: bool,
    time_limit: float | None,
    max_time: float | None,
    target: float | None,
    start_from: tuple[str, ...],
    start_spread: float,
    start_points: int,
    check: bool,
    executor: str | None,
    workers: int | None,
    scheduler: str | None,
    db_path: str,
) -> None:
    """Run an optimizer on a problem, storing every evaluation."""  # fmt: skip
    check_executor_options(executor, workers, scheduler)
    plugins = registry()
    optimizer_info = plugins.optimizer(optimizer_name)
    problem_info = plugins.problem(problem_name)
    optimizer_params, problem_params = split_settings(settings, optimizer_info, problem_info)
    starts = [find_start(target, problem_info, problem_params, plugins.problems, db_path)
              for target in start_from]  # fmt: skip
    spec = RunSpec(
        optimizer=optimizer_name,
        problem=problem_name,
        budget=problem_info.default_budget if budget is None else budget,
        seed=secrets.randbelow(2**31) if seed is None else seed,
        optimizer_params=optimizer_params,
        problem_params=problem_params,
        settings=RunSettings(
            mode,
            batch,
            resample,
            aggregate,
            time_limit,
            common_seeds=common_seeds,
            target=target,
            max_time=max_time,
            start=[point for _, point in starts] or None,
            start_spread=start_spread,
            start_points=start_points,
            start_from=", ".join(label for label, _ in starts) or None,
            screen=screen,
        ),
    )
    spec.settings.check(spec.budget)
    if check:
        check_run(spec, optimizer_info, problem_info)
        click.echo(f"{optimizer_name} on {problem_name}: every setting accepted; nothing run")
        return
    check_store_path(db_path)  # refused first; created once run() has checked the rest
    problem_info.checked_params(problem_params)  # refused before a worker starts
    with warnings.catch_warnings():  # run() gives the settings' warnings, once
        warnings.simplefilter("ignore", SettingWarning)
        check_run(spec, optimizer_info, problem_info)  # refused before a worker starts
    label = f"{optimizer_name} on {problem_name}"
    with build_executor(executor, workers, scheduler) as pool:  # shut down on every way out
        result = _with_progress(
            label, db_path,
            lambda progress: run(spec, optimizer_info, problem_info, db_path, progress, pool),
        )  # fmt: skip
    _print_result(result, db_path, spec.seed, pool.startup_time)


@main.command("resume")
@click.argument("run_id")
@click.option(
    "--max-time",
    help="Stop asking for candidates once this resume has taken this long, in place of the "
    "run's stored max time (stored with the run).",
    **MAX_TIME,
)
@click.option(
    "--budget",
    type=BUDGET,
    default=None,
    help="Evaluations in all, more than the run has made (stored with the run, in place of "
    "its budget): continues a run that spent its budget, or gives a run stopped early N more "
    "(its evaluations plus N).",
)
@scheduling_options
@db_option
def resume_command(
    run_id: str,
    max_time: float | None,
    budget: int | None,
    executor: str | None,
    workers: int | None,
    scheduler: str | None,
    db_path: str,
) -> None:
    """Continue a run that was interrupted or killed, that stopped at its max time with budget
    left, or (with --budget) that spent its budget, from its last checkpoint."""
    check_executor_options(executor, workers, scheduler)
    require_store(db_path)
    plugins = registry()
    with RunStore(db_path) as store:
        record = check_resume(run_id, store, budget)  # refused before a worker starts
        optimizer_info = plugins.optimizer(record.optimizer)
        problem_info = plugins.problem(record.problem)
        label = f"{record.optimizer} on {record.problem} (resumed)"
        # resume() may still refuse (its settings): the workers are shut down on every way out.
        with build_executor(executor, workers, scheduler) as pool:
            result = _with_progress(
                label, db_path,
                lambda progress: resume(
                    record.id, store, optimizer_info, problem_info, progress, pool, max_time,
                    budget,
                ),
            )  # fmt: skip
        _print_result(result, db_path, record.seed, pool.startup_time)


def _with_progress(label: str, db_path: str, start) -> RunResult:
    """Run with a progress bar; Ctrl-C/SIGTERM ends with one line on how to resume, its
    command quoted for a shell (a store path with a space or a shell character pastes back)."""
    try:
        with display.RichProgress(console, label) as progress:
            return start(progress)
    except RunInterrupted as stop:
        errors.print(
            plain(
                f"Interrupted: run {stop.run_id} stopped with {stop.stored} evaluations stored "
                f"in {db_path}. Resume with: metaopt resume {stop.run_id} --db "
                f"{shlex.quote(db_path)}"
            )
        )
        sys.exit(130)


def _print_result(result: RunResult, db_path: str, seed: int, startup_time: float) -> None:
    console.print(display.result_table(result, str(db_path), seed, startup_time))
    if result.failed:
        console.print(
            f"[yellow]{result.failed} evaluation(s) failed; their errors are stored "
            f"(metaopt export {result.run_id} --format csv).[/]"
        )


@main.command("runs")
@format_option
@db_option
def runs_command(fmt: str, db_path: str) -> None:
    """List the runs in a store: what ran, on which engine and settings, how far, how well."""
    require_store(db_path)
    with RunStore(db_path) as store:
        runs = store.runs()
        counts = {r.id: store.evaluation_counts(r.id) for r in runs}
        best = {}
        for r in runs:
            record = store.best_candidate(r)
            best[r.id] = None if record is None else record.fitness
        experiments = experiment_names(store)
    if fmt == "table":
        console.print(display.runs_table(runs, counts, best, experiments))
    else:
        print_records(
            [display.run_summary(r, counts[r.id], best[r.id], experiments.get(r.id)) for r in runs],
            fmt,
        )


def _window_option(flag: str, help: str):
    """A click option counting evaluations in a window (at least 1, 100 by default)."""
    return click.option(
        flag,
        type=click.IntRange(min=1, max=MAX_STORED_INT),
        default=DEFAULT_WINDOW,
        show_default=True,
        metavar="N",
        help=help,
    )


@main.command("show")
@click.argument("run_id")
@_window_option(
    "--recent",
    "Summarise the run's last N evaluations: median fitness and quartiles, each metric's "
    "median (a 0/1 metric's share, e.g. of falls), beside the best.",
)
@format_option
@db_option
def show_command(run_id: str, recent: int, fmt: str, db_path: str) -> None:
    """Show everything stored about one run, and where its last evaluations stand."""
    require_store(db_path)
    with RunStore(db_path) as store:
        record = store.run(run_id)
        counts, best = store.evaluation_counts(record.id), store.best_candidate(record)
        figures = recent_figures(store.last_evaluations(record.id, recent))
    if fmt == "table":
        console.print(display.run_detail(record, counts, best, figures))
    else:
        print_records(display.run_document(record, counts, best, figures), fmt)


@main.command("history")
@click.argument("run_id")
@_window_option(
    "--window", "Evaluations per row: the run's evaluations in consecutive windows of N."
)
@click.option(
    "--metric",
    "metrics",
    multiple=True,
    metavar="NAME",
    help="A metric to show per window, its median (a 0/1 metric's share); repeat for more "
    "[the run's 0/1 metrics, e.g. nao-walk's falls].",
)
@click.option(
    "--spread",
    is_flag=True,
    help="Also show how far apart each window's candidates are: the median over the variables "
    "of their standard deviation, as a share of the variable's range (CMA-ES's step shrinks it).",
)
@format_option
@db_option
def history_command(
    run_id: str, window: int, metrics: tuple[str, ...], spread: bool, fmt: str, db_path: str
) -> None:
    """Show a run's course, window by window: median fitness and quartiles, the best so far,
    and metrics' medians or shares; whether a noisy search still climbed when it stopped.
    A run without evaluations is refused in one line: it has no window to show."""
    require_store(db_path)
    with RunStore(db_path) as store:
        record = store.run(run_id)
        require_evaluations(store, record)
        maximize = record.sense == "maximize"
        space = Space.from_json(record.space) if spread else None
        history = run_history(
            store.evaluations(record.id), window, maximize, metrics or None, space
        )
    if fmt == "table":
        console.print(display.history_table(record, history))
    else:
        print_records(display.history_records(history), fmt)


@main.command("export")
@click.argument("run_id")
@click.option("--format", "fmt", type=click.Choice(FORMATS), default="csv", show_default=True)
@output_file_option("--output", "output", "File [stdout].")
@db_option
def export_command(run_id: str, fmt: str, output: Path | None, db_path: str) -> None:
    """Write a run's evaluations as CSV or JSON."""
    require_store(db_path)
    with RunStore(db_path) as store:
        store.run(run_id)  # an unknown run is an error before any file is touched
        if output is None:
            export_run(store, run_id, fmt, sys.stdout)
        else:
            with written_whole(output) as handle:
                count = export_run(store, run_id, fmt, handle)
            errors.print(plain(f"wrote {count} evaluations to {output}"))


@main.command("replay")
@click.argument("target", metavar="RUN[:CANDIDATE|:recommended]|NAME")
@click.option("--backend", default=None,
              help="Physics engine to replay on, as --set backend=NAME does (give one) [the "
                   "run's own].")  # fmt: skip
@click.option("--set", "settings", multiple=True, metavar="NAME=VALUE",
              help="Change a problem parameter for the replay.")  # fmt: skip
@output_file_option("--video", "video", "Also film the candidate into this MP4 file.", ".mp4")
@click.option("--seeds", type=click.IntRange(min=1), default=None,
              help="Re-evaluate with this many fresh seeds: median, IQR, fall rate.")  # fmt: skip
@click.option("--seed", type=click.IntRange(min=0, max=MAX_STORED_INT), default=0,
              show_default=True, help="With --seeds: draws the evaluation seeds.")  # fmt: skip
@scheduling_options
@db_option
def replay_command(
    target: str, backend: str | None, settings: tuple[str, ...], video: Path | None,
    seeds: int | None, seed: int, executor: str | None, workers: int | None,
    scheduler: str | None, db_path: str,
) -> None:  # fmt: skip
    """Re-run a stored run's best candidate (RUN), another one (RUN:CANDIDATE, as `metaopt
    robustness --top` names them), what its optimizer recommends (RUN:recommended, with the
    best's seeds) or a problem's stored candidate (NAME, e.g. a nao-walk gait),
    and compare with what was stored (with --seeds: a statistic over fresh seeds, for noisy
    problems)."""
    plugins = registry()
    source = find_source(target, plugins, db_path)
    problem_info = plugins.problem(source.problem)
    overrides = _replay_overrides(settings, backend, problem_info)
    if seeds is not None:
        with build_executor(executor, workers, scheduler) as pool:
            over_seeds = replay_seeds(source, plugins, overrides, seeds, seed, pool)
        console.print(display.replay_seeds_table(over_seeds))
        if all(o.fitness is None for o in over_seeds.outcomes):
            errors.print(plain(f"Every replay failed: {over_seeds.outcomes[0].error}"))
            sys.exit(1)
    else:
        result = replay_candidate(source, plugins, overrides)
        console.print(display.replay_table(result))
        if result.replayed.fitness is None:
            errors.print(plain(f"The replay failed: {result.replayed.error}"))
            sys.exit(1)
    if video is not None:
        write_replay_video(source, overrides, video)


def _replay_overrides(
    settings: tuple[str, ...], backend: str | None, problem_info: ProblemInfo
) -> dict[str, Any]:
    """The problem parameters a replay changes: its --set pairs, and --backend as one more
    way to set ``backend``. Both at once is refused: two values, and neither surely the one
    meant."""
    overrides = parse_problem_settings(settings, problem_info)
    if backend is not None:
        if "backend" in overrides:
            raise ConfigError(
                f"--backend {backend} and --set backend={overrides['backend']} both choose the "
                "engine; give one of --backend or --set backend"
            )
        overrides |= parse_problem_settings([f"backend={backend}"], problem_info)
    return overrides


main.add_command(new)
main.add_command(report)
main.add_command(compare)
main.add_command(robustness_command)
main.add_command(robustness_summary_command)
main.add_command(robustness_rank_command)
