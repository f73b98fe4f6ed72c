"""A search design's result over several searches: each search's chosen candidate over the
same perturbation table (the CSV `metaopt robustness --csv` writes), summarised per engine as
the median over the searches of each whole-table figure. A search is one chaotic trajectory,
so a design is judged by such medians over its seeds, not by its luckiest search."""

from __future__ import annotations

import csv
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from metaopt.assessment.robustness import (
    CSV_COLUMNS,
    WHOLE_TABLE,
    Goal,
    figure_metrics,
    write_rows,
)
from metaopt.errors import ConfigError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: the suffixes of a metric's columns (a rate, e.g. 'fell', has one column of its own name)
_SPREAD = ("_q25", "_q75")


@dataclass(frozen=True)
class SearchTable:
    """One search's chosen candidate over a table: the whole-table figures per engine
    (``figures[engine][metric]``: a metric's median, a rate's value) and its failed
    evaluations per engine."""

    source: str
    candidate: str
    version: str
    figures: dict[str, dict[str, float]]
    failed: dict[str, int]

    @property
    def metrics(self) -> tuple[str, ...]:
        """The table's metrics in its column order ('speed', '|drift|', 'fell', ...)."""
        return tuple(next(iter(self.figures.values())))

    def on_metrics(self, metrics: Sequence[str]) -> SearchTable:
        """This table with only ``metrics``' figures, in that order."""
        figures = {
            engine: {m: values[m] for m in metrics} for engine, values in self.figures.items()
        }
        return replace(self, figures=figures)


def read_table(path: Path) -> SearchTable:
    """The whole-table rows of the one candidate in a `metaopt robustness --csv` file;
    ConfigError naming the file and what is wrong otherwise."""
    tables = read_tables(path)
    if len(tables) != 1:
        raise ConfigError(
            f"{path}: holds {len(tables)} candidates ({', '.join(t.candidate for t in tables)}); "
            "give each search's final table, of its one chosen candidate"
        )
    return tables[0]


def read_tables(path: Path) -> list[SearchTable]:
    """The whole-table rows of every candidate in a `metaopt robustness --csv` file, in the
    file's order (its ranking's); ConfigError naming the file and what is wrong otherwise."""
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            header = reader.fieldnames or []
            rows = list(reader)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise ConfigError(f"{path}: cannot read it as CSV: {error}") from None
    if list(header[: len(CSV_COLUMNS)]) != list(CSV_COLUMNS):
        raise ConfigError(
            f"{path}: not a robustness table (its columns start {', '.join(header[:3])}); "
            "give the CSV `metaopt robustness --csv` writes"
        )
    metrics = [c.removesuffix("_median") for c in header[len(CSV_COLUMNS):]
               if not c.endswith(_SPREAD)]  # fmt: skip
    totals: dict[str, list[dict[str, str]]] = {}
    for row in rows:
        if row["cell"] == WHOLE_TABLE:
            totals.setdefault(row["candidate"], []).append(row)
    if not totals:
        raise ConfigError(f"{path}: holds no candidate's whole-table rows")
    try:
        return [
            SearchTable(
                str(path), candidate, found[0]["table_version"],
                {row["engine"]: {m: float(row[m if m in row else f"{m}_median"])
                                 for m in metrics} for row in found},
                {row["engine"]: int(row["failed"]) for row in found},
            )
            for candidate, found in totals.items()
        ]  # fmt: skip
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{path}: a whole-table value is not a number: {error}") from None


def alike(tables: Sequence[SearchTable]) -> list[SearchTable]:
    """The tables on the metrics they all have (in the first's order), once checked to be of
    one table version on the same engines (ConfigError otherwise): medians over searches
    compare like with like. A table written before a metric joined its version (nao-walk-3's
    time_to_fall) is compared with later ones on the metrics it has."""
    first = tables[0]
    for table in tables[1:]:
        for what, mine, theirs in (
            ("table version", first.version, table.version),
            ("engines", sorted(first.figures), sorted(table.figures)),
        ):
            if mine != theirs:
                raise ConfigError(
                    f"{table.source} has {what} {theirs}, {first.source} {mine}: give tables "
                    "of one perturbation table version, on the same engines"
                )
    shared = [m for m in first.metrics if all(m in table.metrics for table in tables)]
    if not shared:
        raise ConfigError(
            f"{', '.join(t.source for t in tables)}: no metric in every table; give tables "
            "written by `metaopt robustness --csv` over one perturbation table"
        )
    return [table.on_metrics(shared) for table in tables]


@dataclass(frozen=True)
class Medians:
    """Per engine, each metric's median over the searches (NaN where none measured it), its
    standard deviation over them (how far one search's figure strays from the design's: NaN
    where fewer than two measured it), and the failed evaluations of all the searches."""

    count: int
    figures: dict[str, dict[str, float]]
    spread: dict[str, dict[str, float]]
    failed: dict[str, int]


def medians(tables: Sequence[SearchTable]) -> Medians:
    """The medians and standard deviations over the searches, computed once for the
    display, the verdict and the CSV."""
    figures: dict[str, dict[str, float]] = {}
    spread: dict[str, dict[str, float]] = {}
    for engine in tables[0].figures:
        figures[engine], spread[engine] = {}, {}
        for metric in tables[0].metrics:
            values = [t.figures[engine][metric] for t in tables]
            values = [v for v in values if not math.isnan(v)]
            figures[engine][metric] = statistics.median(values) if values else math.nan
            spread[engine][metric] = statistics.stdev(values) if len(values) > 1 else math.nan
    failed = {engine: sum(t.failed[engine] for t in tables) for engine in figures}
    return Medians(len(tables), figures, spread, failed)


@dataclass(frozen=True)
class PairedDifferences:
    """Searches paired by seed with a baseline's (the i-th table with the i-th baseline): per
    engine and metric, the median of the differences (search minus baseline), how many pairs
    went up and down, and the two-sided sign test's p-value of that split (ties left out)."""

    count: int
    median: dict[str, dict[str, float]]
    up: dict[str, dict[str, int]]
    down: dict[str, dict[str, int]]

    def sign_test(self, engine: str, metric: str) -> float:
        """P(a split at least this uneven | up and down equally likely), ties left out."""
        up, down = self.up[engine][metric], self.down[engine][metric]
        pairs = up + down
        tail = sum(math.comb(pairs, k) for k in range(min(up, down) + 1)) / 2**pairs
        return min(1.0, 2 * tail)


def paired_differences(
    tables: Sequence[SearchTable], baselines: Sequence[SearchTable]
) -> PairedDifferences:
    """The searches against their baselines, pair by pair (the same seeds, another design or
    more time): paired, the seed's own luck cancels, which medians of each side keep."""
    if len(tables) != len(baselines):
        raise ConfigError(
            f"{len(tables)} tables against {len(baselines)}: give one --against table per "
            "table, in the same order (the i-th of each on the same seed)"
        )
    compared = alike([*tables, *baselines])
    tables, baselines = compared[: len(tables)], compared[len(tables) :]
    median: dict[str, dict[str, float]] = {}
    up: dict[str, dict[str, int]] = {}
    down: dict[str, dict[str, int]] = {}
    for engine in tables[0].figures:
        median[engine], up[engine], down[engine] = {}, {}, {}
        for metric in tables[0].metrics:
            differences = [
                t.figures[engine][metric] - b.figures[engine][metric]
                for t, b in zip(tables, baselines)
            ]
            differences = [d for d in differences if not math.isnan(d)]
            median[engine][metric] = statistics.median(differences) if differences else math.nan
            up[engine][metric] = sum(d > 0 for d in differences)
            down[engine][metric] = sum(d < 0 for d in differences)
    return PairedDifferences(len(tables), median, up, down)


def missed_goals(figures: dict[str, float], failed: int, goals: Sequence[Goal]) -> list[Goal]:
    """The goals one engine's figures miss (every goal, where an evaluation failed)."""
    return [goal for goal in goals if goal.margin_in(figures, failed) < 0]


def within_goals(tables: Sequence[SearchTable], goals: Sequence[Goal]) -> list[SearchTable]:
    """The searches whose candidate meets every goal on every engine."""
    return [
        t
        for t in tables
        if not any(missed_goals(f, t.failed[e], goals) for e, f in t.figures.items())
    ]


def figure(tables: Sequence[SearchTable], summary: Medians, goals: Sequence[Goal]) -> Figure:
    """One panel per engine: each search's candidate at its fall rate and median speed (the
    table's first metric), filled where it meets every goal on every engine, the median over
    the searches as a cross, and the goals on those two metrics as dashed bounds; so a
    design's spread is seen against the corner the goal asks for. ConfigError where the
    table has no fall rate."""
    from matplotlib.figure import Figure

    first = tables[0]
    try:
        speed, fell = figure_metrics(first.metrics, first.version)
    except ConfigError as error:
        raise ConfigError(f"{first.source}: {error}") from None
    within = {id(t) for t in within_goals(tables, goals)} if goals else set()
    engines = list(first.figures)
    fig = Figure(figsize=(3.2 * len(engines), 3.4), layout="constrained")
    axes = fig.subplots(1, len(engines), sharex=True, sharey=True, squeeze=False)[0]
    for ax, engine in zip(axes, engines, strict=True):
        for meets in (False, True) if goals else (False,):  # no goals: none to meet
            chosen = [t for t in tables if (id(t) in within) == meets]
            ax.scatter([t.figures[engine][fell] for t in chosen],
                       [t.figures[engine][speed] for t in chosen],
                       s=22, facecolors="tab:green" if meets else "none",
                       edgecolors="tab:green" if meets else "tab:blue",
                       label="meets every goal" if meets else "a search")  # fmt: skip
        ax.scatter([summary.figures[engine][fell]], [summary.figures[engine][speed]], marker="x",
                   s=70, color="black", label=f"median of {summary.count}")  # fmt: skip
        for goal in goals:
            if goal.metric == speed:
                ax.axhline(goal.threshold, color="grey", linestyle="--", linewidth=1)
            elif goal.metric == fell:
                ax.axvline(goal.threshold, color="grey", linestyle="--", linewidth=1)
        ax.set_title(engine, fontsize="medium")
        ax.set_xlabel(f"{fell} rate")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(f"{speed} (median over the table)")
    axes[-1].legend(fontsize="x-small", loc="lower right")
    fig.suptitle(f"{len(tables)} searches over perturbation table {first.version}",
                 fontsize="medium")  # fmt: skip
    return fig


def write_medians(
    path: Path,
    tables: Sequence[SearchTable],
    summary: Medians,
    paired: PairedDifferences | None = None,
) -> None:
    """One row per search and engine, then one per engine for the median over the searches
    (search 'median of N') and one for the standard deviation over them ('sd over N'), and
    with ``paired`` one per engine for the median paired difference (search 'median
    difference of N pairs'). Written whole or not at all."""
    metrics = tables[0].metrics
    rows = [
        [t.source, t.candidate, engine, t.failed[engine], *(figures[m] for m in metrics)]
        for t in tables
        for engine, figures in t.figures.items()
    ]
    rows += [
        [f"median of {summary.count}", "", engine, summary.failed[engine],
         *(figures[m] for m in metrics)]
        for engine, figures in summary.figures.items()
    ]  # fmt: skip
    rows += [
        [f"sd over {summary.count}", "", engine, "", *(spread[m] for m in metrics)]
        for engine, spread in summary.spread.items()
    ]
    if paired is not None:
        rows += [
            [f"median difference of {paired.count} pairs", "", engine, "",
             *(figures[m] for m in metrics)]
            for engine, figures in paired.median.items()
        ]  # fmt: skip
    write_rows(path, ["search", "candidate", "engine", "failed", *metrics], rows)
