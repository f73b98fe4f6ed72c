"""``metaopt report RUN...``: PNG figures of runs; and the video part of ``metaopt replay``.

matplotlib and the renderers are imported when a command draws, not when the CLI starts.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from metaopt.assessment.replay import ReplaySource
from metaopt.cli.common import db_option, require_store
from metaopt.cli.output import check_output_folder
from metaopt.errors import ConfigError
from metaopt.plugins import registry
from metaopt.reporting.convergence import GROUP_BY
from metaopt.storage.run_store import RunStore


@click.command("report")
@click.argument("run_ids", nargs=-1, metavar="RUN...")
@click.option(
    "--experiment",
    "experiment_file",
    type=click.Path(dir_okay=False),
    default=None,
    help="Instead of runs: an experiment file run by `metaopt compare`; per problem setting, "
    "each cell's bands over its seeds and the best run's figures.",
)
@click.option(
    "--only",
    multiple=True,
    metavar="NAME=VALUE",
    help="With --experiment: only part of its grid, as `metaopt compare --only`.",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder for the PNG files [report-RUN; report-compare for several runs].",
)
@click.option(
    "--group-by",
    type=click.Choice(GROUP_BY),
    default="setup",
    show_default=True,
    help="Several runs: one band per optimizer and parameters, or per optimizer name.",
)
@db_option
def report(
    run_ids: tuple[str, ...],
    experiment_file: str | None,
    only: tuple[str, ...],
    out_dir: Path | None,
    group_by: str,
    db_path: str,
) -> None:
    """Draw a run's convergence and its best candidate's figures (nao-walk: joint angles,
    drift, torso height); for several runs, median and quartile bands of their best so far; for
    an experiment (--experiment FILE), both per problem setting."""
    from metaopt.reporting.report import comparison_figures, run_figures, write_figures

    if (experiment_file is None) == (not run_ids):
        raise ConfigError("give run ids (metaopt report RUN...) or --experiment FILE, not both")
    if experiment_file is not None:
        _report_experiment(experiment_file, only, out_dir, db_path)
        return
    if only:
        raise ConfigError("--only selects part of an experiment: give --experiment FILE")
    default = f"report-{run_ids[0]}" if len(run_ids) == 1 else "report-compare"
    check_output_folder(out_dir or Path(default), "--out")
    require_store(db_path)
    with RunStore(db_path) as store:
        if len(run_ids) == 1:
            figures = run_figures(store, run_ids[0], registry())
        else:
            figures = comparison_figures(store, list(run_ids), group_by)
    paths = write_figures(figures, out_dir or Path(default))
    for path in paths:
        click.echo(f"wrote {path}")
    if figures.note:
        click.echo(f"Note: {figures.note}.", err=True)


def _report_experiment(
    path: str, only: tuple[str, ...], out_dir: Path | None, db_path: str
) -> None:
    """`metaopt report --experiment FILE`: every (selected) setting's figures and an index.md."""
    from metaopt.comparison.experiment import load_experiment, restrict
    from metaopt.reporting.report import experiment_figures, write_experiment_figures
    from metaopt.storage.experiment_store import ExperimentStore

    plugins = registry()
    experiment = restrict(load_experiment(path, plugins), only, plugins)
    target = out_dir or Path(f"report-{experiment.name}")
    check_output_folder(target, "--out")
    require_store(db_path)
    with ExperimentStore(db_path) as store:
        settings = experiment_figures(store, experiment, plugins)
    for written in write_experiment_figures(experiment, settings, target):
        click.echo(f"wrote {written}")
    for found in settings:
        if found.figures.note:
            click.echo(f"Note ({found.setting or 'all runs'}): {found.figures.note}.", err=True)


def write_replay_video(source: ReplaySource, overrides: dict[str, Any], path: Path) -> None:
    """``metaopt replay TARGET --video PATH``: film the replayed candidate into PATH."""
    from metaopt.reporting.video import VIDEO_FPS, VIDEO_SIZE, film_candidate

    frames = film_candidate(source, registry(), overrides, path)
    width, height = VIDEO_SIZE
    click.echo(
        f"wrote {path}: {frames} frames, {width}x{height}, {VIDEO_FPS} fps "
        f"({frames / VIDEO_FPS:.1f} s)"
    )
