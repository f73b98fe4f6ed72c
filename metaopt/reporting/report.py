"""`metaopt report`: the figures of one run, or the convergence bands of several, from the store.

One run: its convergence (best so far and trailing mean against evaluations) and, where the
problem draws figures of its own (Problem.figures), those of the run's best candidate
re-evaluated with its stored problem parameters and seed. Several runs: per group of runs with
the same setup, the median best so far with its interquartile band. An experiment: per problem
setting of its grid, the bands of each cell over its seeds and the figures of the best run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from matplotlib.figure import Figure

from metaopt.assessment.replay import replay_params
from metaopt.comparison.experiment import Experiment
from metaopt.errors import ConfigError, once_each
from metaopt.plugins import Registry
from metaopt.reporting.convergence import (
    best_so_far_band,
    group_runs,
    mean_band,
    require_evaluations,
    run_convergence,
)
from metaopt.reporting.plots import bands_figure, convergence_figure, save_figure
from metaopt.storage.experiment_store import ExperimentStore
from metaopt.storage.run_store import RunRecord, RunStore
from metaopt.storage.whole_file import written_whole


@dataclass
class Figures:
    """Figures by file stem, and a note on what could not be drawn (None when all was)."""

    figures: dict[str, Figure] = field(default_factory=dict)
    note: str | None = None


def run_figures(store: RunStore, run_id: int | str, plugins: Registry) -> Figures:
    """Convergence of run ``run_id``, plus its problem's figures of the best candidate;
    ConfigError for a run without evaluations."""
    run = store.run(run_id)
    require_evaluations(store, run)
    title = f"Run {run.id}: {run.optimizer} on {run.problem}, seed {run.seed}"
    curves = run_convergence(store, run)
    if run.problem not in plugins.problems:
        return Figures(
            {"convergence": convergence_figure(curves, title)},
            f"problem {run.problem!r} is no installed plugin (a Python function run by "
            "metaopt.minimize): only the convergence figure is drawn",
        )
    info, params = replay_params(run, plugins, {})
    problem = info.factory(**params)
    result = Figures({"convergence": convergence_figure(curves, title, problem.optimum)})
    best = store.best_candidate(run)
    if best is None:
        problem.close()
        result.note = f"run {run.id} has no successful evaluation: no figures of its best"
        return result
    try:
        result.figures.update(problem.figures(best.x, best.seed))
    except NotImplementedError as missing:
        result.note = f"problem {run.problem!r}: {missing}; only the convergence figure is drawn"
    finally:
        problem.close()
    return result


def comparison_figures(store: RunStore, run_ids: list[str], group_by: str) -> Figures:
    """Median and quartile bands of the runs' best so far, one band per group of runs;
    ConfigError where a run is given twice (it would count as two in its band) or has no
    evaluations (every band would end before it began)."""
    runs = [store.run(run_id) for run_id in run_ids]
    once_each(
        zip(run_ids, runs, strict=True),
        lambda given: (
            f"run {given[0]} is given twice; each run counts once in the bands, so give each once"
        ),
        key=lambda given: given[1].id,
    )
    for run in runs:
        require_evaluations(store, run)
    problems = sorted({run.problem for run in runs})
    if len(problems) > 1:
        raise ConfigError(f"runs compare only on one problem; these are on {', '.join(problems)}")
    groups = group_runs(runs, group_by)
    bands = {
        label: best_so_far_band([run_convergence(store, run) for run in members])
        for label, members in groups.items()
    }
    title = f"{problems[0]}: {len(runs)} runs"
    maximize = runs[0].sense == "maximize"
    return Figures({"convergence_comparison": bands_figure(bands, maximize, title)})


def write_figures(figures: Figures, out_dir: Path) -> list[Path]:
    """Save every figure as out_dir/STEM.png (out_dir created); returns the paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    return [
        save_figure(figure, out_dir / f"{stem}.png") for stem, figure in figures.figures.items()
    ]


@dataclass
class SettingFigures:
    """The figures of one problem setting of an experiment (every setting when none vary)."""

    setting: str
    best_run: RunRecord
    best_label: str
    best_fitness: float
    figures: Figures

    @property
    def folder(self) -> str:
        """A folder name for the setting: 'backend=ode' -> 'backend-ode'."""
        return self.setting.replace(", ", "_").replace("=", "-") or "all"


def experiment_figures(
    store: ExperimentStore, experiment: Experiment, plugins: Registry
) -> list[SettingFigures]:
    """Per problem setting of the experiment: each cell's median and quartile bands over its
    finished seeds, of the best so far and of the trailing mean fitness (the paper's Figs. 4
    and 5), and the figures of the setting's best run (``run_figures``)."""
    by_setting: dict[str, dict[str, list[RunRecord]]] = {}
    for cell in experiment.cells():
        members = (store.member(experiment.name, cell.key, seed) for seed in experiment.seeds)
        finished = [run for run in members if run is not None and run.status == "finished"]
        if finished:
            by_setting.setdefault(cell.setting, {})[cell.optimizer.label] = finished
    if not by_setting:
        raise ConfigError(
            f"experiment {experiment.name!r} has no finished run in this store: run "
            "`metaopt compare` on it first, or give the store it ran in (--db)"
        )
    found = []
    for setting, cells in by_setting.items():
        title = f"{experiment.name}: {setting or experiment.problem}"
        curves = {
            label: [run_convergence(store, run) for run in runs] for label, runs in cells.items()
        }
        maximize = next(iter(cells.values()))[0].sense == "maximize"
        sign = 1.0 if maximize else -1.0
        scored = [
            (sign * best.fitness, label, run, best.fitness)
            for label, runs in cells.items()
            for run in runs
            if (best := store.best_candidate(run)) is not None
        ]
        if not scored:  # finished runs always hold a success; a hand-edited store may not
            continue
        _, label, best_run, fitness = max(scored, key=lambda entry: (entry[0], -entry[2].id))
        figures = Figures(
            {
                "convergence": bands_figure(
                    {k: best_so_far_band(v) for k, v in curves.items()}, maximize, title
                ),
                "mean_fitness": bands_figure(
                    {k: mean_band(v) for k, v in curves.items()},
                    maximize,
                    title,
                    quantity="mean of the last 5 % of evaluations",
                ),
            }
        )
        of_best = run_figures(store, best_run.id, plugins)
        figures.figures.update({f"best_{stem}": f for stem, f in of_best.figures.items()})
        figures.note = of_best.note
        found.append(SettingFigures(setting, best_run, label, fitness, figures))
    return found


def write_experiment_figures(
    experiment: Experiment, settings: list[SettingFigures], out_dir: Path
) -> list[Path]:
    """Each setting's figures into out_dir/FOLDER/, and out_dir/index.md listing them."""
    lines = [f"# Figures of experiment {experiment.name}", ""]
    paths = []
    for found in settings:
        written = write_figures(found.figures, out_dir / found.folder)
        paths += written
        run = found.best_run
        lines += [
            f"## {found.setting or 'all runs'}",
            "",
            f"Best run: {run.id} ({found.best_label}, seed {run.seed}, best fitness "
            f"{found.best_fitness:.4g}).",
            "",
            *(
                f"- [{path.name}]({found.folder}/{path.name}): {_caption(path.stem)}"
                for path in written
            ),
            "",
        ]
    index = out_dir / "index.md"
    with written_whole(index) as handle:
        handle.write("\n".join(lines))
    return [*paths, index]


def _caption(stem: str) -> str:
    if stem == "convergence":
        return "each cell's median best so far over its seeds, band from 25th to 75th percentile"
    if stem == "mean_fitness":
        return "each cell's median trailing mean fitness over its seeds, with its quartile band"
    return f"the best run's {stem.removeprefix('best_').replace('_', ' ')} figure"
