"""`metaopt compare`: run an experiment's grid (or what is left of it) and compare its cells."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import click
from rich.console import Console

from metaopt.cli.common import (
    BUDGET,
    build_executor,
    check_executor_options,
    console,
    db_option,
    errors,
    require_store,
    scheduling_options,
)
from metaopt.cli.output import OUTPUT_FORMATS, output_file_option
from metaopt.comparison.experiment import (
    Experiment,
    experiment_from_flags,
    load_experiment,
    restrict,
)
from metaopt.comparison.runner import CellSeed, run_experiment, run_experiment_in_parallel
from metaopt.comparison.summary import compare as compare_cells
from metaopt.comparison.transfer import replay_on_other_engines, transfer_table
from metaopt.errors import ConfigError
from metaopt.plugins import Registry, registry
from metaopt.reporting import display
from metaopt.reporting.plain import plain
from metaopt.reporting.result_table import ResultTable
from metaopt.running import RunInterrupted
from metaopt.storage.experiment_store import ExperimentStore
from metaopt.storage.export import dump_json
from metaopt.storage.limits import MAX_STORED_INT
from metaopt.storage.whole_file import written_whole

DEFAULT_SEEDS = 5
#: More seeds than this is a typing slip: a compare runs one run per seed and cell.
MAX_SEEDS = 10_000


@click.command("compare")
@click.argument("experiment_file", required=False, type=click.Path(dir_okay=False))
@click.option(
    "--optimizer",
    "-o",
    "optimizers",
    multiple=True,
    help="Flags form: an optimizer (repeat for each).",
)
@click.option("--problem", "-p", "problem", default=None, help="Flags form: the problem.")
@click.option(
    "--seeds",
    type=click.IntRange(min=1, max=MAX_SEEDS),
    default=None,
    help=f"Flags form: seeds 1..N [{DEFAULT_SEEDS}].",
)
@click.option(
    "--budget",
    type=BUDGET,
    default=None,
    help="Flags form: evaluations per run [the problem's default].",
)
@click.option(
    "--set",
    "settings",
    multiple=True,
    metavar="NAME=VALUE",
    help="Flags form: a problem parameter; repeat a name for a grid over its values.",
)
@click.option(
    "--target",
    type=float,
    default=None,
    help="Flags form: success = best fitness reaches it (sense-aware).",
)
@click.option("--name", default=None, help="Flags form: the experiment's name in the store.")
@click.option(
    "--transfer",
    is_flag=True,
    help="Also replay each run's best on the other physics engines: a second table (with "
    "--format json both in one object; not with --format csv: use --csv and --transfer-csv).",
)
@output_file_option("--csv", "csv_path", "Write the comparison table as CSV.")
@output_file_option(
    "--transfer-csv", "transfer_csv_path", "Write the transfer table as CSV (with --transfer)."
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice((*OUTPUT_FORMATS, "markdown")),
    default="table",
    show_default=True,
    help="table for reading; markdown to paste into a document; csv or json (every field, "
    'full precision) for programs. With --transfer, json is one object {"comparison": [...], '
    '"transfer": [...]}; csv, one table per document, is refused: use --csv FILE and '
    "--transfer-csv FILE.",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1, max=1024),
    default=1,
    show_default=True,
    help="Runs at a time, each in a process of its own and serial inside (a run depends only "
    "on its seed either way).",
)
@click.option(
    "--at",
    type=click.IntRange(min=1, max=MAX_STORED_INT),
    default=None,
    metavar="N",
    help="Also each cell's best fitness within its first N evaluations: cells of different "
    "budgets compared at an equal one (runs without resampling).",
)
@click.option(
    "--only",
    multiple=True,
    metavar="NAME=VALUE",
    help="Only part of the experiment's grid: optimizer=LABEL or a problem setting of the grid "
    "(repeat; one name's values are alternatives). Its runs are the whole experiment's.",
)
@click.option(
    "--no-run",
    is_flag=True,
    help="Run nothing: show what the store holds for the experiment (e.g. while it runs).",
)
@scheduling_options
@db_option
def compare(
    experiment_file: str | None,
    optimizers: tuple[str, ...],
    problem: str | None,
    seeds: int | None,
    budget: int | None,
    settings: tuple[str, ...],
    target: float | None,
    name: str | None,
    transfer: bool,
    csv_path: Path | None,
    transfer_csv_path: Path | None,
    fmt: str,
    jobs: int,
    at: int | None,
    only: tuple[str, ...],
    no_run: bool,
    executor: str | None,
    workers: int | None,
    scheduler: str | None,
    db_path: str,
) -> None:
    """Run optimizers x problem settings x seeds (skipping finished runs, resuming unfinished
    ones) and compare them: an experiment file (TOML, docs/comparing.md) or -o A -o B -p P."""
    check_executor_options(executor, workers, scheduler)
    if jobs > 1 and (executor is not None or scheduler is not None or (workers or 1) > 1):
        raise ConfigError(
            f"--jobs {jobs} runs whole runs side by side, each serial; --workers, --executor and "
            "--scheduler spread the evaluations of one run: use one or the other"
        )
    plugins = registry()
    flags = dict(optimizers=optimizers, problem=problem, seeds=seeds, budget=budget,
                 settings=settings, target=target, name=name)  # fmt: skip
    experiment = restrict(_experiment(experiment_file, flags, plugins), only, plugins)
    if transfer_csv_path is not None and not transfer:
        raise ConfigError("--transfer-csv writes the transfer table: add --transfer")
    if transfer and fmt == "csv":
        raise ConfigError(
            "--format csv writes one table and --transfer adds a second: use --format json (one "
            "object with both), or --csv FILE --transfer-csv FILE for the two tables as CSV"
        )
    shown = console if fmt == "table" else errors  # stdout stays pure CSV, JSON or markdown
    if no_run:
        require_store(db_path)
    with ExperimentStore(db_path) as store:
        if no_run:
            _show_stored(experiment, store, plugins, csv_path, fmt, at, transfer, transfer_csv_path)
            return
        try:
            if jobs > 1:
                done = run_experiment_in_parallel(
                    experiment, store, jobs, lambda member, k, n: _tell(shown, member, k, n)
                )
            else:
                done = run_experiment(
                    experiment, store, plugins,
                    lambda: build_executor(executor, workers, scheduler),
                    lambda label: display.RichProgress(shown, label),
                )  # fmt: skip
        except KeyboardInterrupt as stop:
            where = (
                f"run {stop.run_id} stopped with {stop.stored} evaluations stored"
                if isinstance(stop, RunInterrupted)
                else "the runs under way stopped with what they finished stored"
            )
            errors.print(
                plain(
                    f"Interrupted: {where} in {db_path}. Run the same `metaopt compare` again to "
                    "go on from there."
                )
            )
            sys.exit(130)
        counts = Counter(d.action for d in done)
        shown.print(
            plain(
                f"experiment {experiment.name!r}: {counts['ran']} run(s) ran, "
                f"{counts['resumed']} resumed, {counts['skipped']} already finished (in {db_path})"
            )
        )
        _show_stored(experiment, store, plugins, csv_path, fmt, at, transfer, transfer_csv_path)


def _tell(shown: Console, member: CellSeed, done: int, total: int) -> None:
    """A line per member of a --jobs comparison as it ends."""
    setting = f" [{member.cell.setting}]" if member.cell.setting else ""
    shown.print(
        plain(
            f"[{done}/{total}] {member.cell.optimizer.label}{setting} seed {member.seed}: run "
            f"{member.run_id} {member.action}"
        )
    )


def _show_stored(
    experiment: Experiment,
    store: ExperimentStore,
    plugins: Registry,
    csv_path: Path | None,
    fmt: str,
    at: int | None,
    transfer: bool,
    transfer_csv_path: Path | None,
) -> None:
    """The comparison table (and the transfer table) of what the store holds; as JSON with
    --transfer, one object {"comparison": [...], "transfer": [...]} (one document on stdout)."""
    comparison = compare_cells(experiment, store, plugins, at)
    if not transfer:
        _show(comparison, csv_path, fmt)
        return
    transfers = transfer_table(
        experiment, replay_on_other_engines(experiment, store, plugins), plugins
    )
    if fmt == "json":
        records = {"comparison": comparison.to_records(), "transfer": transfers.to_records()}
        dump_json(records, sys.stdout)
        _write_csv(comparison, csv_path)
        _write_csv(transfers, transfer_csv_path)
        return
    _show(comparison, csv_path, fmt)
    _show(transfers, transfer_csv_path, fmt)


def _experiment(path: str | None, flags: dict, plugins: Registry) -> Experiment:
    """The experiment from the file or from the flags; both at once, or neither, is an error."""
    given = [
        f"--{k}" if k != "optimizers" else "-o" for k, v in flags.items() if v not in (None, ())
    ]
    if path is not None:
        if given:
            raise ConfigError(
                f"{path}: give an experiment file or the flags form, not both "
                f"({', '.join(given)} given)"
            )
        return load_experiment(path, plugins)
    if not flags["optimizers"] or flags["problem"] is None:
        raise ConfigError(
            "give an experiment file (metaopt compare EXPERIMENT.toml) or at least one "
            "-o OPTIMIZER and -p PROBLEM"
        )
    return experiment_from_flags(
        **{**flags, "seeds": flags["seeds"] or DEFAULT_SEEDS}, plugins=plugins
    )


def _show(table: ResultTable, csv_path: Path | None, fmt: str) -> None:
    """The table on stdout in the format asked for, and as CSV into csv_path if given."""
    if fmt == "table":
        console.print(table.to_rich())
    elif fmt == "markdown":
        sys.stdout.write(table.to_markdown())
    elif fmt == "csv":
        table.write_csv(sys.stdout)
    else:
        dump_json(table.to_records(), sys.stdout)
    _write_csv(table, csv_path)


def _write_csv(table: ResultTable, csv_path: Path | None) -> None:
    """The table as CSV into csv_path (written whole), if given, with a line saying so."""
    if csv_path is not None:
        with written_whole(csv_path) as handle:
            table.write_csv(handle)
        errors.print(plain(f"wrote {len(table.rows)} rows to {csv_path}"))
