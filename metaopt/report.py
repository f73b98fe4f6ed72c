"""`metaopt report`: the figures of one run, or the convergence bands of several, from the store.

One run: its convergence (best so far and trailing mean against evaluations) and, where the
problem draws figures of its own (Problem.figures), those of the run's best candidate
re-evaluated with its stored problem parameters and seed. Several runs: per group of runs with
the same setup, the median best so far with its interquartile band.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from matplotlib.figure import Figure

from metaopt.convergence import best_so_far_band, group_runs, run_convergence
from metaopt.errors import ConfigError
from metaopt.plots import bands_figure, convergence_figure, save_figure
from metaopt.plugins import Registry
from metaopt.replay import replay_params
from metaopt.store import RunStore


@dataclass
class Figures:
    """Figures by file stem, and a note on what could not be drawn (None when all was)."""

    figures: dict[str, Figure] = field(default_factory=dict)
    note: str | None = None


def run_figures(store: RunStore, run_id: int | str, plugins: Registry) -> Figures:
    """Convergence of run ``run_id``, plus its problem's figures of the best candidate."""
    run = store.run(run_id)
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
    """Median and quartile bands of the runs' best so far, one band per group of runs."""
    runs = [store.run(run_id) for run_id in run_ids]
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
