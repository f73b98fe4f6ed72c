"""Comparing an experiment's cells from the run store: per cell the median and interquartile
range of the best fitness and of the problem's key metrics, success against a target,
evaluations to reach it, wall time, and a two-sided Mann-Whitney rank-sum test against the
best cell of the same problem setting."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from metaopt.comparison.experiment import Cell, Experiment
from metaopt.params import resolve
from metaopt.plugins import Registry
from metaopt.problem import Sense
from metaopt.reporting.recent import is_flag, metric_value
from metaopt.reporting.result_table import Column, ResultTable, Row
from metaopt.storage.experiment_store import ExperimentStore
from metaopt.storage.run_store import RunRecord


@dataclass(frozen=True)
class FinishedRun:
    """What the comparison uses of one finished run: its best candidate (aggregated over its
    samples when resampled) and its cost."""

    run: RunRecord
    best_fitness: float | None
    #: the best candidate's metrics
    metrics: dict[str, float]
    #: evaluations spent until a candidate (its aggregate when resampled) reached the target
    #: (None: never, or no target)
    evaluations_to_target: int | None
    #: the best single evaluation among the first ``at`` (compare's equal-budget column); None
    #: without ``at``, for a resampled run, or when the run has fewer evaluations
    best_at: float | None = None


@dataclass(frozen=True)
class CellRuns:
    """A cell and its finished runs (seeds whose run is missing or unfinished are left out)."""

    cell: Cell
    runs: list[FinishedRun]
    planned: int


@dataclass(frozen=True)
class ProblemTraits:
    """What the comparison needs to know of the experiment's problem."""

    sense: Sense
    key_metrics: tuple[str, ...]

    def better(self, a: float, b: float) -> bool:
        """Whether fitness a is better than b."""
        return a > b if self.sense is Sense.MAXIMIZE else a < b

    def reaches(self, fitness: float, target: float) -> bool:
        """Whether fitness reaches the target (at least as good)."""
        return not self.better(target, fitness)


def problem_traits(experiment: Experiment, plugins: Registry) -> ProblemTraits:
    """Sense and key metrics, read from the problem built with the first cell's settings."""
    info = plugins.problem(experiment.problem)
    params = resolve(info.params, experiment.cells()[0].problem_params, info.name)
    problem = info.factory(**params)
    try:
        return ProblemTraits(Sense(problem.sense), tuple(problem.key_metrics))
    finally:
        problem.close()


def finished_runs(
    experiment: Experiment, store: ExperimentStore, traits: ProblemTraits, at: int | None = None
) -> list[CellRuns]:
    """Every cell with the finished runs of its seeds, read from the store."""
    cells = []
    for cell in experiment.cells():
        runs = []
        for seed in experiment.seeds:
            record = store.member(experiment.name, cell.key, seed)
            if record is not None and record.status == "finished":
                runs.append(_finished_run(record, store, traits, experiment.target, at))
        cells.append(CellRuns(cell, runs, len(experiment.seeds)))
    return cells


def _finished_run(
    record: RunRecord,
    store: ExperimentStore,
    traits: ProblemTraits,
    target: float | None,
    at: int | None,
) -> FinishedRun:
    """What the comparison uses of a finished run (success judged on its best candidate)."""
    best = store.best_candidate(record)
    reached = None
    if target is not None and best is not None and traits.reaches(best.fitness, target):
        reached = _evaluations_to_target(record, store, traits, target)
    return FinishedRun(
        run=record,
        best_fitness=None if best is None else best.fitness,
        metrics={} if best is None else best.metrics,
        evaluations_to_target=reached,
        best_at=None if at is None else _best_at(record, store, traits, at),
    )


def _evaluations_to_target(
    record: RunRecord, store: ExperimentStore, traits: ProblemTraits, target: float
) -> int:
    """Evaluations spent until a candidate's aggregate (as the optimizer judged it, and success
    is judged) reached ``target``: its last sample's index + 1; one sample is one evaluation."""
    # The store's own grouping of samples into complete candidates with their aggregate.
    return min(
        candidate.samples[-1].index + 1
        for candidate in store.complete_candidates(record)
        if traits.reaches(candidate.fitness, target)
    )


def _best_at(
    record: RunRecord, store: ExperimentStore, traits: ProblemTraits, at: int
) -> float | None:
    """The best fitness among the run's first ``at`` evaluations; None for a resampled run (a
    single sample is not what its optimizer judged) or one with fewer evaluations."""
    if int(record.settings.get("resample", 1)) != 1:
        return None
    first = [e for e in store.evaluations(record.id) if e.index < at]
    fitnesses = [e.fitness for e in first if e.fitness is not None]
    if len(first) < at or not fitnesses:
        return None
    return max(fitnesses) if traits.sense is Sense.MAXIMIZE else min(fitnesses)


def median_iqr(values: Sequence[float]) -> tuple[float | None, float | None]:
    """(median, 75th - 25th percentile), linear interpolation; (None, None) when empty."""
    if not values:
        return None, None
    q25, q50, q75 = np.percentile(np.asarray(values, dtype=float), [25, 50, 75])
    return float(q50), float(q75 - q25)


def rank_sum_p(a: Sequence[float], b: Sequence[float]) -> float | None:
    """Two-sided Mann-Whitney U test p-value of two samples (None when one is empty)."""
    if not a or not b:
        return None
    from scipy.stats import mannwhitneyu  # here: scipy.stats costs every CLI call a second

    return float(mannwhitneyu(a, b, alternative="two-sided").pvalue)


def shown_metrics(key_metrics: Iterable[str], metric_sets: Iterable[dict[str, float]]) -> list[str]:
    """The key metrics the runs have, each followed by its per-engine forms ``NAME@ENGINE``."""
    present = set().union(*metric_sets)
    names = []
    for key in key_metrics:
        names += [key] if key in present else []
        names += sorted(name for name in present if name.startswith(f"{key}@"))
    return names


def center(values: Sequence[float], flag: bool) -> float | None:
    """Over runs: the rate of a flag (the fraction of 1s), else the median, as
    reporting.recent.metric_value reckons a window's; None when there are none."""
    return float(metric_value(values, flag)) if values else None


def metric_column(name: str, flag: bool) -> Column:
    """A metric's column: the rate of runs where a flag is 1, else median (IQR). Per-engine
    forms (NAME@ENGINE) go to the CSV only."""
    in_terminal = "@" not in name
    if flag:
        return Column(f"{name} rate", (f"{name}_rate",), percent=True, in_terminal=in_terminal)
    fields = (f"{name}_median", f"{name}_iqr")
    return Column(f"{name}\nmedian (IQR)", fields, "{} ({})", in_terminal=in_terminal)


def metric_fields(name: str, values: Sequence[float], flag: bool) -> Row:
    """A metric's fields over runs: the rate of runs where a flag is 1, else median and IQR."""
    if flag:
        return {f"{name}_rate": center(values, flag)}
    median, iqr = median_iqr(values)
    return {f"{name}_median": median, f"{name}_iqr": iqr}


def compare(
    experiment: Experiment, store: ExperimentStore, plugins: Registry, at: int | None = None
) -> ResultTable:
    """The comparison table of the experiment's cells from what the store holds; with ``at``,
    also each cell's best fitness within its first ``at`` evaluations (cells with different
    budgets compared at an equal one)."""
    traits = problem_traits(experiment, plugins)
    cells = finished_runs(experiment, store, traits, at)
    all_runs = [run for cell in cells for run in cell.runs]
    metrics = shown_metrics(traits.key_metrics, (run.metrics for run in all_runs))
    flags = {m: is_flag(r.metrics[m] for r in all_runs if m in r.metrics) for m in metrics}
    columns = [
        Column("optimizer", ("optimizer",)),
        Column("setting", ("setting",)),
        Column("runs", ("finished", "planned"), "{}/{}"),
        Column("best fitness\nmedian (IQR)", ("fitness_median", "fitness_iqr"), "{} ({})"),
        *(metric_column(name, flags[name]) for name in metrics),
    ]
    rows: list[Row] = []
    for cell in cells:
        fitnesses = _fitnesses(cell)
        median, iqr = median_iqr(fitnesses)
        row: Row = {
            "optimizer": cell.cell.optimizer.label,
            "setting": cell.cell.setting or None,
            "finished": len(cell.runs),
            "planned": cell.planned,
            "fitness_median": median,
            "fitness_iqr": iqr,
        }
        for name in metrics:
            values = [r.metrics[name] for r in cell.runs if name in r.metrics]
            row.update(metric_fields(name, values, flags[name]))
        if at is not None:
            row["best_at_median"], row["best_at_iqr"] = median_iqr(_values_at(cell))
        if experiment.target is not None:
            row.update(_success(cell))
        walls = [r.run.wall_time for r in cell.runs if r.run.wall_time is not None]
        row["wall_time_median"] = median_iqr(walls)[0]
        rows.append(row)
    if at is not None:
        header = f"best in first {at}\nmedian (IQR)"
        columns.append(Column(header, ("best_at_median", "best_at_iqr"), "{} ({})"))
        columns.append(Column(f"p vs best\nin first {at}", ("p_at",)))
        _add_p_values(cells, rows, traits, ("best_at_median", "p_at"), _values_at)
    if experiment.target is not None:
        columns += [
            Column(f"success\n(target {experiment.target:g})", ("success_rate",), percent=True),
            Column("evals to\ntarget", ("evaluations_to_target",)),
        ]
    columns += [Column("wall time\nmedian, s", ("wall_time_median",)),
                Column("p vs best\n(rank-sum)", ("p_value",))]  # fmt: skip
    _add_p_values(cells, rows, traits)
    return ResultTable(f"experiment {describe(experiment)}", columns, rows)


def describe(experiment: Experiment) -> str:
    """'NAME: PROBLEM (fixed settings), seeds 1, 2, 3' for table titles."""
    fixed = f" ({experiment.fixed_settings})" if experiment.fixed_settings else ""
    seeds = ", ".join(map(str, experiment.seeds))
    return f"{experiment.name}: {experiment.problem}{fixed}, seeds {seeds}"


def _fitnesses(cell: CellRuns) -> list[float]:
    return [r.best_fitness for r in cell.runs if r.best_fitness is not None]


def _values_at(cell: CellRuns) -> list[float]:
    return [r.best_at for r in cell.runs if r.best_at is not None]


def _success(cell: CellRuns) -> Row:
    """Success rate over finished runs; median evaluations to the target over successful ones."""
    reached = [r.evaluations_to_target for r in cell.runs if r.evaluations_to_target is not None]
    return {
        "success_rate": len(reached) / len(cell.runs) if cell.runs else None,
        "evaluations_to_target": median_iqr(reached)[0],
    }


def _add_p_values(
    cells: list[CellRuns],
    rows: list[Row],
    traits: ProblemTraits,
    fields: tuple[str, str] = ("fitness_median", "p_value"),
    values: Callable[[CellRuns], list[float]] = lambda cell: _fitnesses(cell),
) -> None:
    """Within each problem setting, each cell's rank-sum p-value against the cell with the
    best median fitness (the best cell itself gets none); ``fields`` name the median compared
    and the p-value written, ``values`` gives a cell's samples."""
    median, p_value = fields
    by_setting: dict[str, list[int]] = {}
    for index, cell in enumerate(cells):
        by_setting.setdefault(cell.cell.setting, []).append(index)
    for indices in by_setting.values():
        ranked = [i for i in indices if rows[i].get(median) is not None]
        if len(ranked) < 2:
            continue
        best = ranked[0]
        for i in ranked[1:]:
            if traits.better(rows[i][median], rows[best][median]):
                best = i
        for i in ranked:
            if i != best:
                rows[i][p_value] = rank_sum_p(values(cells[best]), values(cells[i]))
