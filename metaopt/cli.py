"""The ``metaopt`` command line: list, run, resume, runs, show, export, replay, compare, report,
new."""

from __future__ import annotations

import secrets
import sys

import click

from metaopt import display
from metaopt.cli_common import (
    build_executor,
    console,
    db_option,
    errors,
    require_store,
    scheduling_options,
)
from metaopt.cli_compare import compare
from metaopt.cli_new import new
from metaopt.cli_report import report, write_replay_video
from metaopt.errors import MetaoptError
from metaopt.export import FORMATS, export_run
from metaopt.plugins import registry
from metaopt.replay import replay_best
from metaopt.run_loop import (
    AGGREGATES,
    MODES,
    RunInterrupted,
    RunResult,
    RunSettings,
    RunSpec,
    resume,
    run,
)
from metaopt.settings import parse_problem_settings, split_settings
from metaopt.store import RunStore


class MetaoptGroup(click.Group):
    """Turns every MetaoptError into one 'Error: ...' line and exit code 2."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except MetaoptError as error:
            errors.print(f"[bold red]Error:[/] {error}", highlight=False, soft_wrap=True)
            sys.exit(2)


@click.group(cls=MetaoptGroup)
@click.version_option(package_name="metaopt")
def main() -> None:
    """metaopt: metaheuristic optimization with plugins."""


@main.command("list")
@click.argument("name", required=False)
def list_plugins(name: str | None) -> None:
    """Show the installed optimizers, problems and physics engines (or one of them in full)."""
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
    for kind, table in (("optimizer", plugins.optimizers), ("problem", plugins.problems)):
        if name in table:
            info = table[name]
            console.print(f"[bold cyan]{info.name}[/] ({kind}): {info.summary}")
            if info.description:
                console.print(display.reflow(info.description), markup=False)
            if kind == "problem":
                console.print(f"default budget: {info.default_budget} evaluations")
            console.print(display.params_table("parameters", info.params))
            return
    if name in plugins.physics_backends:
        info = plugins.physics_backends[name]
        console.print(f"[bold cyan]{info.name}[/] (physics backend): {info.summary}")
        return
    plugins.optimizer(name)  # raises with close matches among optimizers
    raise AssertionError("unreachable")


@main.command("run")
@click.option("--optimizer", "-o", "optimizer_name", required=True, help="Optimizer name.")
@click.option("--problem", "-p", "problem_name", required=True, help="Problem name.")
@click.option("--budget", type=int, default=None, help="Evaluations [problem's default].")
@click.option("--seed", type=int, default=None, help="Run seed [random, printed].")
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
    type=click.IntRange(min=0),
    default=0,
    help="sync: candidates per batch [the optimizer's own; e.g. 1 for hs].",
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
    "--time-limit",
    type=float,
    default=None,
    help="Seconds per evaluation before it is stopped and stored as failed.",
)
@click.option(
    "--target",
    type=float,
    default=None,
    help="Stop once a fitness this good is found (at or below it; at or above when maximizing).",
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
    time_limit: float | None,
    target: float | None,
    executor: str | None,
    workers: int | None,
    scheduler: str | None,
    db_path: str,
) -> None:
    """Run an optimizer on a problem, storing every evaluation."""  # fmt: skip
    plugins = registry()
    optimizer_info = plugins.optimizer(optimizer_name)
    problem_info = plugins.problem(problem_name)
    optimizer_params, problem_params = split_settings(settings, optimizer_info, problem_info)
    spec = RunSpec(
        optimizer=optimizer_name,
        problem=problem_name,
        budget=problem_info.default_budget if budget is None else budget,
        seed=secrets.randbelow(2**31) if seed is None else seed,
        optimizer_params=optimizer_params,
        problem_params=problem_params,
        settings=RunSettings(mode, batch, resample, aggregate, time_limit, target),
    )
    if spec.budget < 1:
        raise click.BadParameter(f"must be at least 1, got {spec.budget}", param_hint="--budget")
    spec.settings.check(spec.budget)
    with RunStore(db_path) as store:
        label = f"{optimizer_name} on {problem_name}"
        pool = build_executor(executor, workers, scheduler)
        result = _with_progress(
            label, db_path,
            lambda progress: run(spec, optimizer_info, problem_info, store, progress, pool),
        )  # fmt: skip
        _print_result(result, db_path, spec.seed)


@main.command("resume")
@click.argument("run_id")
@scheduling_options
@db_option
def resume_command(
    run_id: str, executor: str | None, workers: int | None, scheduler: str | None, db_path: str
) -> None:
    """Continue a run that was interrupted or killed, from its last checkpoint."""
    require_store(db_path)
    plugins = registry()
    with RunStore(db_path) as store:
        record = store.run(run_id)
        optimizer_info = plugins.optimizer(record.optimizer)
        problem_info = plugins.problem(record.problem)
        pool = build_executor(executor, workers, scheduler)
        label = f"{record.optimizer} on {record.problem} (resumed)"
        result = _with_progress(
            label, db_path,
            lambda progress: resume(record.id, store, optimizer_info, problem_info, progress, pool),
        )  # fmt: skip
        _print_result(result, db_path, record.seed)


def _with_progress(label: str, db_path: str, start) -> RunResult:
    """Run with a progress bar; Ctrl-C/SIGTERM ends with one line on how to resume."""
    try:
        with display.RichProgress(console, label) as progress:
            return start(progress)
    except RunInterrupted as stop:
        errors.print(
            f"Interrupted: run {stop.run_id} stopped with {stop.stored} evaluations stored in "
            f"{db_path}. Resume with: metaopt resume {stop.run_id} --db {db_path}"
        )
        sys.exit(130)


def _print_result(result: RunResult, db_path: str, seed: int) -> None:
    console.print(display.result_table(result, str(db_path), seed))
    if result.failed:
        console.print(
            f"[yellow]{result.failed} evaluation(s) failed; their errors are stored "
            f"(metaopt export {result.run_id} --format csv).[/]"
        )


@main.command("runs")
@db_option
def runs_command(db_path: str) -> None:
    """List the runs in a store."""
    require_store(db_path)
    with RunStore(db_path) as store:
        runs = store.runs()
        counts = {r.id: store.evaluation_counts(r.id) for r in runs}
        best = {}
        for r in runs:
            record = store.best_evaluation(r)
            best[r.id] = None if record is None else record.fitness
        console.print(display.runs_table(runs, counts, best))


@main.command("show")
@click.argument("run_id")
@db_option
def show_command(run_id: str, db_path: str) -> None:
    """Show everything stored about one run."""
    require_store(db_path)
    with RunStore(db_path) as store:
        record = store.run(run_id)
        console.print(
            display.run_detail(
                record, store.evaluation_counts(record.id), store.best_evaluation(record)
            )
        )


@main.command("export")
@click.argument("run_id")
@click.option("--format", "fmt", type=click.Choice(FORMATS), default="csv", show_default=True)
@click.option("--output", type=click.Path(dir_okay=False), default=None, help="File [stdout].")
@db_option
def export_command(run_id: str, fmt: str, output: str | None, db_path: str) -> None:
    """Write a run's evaluations as CSV or JSON."""
    require_store(db_path)
    with RunStore(db_path) as store:
        if output is None:
            export_run(store, run_id, fmt, sys.stdout)
        else:
            with open(output, "w", newline="") as handle:
                count = export_run(store, run_id, fmt, handle)
            errors.print(f"wrote {count} evaluations to {output}")


@main.command("replay")
@click.argument("run_id")
@click.option("--backend", default=None, help="Physics engine to replay on [the run's own].")
@click.option("--set", "settings", multiple=True, metavar="NAME=VALUE",
              help="Change a problem parameter for the replay.")  # fmt: skip
@click.option("--video", type=click.Path(dir_okay=False), default=None,
              help="Also film the best candidate into this MP4 file.")  # fmt: skip
@db_option
def replay_command(
    run_id: str, backend: str | None, settings: tuple[str, ...], video: str | None, db_path: str
) -> None:
    """Re-run a stored run's best candidate and compare with what was stored."""
    require_store(db_path)
    plugins = registry()
    with RunStore(db_path) as store:
        run_record = store.run(run_id)
        problem_info = plugins.problem(run_record.problem)
        pairs = [*settings, *([f"backend={backend}"] if backend is not None else [])]
        overrides = parse_problem_settings(pairs, problem_info)
        result = replay_best(store, run_id, plugins, overrides)
    console.print(display.replay_table(result))
    if result.replayed.fitness is None:
        errors.print(f"The replay failed: {result.replayed.error}")
        sys.exit(1)
    if video is not None:
        write_replay_video(db_path, run_id, overrides, video)


main.add_command(new)
main.add_command(report)
main.add_command(compare)
