"""``metaopt robustness RUN|NAME``: a candidate over its problem's standard perturbation table
on every installed engine (the work is in metaopt.robustness)."""

from __future__ import annotations

from pathlib import Path

import click

from metaopt import display, robustness
from metaopt.candidates import Candidate, find_candidate
from metaopt.cli.common import (
    MAX_INT64,
    build_executor,
    console,
    db_option,
    scheduling_options,
)
from metaopt.cli.compare import MAX_SEEDS
from metaopt.cli.output import check_output_file
from metaopt.errors import ConfigError
from metaopt.physics import engine_names
from metaopt.plugins import registry
from metaopt.settings import parse_problem_settings


@click.command("robustness")
@click.argument("target", metavar="RUN|NAME")
@click.option("--engines", default=None, help="Engines joined by '+' [every installed one].")
@click.option(
    "--seeds",
    type=click.IntRange(min=1, max=MAX_SEEDS),
    default=10,
    show_default=True,
    help="Evaluation seeds per perturbation and engine.",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0, max=MAX_INT64),
    default=0,
    show_default=True,
    help="Draws the evaluation seeds (the same ones in every cell).",
)
@click.option(
    "--cells", default=None, metavar="NAME,...", help="Only these perturbations of the table [all]."
)
@click.option(
    "--set",
    "settings",
    multiple=True,
    metavar="NAME=VALUE",
    help="Change one of the candidate's problem parameters first.",
)
@click.option(
    "--csv",
    "csv_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the table as CSV here.",
)
@click.option(
    "--figure",
    "figure_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Draw speed and fall rate per perturbation (PNG) here.",
)
@scheduling_options
@db_option
def robustness_command(
    target: str, engines: str | None, seeds: int, seed: int, cells: str | None,
    settings: tuple[str, ...], csv_path: Path | None, figure_path: Path | None,
    executor: str | None, workers: int | None, scheduler: str | None, db_path: str,
) -> None:  # fmt: skip
    """Evaluate a run's best candidate or a stored one (e.g. a nao-walk gait) over its
    problem's standard perturbation table, on every engine, over N seeds per cell."""
    if csv_path is not None:
        check_output_file(str(csv_path), "--csv", suffix=".csv")
    if figure_path is not None:
        check_output_file(str(figure_path), "--figure", suffix=".png")
    plugins = registry()
    candidate, info = find_candidate(target, plugins.problems, db_path)
    if info.perturbations is None:
        raise ConfigError(f"problem {info.name!r} has no perturbation table")
    changes = parse_problem_settings(settings, info)
    candidate = Candidate(
        candidate.label, candidate.problem, {**candidate.params, **changes}, candidate.x
    )
    names = engine_names(engines) if engines is not None else tuple(plugins.physics_backends)
    for name in names:
        plugins.physics_backend(name)  # ConfigError listing the installed ones
    table = robustness.select_cells(
        info.perturbations, [c.strip() for c in cells.split(",")] if cells is not None else None
    )
    robustness.tasks(candidate, info, table, names, seeds, seed)  # bad parameters: before work
    console.print(f"perturbation table {table.version}: {len(table.cells)} cells x "
                  f"{len(names)} engines x {seeds} seeds")  # fmt: skip
    with build_executor(executor, workers, scheduler) as pool:
        results = robustness.evaluate(candidate, info, table, names, seeds, seed, pool)
    totals = robustness.whole_table(results)
    console.print(
        display.robustness_table(candidate.label, table.version, results, table.metrics, totals)
    )
    if csv_path is not None:
        robustness.write_csv(csv_path, candidate, table, [*results, *totals])
        console.print(f"wrote {csv_path}")
    if figure_path is not None:
        from metaopt.plots import save_figure

        speed, fell = table.metrics[0], next(m for m in table.metrics if m.startswith("fell"))
        save_figure(robustness.figure(candidate, table, results, speed, fell), figure_path)
        console.print(f"wrote {figure_path}")
