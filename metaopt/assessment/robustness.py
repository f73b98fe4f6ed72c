"""How a candidate fares in worlds it was not tuned in: a problem's perturbation table, every
cell evaluated on every engine over N seeds, summarized as statistics (median, interquartile
range, rate), not single trajectories.

A problem announces its standard table (ProblemInfo.perturbations): named cells, each a change
of problem parameters (scale one, set another), under a version string that changes whenever a
cell does, so tables from different days are comparable. Every cell uses the same N evaluation
seeds (common random numbers: differences between cells are not seed noise). A cell that
changes nothing on an engine (its ``inert`` says why) is left out there, so the whole table
does not count the nominal world twice.
"""

from __future__ import annotations

import csv
import math
import statistics
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from metaopt.assessment.candidates import Candidate, space_of
from metaopt.assessment.replay import check_space
from metaopt.errors import ConfigError
from metaopt.executors.base import EvaluationTask, Executor, Outcome, release_problems
from metaopt.params import resolve
from metaopt.problem import Problem, ProblemInfo
from metaopt.seeding import EvaluationSeeds
from metaopt.storage.whole_file import written_whole

if TYPE_CHECKING:
    from matplotlib.figure import Figure


@dataclass(frozen=True)
class Perturbation:
    """One cell of a table: problem parameters multiplied (``scale``) or replaced (``set``)
    relative to the candidate's own. ``inert``, given the cell's problem on one engine, says
    why the cell changes nothing there (None: it does); the cell is then left out on that
    engine, where its episodes would repeat the nominal world's."""

    name: str
    description: str
    scale: Mapping[str, float] = field(default_factory=dict)
    set: Mapping[str, Any] = field(default_factory=dict)
    inert: Callable[[Problem], str | None] | None = None

    def apply(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """The candidate's parameters with this cell's changes."""
        changed = dict(params)
        for name, factor in self.scale.items():
            changed[name] = params[name] * factor
        changed.update(self.set)
        return changed


@dataclass(frozen=True)
class PerturbationTable:
    """A versioned list of cells; ``common`` is set in every cell (e.g. a background noise that
    makes N seeds N different episodes, or a metric to measure); ``metrics`` are summarized.
    A metric whose name starts with 'fell' is a rate; others get median and quartiles; one
    written '|name|' is the metric's absolute value."""

    version: str
    cells: tuple[Perturbation, ...]
    metrics: tuple[str, ...]
    common: Mapping[str, Any] = field(default_factory=dict)
    #: metrics an episode reports only when an event happened, each with the rate that counts
    #: the event (nao-walk's time_to_fall, only where the episode fell): a goal on one holds
    #: where no episode had the event, rather than failing on a median of nothing
    only_when: Mapping[str, str] = field(default_factory=dict)


@dataclass
class CellResult:
    """One (cell, engine): the N evaluations' metrics and fitnesses, in the same order (failed
    ones counted apart)."""

    cell: str
    engine: str
    samples: list[dict[str, float]]
    failed: int
    fitnesses: list[float] = field(default_factory=list)

    def summary(self, metric: str) -> tuple[float, float, float]:
        """summarize() of a metric over this cell's evaluations."""
        return summarize(self.samples, metric)


def is_rate(metric: str) -> bool:
    """Whether a metric is a rate (its name starts with 'fell': the share of episodes that
    fell), summarized by its mean and shown in %, not by a median and quartiles."""
    return metric.startswith("fell")


def summarize(samples: Sequence[Mapping[str, float]], metric: str) -> tuple[float, float, float]:
    """(median, lower quartile, upper quartile) of a metric over the samples that report it
    (NaN when none do); for a rate (is_rate) its mean thrice; '|name|'
    summarizes the absolute values."""
    name = metric.strip("|")
    values = [s[name] for s in samples if name in s]
    if metric != name:
        values = [abs(v) for v in values]
    if not values:
        return (math.nan, math.nan, math.nan)
    if is_rate(metric):
        rate = statistics.fmean(values)
        return (rate, rate, rate)
    low, median, high = np.percentile(values, [25, 50, 75])
    return (float(median), float(low), float(high))


def engine_param(info: ProblemInfo) -> str:
    """The parameter that names a problem's physics engine (ConfigError when it has none)."""
    if not any(p.name == "backend" for p in info.params):
        raise ConfigError(f"problem {info.name!r} has no backend parameter to choose engines by")
    return "backend"


@dataclass
class Plan:
    """What one candidate's table runs: every (cell, engine, task), and the (cell, engine,
    reason) left out because the cell changes nothing on that engine."""

    tasks: list[tuple[str, str, EvaluationTask]]
    left_out: list[tuple[str, str, str]]


def tasks(
    candidate: Candidate,
    info: ProblemInfo,
    table: PerturbationTable,
    engines: Sequence[str],
    seeds: int,
    seed: int,
) -> Plan:
    """Every (cell, engine, task): the same ``seeds`` evaluation seeds (drawn from ``seed``)
    in every cell and on every engine, but for the cells inert there (ConfigError when that
    leaves an engine nothing). Parameters are checked before anything runs (each cell's
    problem is built once and closed: engines are built on first use)."""
    if seeds < 1:
        raise ConfigError(f"seeds must be at least 1, got {seeds}")
    backend = engine_param(info)
    draw = EvaluationSeeds(seed)
    base = {**candidate.params, **table.common}
    plan = Plan([], [])
    for cell in table.cells:
        for engine in engines:
            given = {**cell.apply(base), backend: engine}
            params = resolve(info.params, given, f"{info.name} ({cell.name} on {engine})")
            problem = info.factory(**params)  # a problem refusing its parameters says so now
            try:
                if problem.space.dim != len(candidate.x):
                    raise ConfigError(
                        f"{candidate.label}: {cell.name} on {engine} has a space of "
                        f"{problem.space.dim} variables; the candidate has {len(candidate.x)}"
                    )
                reason = cell.inert(problem) if cell.inert is not None else None
            finally:
                problem.close()
            if reason is not None:
                plan.left_out.append((cell.name, engine, reason))
                continue
            for i in range(seeds):
                index = len(plan.tasks)
                plan.tasks.append((cell.name, engine, EvaluationTask(
                    index, candidate.x, draw(i), info.factory, params)))  # fmt: skip
    ran = {on for _, on, _ in plan.tasks}
    idle = [engine for engine in engines if engine not in ran]
    if idle:
        engine = idle[0]
        reasons = "; ".join(f"{cell}: {reason}" for cell, on, reason in plan.left_out
                            if on == engine)  # fmt: skip
        raise ConfigError(
            f"{candidate.label}: every cell asked for changes nothing on {engine} ({reasons}), "
            "so there is nothing to evaluate there; ask for other cells or engines"
        )
    return plan


def evaluate(plans: Sequence[Plan], executor: Executor) -> list[list[CellResult]]:
    """Each plan (what tasks() returns for one candidate) as that candidate's cells on every
    engine they run on, in table order (a cell left out on an engine has no result there).
    Every plan's tasks are submitted before any result is awaited, so the executor's workers
    stay busy from one candidate to the next. The problems this process built for them (an
    in-process executor's) are closed at the end, as replay_seeds does."""
    try:
        submitted = [
            [(cell, engine, executor.submit(task)) for cell, engine, task in plan.tasks]
            for plan in plans
        ]
        tables = []
        for futures in submitted:
            results: dict[tuple[str, str], CellResult] = {}
            for cell, engine, future in futures:
                outcome: Outcome = future.result()
                result = results.setdefault((cell, engine), CellResult(cell, engine, [], 0))
                if outcome.fitness is None:
                    result.failed += 1
                else:
                    result.samples.append(outcome.metrics)
                    result.fitnesses.append(outcome.fitness)
            tables.append(list(results.values()))
    finally:
        release_problems()
    return tables


#: The cell name of an engine's row over every episode of the table.
WHOLE_TABLE = "whole table"


def whole_table(results: Sequence[CellResult]) -> list[CellResult]:
    """Per engine, one result over every episode of every cell (what "over the standard table"
    means in a goal: the median over all of them, the fall rate of all of them)."""
    pooled: dict[str, CellResult] = {}
    for result in results:
        row = pooled.setdefault(result.engine, CellResult(WHOLE_TABLE, result.engine, [], 0))
        row.samples.extend(result.samples)
        row.fitnesses.extend(result.fitnesses)
        row.failed += result.failed
    return list(pooled.values())


def differing_params(
    candidates: Sequence[Candidate], table: PerturbationTable, engine: str
) -> list[str]:
    """The problem parameters the candidates do not share, beyond those the table sets for all
    (its common settings) and the ``engine`` parameter: where a ranking may compare unlike
    fitnesses."""
    fixed = {*table.common, engine}
    names = sorted({name for c in candidates for name in c.params} - fixed)
    return [
        name for name in names
        if len({repr(c.params.get(name)) for c in candidates}) > 1
    ]  # fmt: skip


@dataclass(frozen=True)
class Goal:
    """A bound on one of a table's metrics over an engine's whole table: its median (for a
    rate, its value) at least or at most a threshold; written ``speed>=0.44``, ``fell<=0.05``."""

    metric: str
    at_least: bool
    threshold: float
    #: the rate of the event the metric is reported with alone (PerturbationTable.only_when)
    only_when: str | None = None

    def __str__(self) -> str:
        return f"{self.metric}{'>=' if self.at_least else '<='}{self.threshold:g}"

    def margin(self, row: CellResult) -> float:
        """margin_in the row's figures (medians; a rate's value)."""
        names = (self.metric, self.only_when)
        return self.margin_in({n: row.summary(n)[0] for n in names if n is not None}, row.failed)

    def margin_in(self, figures: Mapping[str, float], failed: int = 0) -> float:
        """How far inside the bound one engine's figure is, relative to the threshold
        (absolute for a threshold of 0): negative outside it, -inf where an evaluation failed
        or nothing measured it, +inf where the metric comes with an event that never happened
        (a time to fall of a gait that never fell)."""
        if failed:
            return -math.inf
        value = figures.get(self.metric, math.nan)
        if math.isnan(value):
            no_event = self.only_when is not None and figures.get(self.only_when) == 0
            return math.inf if no_event else -math.inf
        slack = value - self.threshold if self.at_least else self.threshold - value
        return slack / abs(self.threshold) if self.threshold else slack


def parse_goal(
    text: str, metrics: Sequence[str], version: str, only_when: Mapping[str, str] | None = None
) -> Goal:
    """``METRIC>=VALUE`` or ``METRIC<=VALUE``, METRIC one of ``metrics`` (those of table
    ``version``, whose ``only_when`` it carries); ConfigError naming what is accepted
    otherwise."""
    for operator in (">=", "<="):
        metric, found, value = text.partition(operator)
        if found and metric.strip() in metrics:
            try:
                threshold = float(value)
            except ValueError:
                break
            if math.isfinite(threshold):
                name = metric.strip()
                return Goal(name, operator == ">=", threshold, (only_when or {}).get(name))
    raise ConfigError(
        f"goal {text!r}: write METRIC>=VALUE or METRIC<=VALUE with a finite VALUE and a "
        f"metric of table {version} ({', '.join(metrics)})"
    )


@dataclass
class Ranked:
    """A candidate's table, its whole-table rows per engine, and its score: the worst
    engine's mean fitness over the whole table (a failed evaluation counts as the worst); with
    goals, ``missed``: how many
    (goal, engine) pairs it misses, and ``margin``: its smallest margin to any goal on any
    engine (Goal.margin)."""

    candidate: Candidate
    results: list[CellResult]
    totals: list[CellResult]  # whole_table(results), per engine
    score: float
    margin: float | None = None
    missed: int | None = None


def rank(
    tables: Sequence[tuple[Candidate, list[CellResult]]],
    maximize: bool,
    goals: Sequence[Goal] = (),
) -> list[Ranked]:
    """Candidates best first by their worst engine's mean fitness over the whole table: the
    mean counts every fall at its fitness's price, the worst engine asks for one candidate
    that holds on all. With goals, by the smallest margin to a goal on any engine first (the
    candidate that meets every goal with the most room; fitness beyond a goal buys nothing),
    then by fitness; each also counts the (goal, engine) pairs it misses, shown beside it.
    Ties keep the given order."""
    sign = 1.0 if maximize else -1.0
    ranked = []
    for candidate, results in tables:
        rows = whole_table(results)
        means = [
            sign * statistics.fmean(row.fitnesses) if row.fitnesses and not row.failed
            else -math.inf
            for row in rows
        ]  # fmt: skip
        margins = [goal.margin(row) for goal in goals for row in rows]
        ranked.append(
            Ranked(candidate, results, rows, sign * min(means),
                   min(margins) if goals else None, sum(m < 0 for m in margins) if goals else None)
        )  # fmt: skip
    return sorted(ranked, key=lambda r: (-(r.margin or 0.0), -sign * r.score))


CSV_COLUMNS = ("table_version", "candidate", "cell", "engine", "seeds", "failed")


def write_csv(
    path: Path,
    table: PerturbationTable,
    tables: Sequence[tuple[Candidate, Sequence[CellResult]]],
) -> None:
    """One row per candidate, cell and engine: the table's version, then each metric's median
    and quartiles (a rate: its value). Written whole or not at all."""
    header = list(CSV_COLUMNS)
    for metric in table.metrics:
        header += [metric] if is_rate(metric) else [
            f"{metric}_median", f"{metric}_q25", f"{metric}_q75"]  # fmt: skip
    rows = []
    for candidate, results in tables:
        for result in results:
            row: list[Any] = [table.version, candidate.label, result.cell, result.engine,
                              len(result.samples) + result.failed, result.failed]  # fmt: skip
            for metric in table.metrics:
                median, low, high = result.summary(metric)
                row += [median] if is_rate(metric) else [median, low, high]
            rows.append(row)
    write_rows(path, header, rows)


RANKING_COLUMNS = (
    "rank", "target", "candidate", "goals_missed", "goal_margin", "meets_goals", "score"
)  # fmt: skip


def write_ranking(path: Path, ranked: Sequence[Ranked]) -> None:
    """One row per candidate, best first: its rank, the target naming it to another command
    (so a study chains a re-check into a race without reading the display), its label, the
    (goal, engine) pairs it misses, its goal margin and whether it meets every goal (empty
    without goals), its score."""
    rows = [
        [number, r.candidate.target, r.candidate.label]
        + (["", "", ""] if r.missed is None else [r.missed, r.margin, r.missed == 0])
        + [r.score]
        for number, r in enumerate(ranked, start=1)
    ]
    write_rows(path, list(RANKING_COLUMNS), rows)


def write_rows(path: Path, header: list[str], rows: list[list[Any]]) -> None:
    """A CSV written whole or not at all (a killed run leaves no half-written file)."""
    with written_whole(path) as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)


def figure(
    candidate: Candidate,
    table: PerturbationTable,
    results: Sequence[CellResult],
    speed: str,
    fell: str,
) -> Figure:
    """Per cell and engine: the median of ``speed`` with its interquartile range (top) and the
    rate of ``fell`` (bottom); a cell left out on an engine is marked so, without a bar."""
    from matplotlib.figure import Figure

    cells = [c.name for c in table.cells]
    engines = list(dict.fromkeys(r.engine for r in results))
    by_key = {(r.cell, r.engine): r for r in results}
    fig = Figure(figsize=(8.0, 5.6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    width = 0.8 / max(1, len(engines))
    where = np.arange(len(cells))
    no_bar = (math.nan, math.nan, math.nan)  # a cell left out on an engine (inert there)
    for k, engine in enumerate(engines):
        offset = where - 0.4 + width * (k + 0.5)
        rows = [by_key.get((c, engine)) for c in cells]
        stats = [row.summary(speed) if row is not None else no_bar for row in rows]
        median = np.array([s[0] for s in stats])
        spread = np.array([[s[0] - s[1] for s in stats], [s[2] - s[0] for s in stats]])
        top.bar(offset, median, width, yerr=spread, capsize=2, label=engine)
        falls = [row.summary(fell)[0] if row is not None else math.nan for row in rows]
        bottom.bar(offset, falls, width)
        for place, row in zip(offset, rows, strict=True):
            if row is None:
                top.annotate("left out", (place, 0), xytext=(0, 4), textcoords="offset points",
                             ha="center", va="bottom", rotation=90, fontsize="x-small",
                             color="grey")  # fmt: skip
    top.set_ylabel(f"{speed} (median, IQR)")
    top.set_title(f"{candidate.label}: perturbation table {table.version}", fontsize="medium")
    top.legend(fontsize="small")
    top.grid(alpha=0.3, axis="y")
    bottom.set_ylabel(f"{fell} rate")
    bottom.set_ylim(0, 1)
    bottom.grid(alpha=0.3, axis="y")
    bottom.set_xticks(where, cells, rotation=30, ha="right", fontsize="small")
    return fig


def figure_metrics(metrics: Sequence[str], version: str) -> tuple[str, str]:
    """What the figures draw: a table's first metric (its speed) against its first fall rate
    ('fell...'); ConfigError where table ``version`` has none, so that a figure that cannot
    be drawn is refused before any work."""
    fell = next((m for m in metrics if is_rate(m)), None)
    if fell is None:
        raise ConfigError(
            f"table {version} has no fall rate (metrics: {', '.join(metrics)}); --figure draws "
            f"{metrics[0]} against a 'fell' rate"
        )
    return metrics[0], fell


def check_changes(changes: Mapping[str, Any], table: PerturbationTable) -> None:
    """ConfigError where a change to the candidates' parameters names one the table sets in
    every cell (it would change nothing) or the engine (--engines chooses those)."""
    if "backend" in changes:  # engine_param's: every cell runs on each of --engines
        value = changes["backend"]
        raise ConfigError(
            f"--set backend={value}: robustness runs every engine in --engines; use --engines "
            f"{value}"
        )
    fixed = [name for name in changes if name in table.common]
    if fixed:
        name = fixed[0]
        raise ConfigError(
            f"--set {name}={changes[name]}: table {table.version} sets {name}="
            f"{table.common[name]!r} in every cell, so the change would do nothing; accepted: "
            f"the candidate's other parameters (the table sets {', '.join(table.common)})"
        )


def check_space_kept(
    candidates: Sequence[Candidate], changes: Mapping[str, Any], info: ProblemInfo
) -> None:
    """ConfigError where ``changes`` to the candidates' parameters change a candidate's space
    (replay.check_space): its vector would be evaluated as a point it is not."""
    if not changes:
        return
    seen: set[str] = set()
    for candidate in candidates:
        key = repr(sorted(candidate.params.items()))
        if key not in seen:  # one build per distinct parameters (a run's --top K share them)
            seen.add(key)
            changed = resolve(info.params, {**candidate.params, **changes}, info.name)
            check_space(changes, space_of(info, candidate.params), space_of(info, changed))


def select_cells(table: PerturbationTable, names: Sequence[str] | None) -> PerturbationTable:
    """The table restricted to the named cells, in table order (all when names is None)."""
    if names is None:
        return table
    known = [cell.name for cell in table.cells]
    unknown = [name for name in names if name not in known]
    if unknown:
        raise ConfigError(
            f"no perturbation {unknown[0]!r} in table {table.version}; accepted: "
            + ", ".join(known)
        )
    cells = tuple(cell for cell in table.cells if cell.name in names)
    return replace(table, cells=cells)  # every other field (only_when too) kept
