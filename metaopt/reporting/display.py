"""Everything metaopt shows in the terminal: plugin tables, the progress bar, result tables."""

from __future__ import annotations

import inspect
import math
import statistics
import time
from collections.abc import Sequence
from typing import Any

from rich import box
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table
from rich.text import Text

from metaopt.assessment.replay import Replay, ReplaySource, SeedReplay
from metaopt.assessment.robustness import is_rate, summarize
from metaopt.assessment.search_medians import (
    Medians,
    PairedDifferences,
    SearchTable,
    missed_goals,
    within_goals,
)
from metaopt.params import Param
from metaopt.reporting.history import RunHistory
from metaopt.reporting.plain import plain, table_title
from metaopt.reporting.recent import RecentFigures
from metaopt.running import RunResult, common_seeds_mode
from metaopt.storage.run_store import CandidateRecord, EvaluationCounts, RunRecord

PROGRESS_REFRESH = 0.1


def format_number(value: float | None) -> str:
    """Compact, precise enough for fitness values and parameters."""
    if value is None:
        return "-"
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return f"{value:.6g}"


def params_table(title: str, params: Sequence[Param]) -> Table:
    """A table of declared parameters: name, type, default, range, meaning."""
    table = Table(title=title, title_justify="left", show_lines=False)
    for column in ("parameter", "type", "default", "range", "meaning"):
        table.add_column(column, overflow="fold")
    for p in params:
        table.add_row(*_plain(p.name, p.type_name, str(p.default), p.range_text(), p.help))
    return table


def _plain(*cells: str) -> list[Text]:
    """A row's cells of data (names, labels, settings, paths, messages), each as typed."""
    return [plain(cell) for cell in cells]


def plugin_overview(kind: str, infos: Sequence, sources: Sequence[str]) -> Table:
    """Every plugin of a kind: its name, summary and source, then each parameter's name, type,
    default, range and meaning."""
    table = Table(title=kind, title_justify="left")
    table.add_column("name / parameter", no_wrap=True)
    table.add_column("type")
    table.add_column("default")
    table.add_column("range", overflow="fold")
    table.add_column("summary / meaning", overflow="fold")
    for info, source in zip(infos, sources):
        summary = Text.assemble(info.summary, " ", (f"(from {source})", "dim"))
        if getattr(info, "unavailable", ""):
            summary = Text.assemble(
                ("unavailable:", "bold red"), " ", info.unavailable, "\n", summary
            )
        table.add_row(plain(info.name, "bold cyan"), "", "", "", summary)
        for p in getattr(info, "params", ()):
            table.add_row(
                *_plain(f"  {p.name}", p.type_name, str(p.default), p.range_text(), p.help)
            )
        table.add_section()
    return table


class RichProgress:
    """The run loop's progress observer: a rich bar with evaluations, best so far, rate, ETA."""

    def __init__(self, console: Console, label: str) -> None:
        self._bar = Progress(
            TextColumn("{task.description}", style="bold", markup=False),  # a label is data
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("best {task.fields[best]}"),
            TextColumn("{task.fields[rate]} eval/s"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=console,
            transient=False,
        )
        self._label = label
        self._task = None
        self._last_refresh = 0.0
        self._started = 0.0
        self._first_done = 0

    def __enter__(self) -> RichProgress:
        self._bar.__enter__()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._bar.__exit__(*exc_info)

    def start(self, total: int, done: int) -> None:
        """Create the bar."""
        self._task = self._bar.add_task(
            self._label, total=total, completed=done, best="-", rate="-"
        )
        self._started = time.perf_counter()
        self._first_done = done

    def update(self, done: int, best: float | None) -> None:
        """Refresh at most every PROGRESS_REFRESH seconds (cheap evaluations come in millions)."""
        now = time.perf_counter()
        if now - self._last_refresh < PROGRESS_REFRESH and done < self._bar.tasks[0].total:
            return
        self._last_refresh = now
        elapsed = max(now - self._started, 1e-9)
        rate = (done - self._first_done) / elapsed
        self._bar.update(self._task, completed=done, best=format_number(best), rate=f"{rate:,.0f}")


def _left_out(failed: int, screened: int) -> str:
    """'(k failed)', with ', s screened' where a run screened (metaopt run --screen)."""
    return f"({failed} failed" + (f", {screened} screened)" if screened else ")")


def result_table(result: RunResult, db_path: str, seed: int, startup_time: float = 0.0) -> Table:
    """The summary printed after a run (its wall time includes starting the workers)."""
    table = Table(title=f"Run {result.run_id} ({result.status})", title_justify="left")
    table.add_column("", style="bold")
    table.add_column("value")
    table.add_row(*_plain("best fitness", format_number(result.best_fitness)))
    for name in _shown_metrics(result.best_metrics, result.key_metrics):
        table.add_row(*_plain(f"  {name}", format_number(result.best_metrics[name])))
    if result.best_x is not None:
        for name, value in zip(result.names, result.best_x):
            table.add_row(*_plain(f"  {name}", format_number(float(value))))
    left_out = _left_out(result.failed, result.screened)
    table.add_row(*_plain("evaluations", f"{result.evaluations} {left_out}"))
    starting = f" (of which starting workers {startup_time:.2f} s)" if startup_time >= 0.01 else ""
    table.add_row(*_plain("wall time", f"{result.wall_time:.2f} s{starting}"))
    table.add_row(*_plain("seed", str(seed)))
    table.add_row(*_plain("run id", f"{result.run_id}  (in {db_path})"))
    return table


def _shown_metrics(metrics: dict[str, float], key_metrics: Sequence[str]) -> list[str]:
    keys = [k for k in key_metrics if k in metrics]
    return keys + [k for k in metrics if k not in keys]


def _replay_setting(source: ReplaySource, params: dict[str, Any]) -> str:
    """The problem parameters a replay changed, 'k=v, ...', or 'as stored'."""
    changed = {k: v for k, v in params.items() if source.problem_params.get(k) != v}
    return ", ".join(f"{k}={v}" for k, v in changed.items()) or "as stored"


def _stored_scores(source: ReplaySource) -> dict[str, float | None] | None:
    """What the replayed candidate scored when stored, fitness first; None for a candidate
    kept without a score (a problem's stored candidate): its tables have no 'stored' column."""
    if source.fitness is None and not source.metrics:
        return None
    return {"fitness": source.fitness, **(source.metrics or {})}


def replay_table(replay: Replay) -> Table:
    """`metaopt replay`: the stored metrics beside the replayed ones."""
    source = replay.source
    table = Table(
        title=table_title(
            f"{source.label} replayed ({_replay_setting(source, replay.problem_params)})"
        ),
        title_justify="left",
    )
    stored = _stored_scores(source)
    for column in ("", *(["stored"] if stored is not None else []), "replayed"):
        table.add_column(column, justify="right" if column else "left")
    replayed = replay.replayed
    failed = replayed.fitness is None
    names = [*(stored or {"fitness": None}), *replayed.metrics]
    for name in dict.fromkeys(names):
        value = replayed.fitness if name == "fitness" else replayed.metrics.get(name)
        shown = ("failed" if name == "fitness" else "-") if failed else format_number(value)
        before = [] if stored is None else [format_number(stored.get(name))]
        table.add_row(*_plain(name, *before, shown))
    return table


def settings_text(settings: dict[str, Any]) -> str:
    """A run's scheduling settings in a few words: 'sync', 'async, resample 3 (mean), limit
    2 s, max time 600 s', 'sync, started from stride_mujoco (20 points within 0.05)'."""
    parts = [settings.get("mode", "sync")]
    if settings.get("batch"):
        parts.append(f"batch {settings['batch']}")
    if settings.get("resample", 1) > 1:
        parts.append(f"resample {settings['resample']} ({settings.get('aggregate', 'mean')})")
    common = common_seeds_mode(settings.get("common_seeds", "off"))
    if common != "off":
        parts.append("common seeds" + (" per batch" if common == "batch" else ""))
    if settings.get("screen"):
        parts.append("screened")
    if settings.get("time_limit") is not None:
        parts.append(f"limit {settings['time_limit']:g} s")
    if settings.get("max_time") is not None:
        parts.append(f"max time {settings['max_time']:g} s")
    if settings.get("start") is not None:
        parts.append(
            f"started from {settings.get('start_from') or 'a given point'} "
            f"({settings['start_points']} points within {settings['start_spread']:g})"
        )
    return ", ".join(parts)


def run_summary(
    run: RunRecord, counts: EvaluationCounts, best: float | None, experiment: str | None
) -> dict[str, Any]:
    """One run of `metaopt runs` as named fields (its CSV and JSON form)."""
    return {
        "id": run.id,
        "optimizer": run.optimizer,
        "problem": run.problem,
        "backend": run.problem_params.get("backend"),
        "experiment": experiment,
        "settings": settings_text(run.settings),
        "seed": run.seed,
        "evaluations": counts.stored,
        "budget": run.budget,
        "failed": counts.failed,
        "screened": counts.screened,
        "best": best,
        "status": run.status,
        "started": run.started_at,
    }


def runs_table(
    runs: Sequence[RunRecord],
    counts: dict[int, EvaluationCounts],
    best: dict[int, float | None],
    experiments: dict[int, str],
) -> Table:
    """`metaopt runs`: one row per run (cells fold rather than being cut in a narrow
    terminal), with a screened column where a listed run screened (metaopt run --screen)."""
    screened = any(counts[run.id].screened for run in runs)
    headers = ("id", "optimizer", "problem", "backend", "experiment", "settings", "seed",
               "evals", "failed", *(("screened",) if screened else ()), "best", "status",
               "started")  # fmt: skip
    rows = []
    for run in runs:
        fields = run_summary(run, counts[run.id], best[run.id], experiments.get(run.id))
        rows.append((
            str(run.id), run.optimizer, run.problem, fields["backend"] or "-",
            fields["experiment"] or "-", fields["settings"], str(run.seed),
            f"{fields['evaluations']}/{run.budget}", str(fields["failed"]),
            *((str(fields["screened"]),) if screened else ()),
            format_number(best[run.id]), run.status, run.started_at[:16].replace("T", " "),
        ))  # fmt: skip
    table = Table(title="runs", title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
    for header in headers:  # cells fold in a narrow terminal: every column stays
        table.add_column(header, overflow="fold")
    for row in rows:
        table.add_row(*_plain(*row))
    return table


def run_document(
    run: RunRecord,
    counts: EvaluationCounts,
    best: CandidateRecord | None,
    recent: RecentFigures | None = None,
) -> dict[str, Any]:
    """`metaopt show RUN --format json|csv`: everything stored about one run, best included,
    and the figures of its last evaluations."""
    return {
        "id": run.id,
        "status": run.status,
        "message": run.message,
        "optimizer": run.optimizer,
        "optimizer_params": run.optimizer_params,
        "problem": run.problem,
        "problem_params": run.problem_params,
        "sense": run.sense,
        "settings": run.settings,
        "seed": run.seed,
        "budget": run.budget,
        "evaluations": counts.stored,
        "failed": counts.failed,
        "screened": counts.screened,
        "started_at": run.started_at,
        "ended_at": run.ended_at,
        "wall_time": run.wall_time,
        "best": None
        if best is None
        else {
            "fitness": best.fitness,
            "candidate": best.number,
            "evaluations": [e.index for e in best.samples],
            "metrics": best.metrics,
            "x": dict(zip([v["name"] for v in run.space], best.x.tolist())),
        },
        "recent": None if recent is None else recent_document(recent),
        "versions": run.versions,
    }


def recent_document(recent: RecentFigures) -> dict[str, Any]:
    """A run's last evaluations as data: their range, fitness quartiles, and each metric's
    median or share ({"median": v} or {"share": v}, with the evaluations that report it)."""
    quartiles = recent.fitness_quartiles
    return {
        "evaluations": [recent.first, recent.last],
        "count": recent.evaluations,
        "succeeded": recent.succeeded,
        "screened": recent.screened,
        "fitness": None
        if quartiles is None
        else dict(zip(("lower_quartile", "median", "upper_quartile"), quartiles)),
        "metrics": {
            m.name: {"share" if m.is_share else "median": m.value, "count": m.count}
            for m in recent.metrics
        },
    }


def run_detail(
    run: RunRecord,
    counts: EvaluationCounts,
    best: CandidateRecord | None,
    recent: RecentFigures | None = None,
) -> Table:
    """`metaopt show RUN`: everything stored about one run, and where its last evaluations
    stand beside its best."""
    table = Table(title=f"run {run.id}", title_justify="left", show_header=False)
    table.add_column("", style="bold", overflow="fold")
    table.add_column("", overflow="fold")
    table.add_row(*_plain("status", run.status + (f" ({run.message})" if run.message else "")))
    table.add_row(*_plain("optimizer", run.optimizer))
    for name, value in run.optimizer_params.items():
        table.add_row(*_plain(f"  {name}", str(value)))
    table.add_row(*_plain("problem", f"{run.problem} ({run.sense})"))
    for name, value in run.problem_params.items():
        table.add_row(*_plain(f"  {name}", str(value)))
    table.add_row(*_plain("settings", settings_text(run.settings)))
    table.add_row(*_plain("seed", str(run.seed)))
    left_out = _left_out(counts.failed, counts.screened)
    table.add_row(*_plain("evaluations", f"{counts.stored} of {run.budget} {left_out}"))
    table.add_row(*_plain("started / ended", f"{run.started_at} / {run.ended_at or '-'}"))
    table.add_row(*_plain("wall time", "-" if run.wall_time is None else f"{run.wall_time:.2f} s"))
    if best is not None:
        table.add_row(*_plain("best fitness", f"{format_number(best.fitness)} ({best.describe()})"))
        for name, value in best.metrics.items():
            table.add_row(*_plain(f"  {name}", format_number(value)))
        for variable, value in zip(run.space, best.x):
            table.add_row(*_plain(f"  {variable['name']}", format_number(float(value))))
    if recent is not None:
        _recent_rows(table, recent)
    table.add_row(*_plain("versions", ", ".join(f"{k} {v}" for k, v in run.versions.items())))
    return table


def _recent_rows(table: Table, recent: RecentFigures) -> None:
    """The last evaluations' rows of `metaopt show`: fitness median and quartiles, then each
    metric's median, or its share of evaluations where it is 1 (a flag such as a fall)."""
    failed = recent.evaluations - recent.succeeded - recent.screened
    heading = f"last {recent.evaluations} evaluations ({recent.first}-{recent.last})"
    if recent.fitness_quartiles is None:
        table.add_row(*_plain(heading, f"fitness: all {failed} failed"))
        return
    lower, median, upper = recent.fitness_quartiles
    failures = f", {failed} failed" if failed else ""
    if recent.screened:  # their fitness is unknown, and worse than the completed ones'
        failures += f"; {recent.screened} screened, the figures are the other {recent.succeeded}"
    table.add_row(
        *_plain(
            heading,
            f"median fitness {format_number(median)} (quartiles {format_number(lower)} to "
            f"{format_number(upper)}{failures})",
        )
    )
    for metric in recent.metrics:
        # a metric some evaluations lack (nao-walk's flight: none after a fall) says its count
        among = f" of {metric.count}" if metric.count != recent.succeeded else ""
        if metric.is_share:
            table.add_row(*_plain(f"  {metric.name}", f"{metric.value:.0%} at 1 (share{among})"))
        else:
            table.add_row(
                *_plain(f"  {metric.name}", f"{format_number(metric.value)} (median{among})")
            )


def history_table(run: RunRecord, history: RunHistory) -> Table:
    """`metaopt history RUN`: a row per window of evaluations: failures (and screened ones,
    where the run screened), fitness median and quartiles, the best so far, each shown
    metric's median or share (a share in %) and, asked for, the candidates' spread."""
    better = "higher" if run.sense == "maximize" else "lower"
    table = Table(
        title=f"run {run.id}: {history.window} evaluations a row ({better} fitness is better)",
        title_justify="left",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
    )
    screened = any(window.screened for window in history.windows)  # metaopt run --screen
    headers = ("evaluations", "failed", *(("screened",) if screened else ()), "median fitness",
               "quartiles", "best so far")  # fmt: skip
    for header in headers:
        table.add_column(header, justify="right")
    for name in history.metrics:
        header = plain(f"{name} ({history.kind(name)})")
        table.add_column(header, justify="right", overflow="fold")
    if history.spread:
        table.add_column("spread", justify="right")
    for window in history.windows:
        quartiles = window.fitness_quartiles
        cells = [
            f"{window.first}-{window.last}",
            str(window.evaluations - window.succeeded - window.screened),
            *((str(window.screened),) if screened else ()),
            "-" if quartiles is None else format_number(quartiles[1]),
            "-"
            if quartiles is None
            else f"{format_number(quartiles[0])} to {format_number(quartiles[2])}",
            format_number(window.best_so_far),
        ]
        for name in history.metrics:
            value = window.metrics[name]
            if value is None:
                cells.append("-")
            elif name in history.shares:
                cells.append(f"{value:.0%}")
            else:
                cells.append(format_number(value))
        if history.spread:
            cells.append("-" if window.spread is None else f"{window.spread:.4f}")
        table.add_row(*_plain(*cells))
    return table


def history_records(history: RunHistory) -> list[dict[str, Any]]:
    """A run's history as data, a record per window; a metric's key says whether its value is
    the window's median or its share at 1 (``fell_share``, ``speed_median``)."""
    records = []
    for window in history.windows:
        lower, median, upper = window.fitness_quartiles or (None, None, None)
        record: dict[str, Any] = {
            "first": window.first,
            "last": window.last,
            "evaluations": window.evaluations,
            "failed": window.evaluations - window.succeeded - window.screened,
            "screened": window.screened,
            "fitness_lower_quartile": lower,
            "fitness_median": median,
            "fitness_upper_quartile": upper,
            "best_so_far": window.best_so_far,
        }
        for name in history.metrics:
            record[f"{name}_{history.kind(name)}"] = window.metrics[name]
        if history.spread:
            record["spread"] = window.spread
        records.append(record)
    return records


def reflow(text: str) -> str:
    """A docstring-style description with its hard line breaks joined, so the terminal wraps it
    to its own width: paragraphs (blank-line separated) and list items ('- ', '* ') stay apart."""
    paragraphs = []
    for block in inspect.cleandoc(text).split("\n\n"):
        lines: list[str] = []
        for line in block.splitlines():
            stripped = line.strip()
            if lines and not stripped.startswith(("- ", "* ")):
                lines[-1] += " " + stripped
            else:
                lines.append(stripped)
        paragraphs.append("\n".join(lines))
    return "\n\n".join(paragraphs)


def robustness_table(
    label: str,
    version: str,
    results: Sequence,
    metrics: Sequence[str],
    totals: Sequence = (),
    left_out: Sequence[tuple[str, str, str]] = (),
) -> Table:
    """`metaopt robustness`: per perturbation and engine, each metric's median over the seeds
    (a rate: its value), with the first metric's interquartile range; then the ``totals``
    (per engine, over the whole table) below a line; the (cell, engine, reason) ``left_out``
    (inert there) named below the table."""
    inert: dict[tuple[str, str], list[str]] = {}
    for cell, engine, reason in left_out:
        inert.setdefault((engine, reason), []).append(cell)
    caption = "\n".join(f"left out on {engine} ({', '.join(cells)}): {reason}"
                         for (engine, reason), cells in inert.items())  # fmt: skip
    table = Table(title=table_title(f"{label}: perturbation table {version}"),
                  title_justify="left", caption=plain(caption, "table.caption") or None,
                  caption_justify="left")  # fmt: skip
    table.add_column("perturbation")
    table.add_column("engine")
    table.add_column("seeds", justify="right")
    table.add_column(plain(f"{metrics[0]} (median)"), justify="right")
    table.add_column("IQR", justify="right")
    _add_figure_columns(table, metrics[1:])
    for number, result in enumerate([*results, *totals]):
        if number == len(results):
            table.add_section()
        median, low, high = result.summary(metrics[0])
        cells = [f"{median:.3f}", f"{low:.3f} to {high:.3f}"]
        for metric in metrics[1:]:
            value = result.summary(metric)[0]
            cells.append(_figure_cell(value, ".0%" if is_rate(metric) else ".3f"))
        seeds = f"{len(result.samples)}" + (f" ({result.failed} failed)" if result.failed else "")
        table.add_row(*_plain(result.cell, result.engine, seeds, *cells))
    return table


def search_medians_table(tables: Sequence, summary: Medians) -> Table:
    """`metaopt robustness-summary`: each search's whole-table figures per engine (a metric's
    median, a rate's value), then per engine their median and standard deviation over the
    searches below a line."""
    first = tables[0]
    title = (f"{len(tables)} searches over perturbation table {first.version}: whole table per "
             "engine, and the median and sd over the searches")  # fmt: skip
    table = Table(title=table_title(title), title_justify="left")
    for name in ("search", "candidate", "engine"):
        table.add_column(name)
    _add_figure_columns(table, first.metrics)
    for search in tables:
        for engine, figures in search.figures.items():
            table.add_row(*_plain(search.source, search.candidate, _engine_cell(search, engine),
                          *_figure_cells(first.metrics, figures)))  # fmt: skip
    table.add_section()
    for label, per_engine in (
        (f"median of {summary.count}", summary.figures),
        (f"sd over {summary.count}", summary.spread),
    ):
        for engine, figures in per_engine.items():
            table.add_row(*_plain(label, "", engine, *_figure_cells(first.metrics, figures)))
    return table


def paired_differences_table(paired: PairedDifferences, metrics: Sequence[str]) -> Table:
    """`metaopt robustness-summary ... --against ...`: per engine and metric, the median of
    the pairs' differences (a rate's in percentage points), how many went up and down, and
    the sign test's p-value; a dash where no pair measured the metric (time_to_fall where
    none fell)."""
    table = Table(title=f"{paired.count} searches against their --against tables, pair by "
                  "pair: the median difference (pairs up / down, two-sided sign test p)",
                  title_justify="left")  # fmt: skip
    table.add_column("engine")
    _add_figure_columns(table, metrics)
    for engine, medians in paired.median.items():
        cells = []
        for metric in metrics:
            value = medians[metric]
            if math.isnan(value):
                cells.append("–")
                continue
            shown = f"{value * 100:+.1f} pp" if is_rate(metric) else f"{value:+.3f}"
            up, down = paired.up[engine][metric], paired.down[engine][metric]
            cells.append(f"{shown} ({up}↑ {down}↓, p {paired.sign_test(engine, metric):.2f})")
        table.add_row(*_plain(engine, *cells))
    return table


def goal_ranking_table(ranked: Sequence, goals: Sequence) -> Table:
    """`metaopt robustness-rank`: the candidates best first by their margin to the goals,
    each with the (goal, engine) pairs it misses, and per engine its whole-table figures and
    the goals it misses there."""
    first = ranked[0].table
    sources = {r.table.source for r in ranked}
    table = Table(title=table_title(f"candidates ranked over perturbation table {first.version} "
                                    f"by the goals {', '.join(map(str, goals))}"),
                  title_justify="left")  # fmt: skip
    columns = ["rank", *(["file"] if len(sources) > 1 else []), "candidate", "goals missed",
               "goal margin", "engine"]  # fmt: skip
    for name in columns:
        table.add_column(name, justify="right" if name in ("rank", "goals missed",
                                                            "goal margin") else "left")  # fmt: skip
    _add_figure_columns(table, first.metrics)
    table.add_column("misses")
    for number, entry in enumerate(ranked, start=1):
        if number > 1:
            table.add_section()
        candidate = entry.table
        for row, (engine, figures) in enumerate(candidate.figures.items()):
            head = [str(number), *([candidate.source] if len(sources) > 1 else []),
                    candidate.candidate, str(entry.missed), f"{entry.margin:+.3f}"]  # fmt: skip
            missed = missed_goals(figures, candidate.failed[engine], goals)
            table.add_row(*_plain(*(head if row == 0 else [""] * len(head)),
                          _engine_cell(candidate, engine), *_figure_cells(first.metrics, figures),
                          ", ".join(map(str, missed))))  # fmt: skip
    return table


def _add_figure_columns(table: Table, metrics: Sequence[str]) -> None:
    """A column per metric, headed by its name as typed ('(median)' after a metric's)."""
    for metric in metrics:
        table.add_column(plain(metric if is_rate(metric) else f"{metric} (median)"),
                         justify="right")  # fmt: skip


def _figure_cells(metrics: Sequence[str], figures: dict[str, float]) -> list[str]:
    """A table's whole-table figures as shown: a rate in %, a median to 3 decimals, a dash
    where none was measured."""
    return [_figure_cell(figures[m], ".1%" if is_rate(m) else ".3f") for m in metrics]


def _figure_cell(value: float, shown_as: str) -> str:
    """A figure in format ``shown_as``; a dash where nothing measured it (time_to_fall where
    none fell, a spread over fewer than two searches)."""
    return "–" if math.isnan(value) else format(value, shown_as)


def _engine_cell(table: SearchTable, engine: str) -> str:
    """The engine's name, with its failed evaluations where there are any."""
    failed = table.failed[engine]
    return engine + (f" ({failed} failed)" if failed else "")


def search_medians_verdict(tables: Sequence, summary: Medians, goals: Sequence) -> str:
    """Which goals the medians over the searches meet per engine, and how many of the
    searches' own candidates meet every goal on every engine."""
    lines = [f"the median of {summary.count} searches against the goals "
             f"{', '.join(map(str, goals))}:"]  # fmt: skip
    for engine, figures in summary.figures.items():
        lines.append(_verdict_line(engine, figures, summary.failed[engine], goals))
    within = [t.source for t in within_goals(tables, goals)]
    lines.append(f"searches whose candidate meets every goal on every engine: {len(within)} of "
                 f"{len(tables)}" + (f" ({', '.join(within)})" if within else ""))  # fmt: skip
    return "\n".join(lines)


def robustness_ranking(
    ranked: Sequence, version: str, metrics: Sequence[str], goals: Sequence = ()
) -> Table:
    """`metaopt robustness` with several candidates: best first, each with its score (the
    worst engine's mean fitness over the table; with goals, first the (goal, engine) pairs it
    misses and its smallest margin to a goal) and, per engine over the whole table, the mean
    fitness, the first metric's median and the rates."""
    rates = [m for m in metrics if is_rate(m)]
    by = f" by the goals {', '.join(map(str, goals))}" if goals else ""
    title = f"candidates ranked over perturbation table {version}{by}"
    table = Table(title=table_title(title), title_justify="left")
    margin = ["goals missed", "goal margin"] if goals else []
    for name in ("rank", "candidate", *margin, "score", "engine", "fitness (mean)",
                 f"{metrics[0]} (median)", *rates):  # fmt: skip
        justify = "left" if name in ("candidate", "engine") else "right"
        table.add_column(plain(name), justify=justify)
    for number, entry in enumerate(ranked, start=1):
        if number > 1:
            table.add_section()
        for row, total in enumerate(entry.totals):
            mean = statistics.fmean(total.fitnesses) if total.fitnesses else math.nan
            shown_margin = [str(entry.missed), f"{entry.margin:+.3f}"] if goals else []
            first = (
                (str(number), entry.candidate.label, *shown_margin, f"{entry.score:.3f}")
                if row == 0
                else ("",) * (3 + len(margin))
            )
            speed = total.summary(metrics[0])[0]
            table.add_row(*_plain(*first, total.engine, f"{mean:.3f}", f"{speed:.3f}",
                          *(f"{total.summary(m)[0]:.0%}" for m in rates)))  # fmt: skip
    return table


def goal_verdict(label: str, totals: Sequence, goals: Sequence) -> str:
    """Which goals a candidate meets over each engine's whole table, one line per engine:
    'mujoco: meets all', 'pybullet: misses fell<=0.05 (0.073)' (judged as Goal.margin does,
    a goal's only_when rate included)."""
    lines = [f"{label} against the goals {', '.join(map(str, goals))}:"]
    for total in totals:
        names = dict.fromkeys(n for g in goals for n in (g.metric, g.only_when) if n is not None)
        figures = {name: total.summary(name)[0] for name in names}
        lines.append(_verdict_line(total.engine, figures, total.failed, goals))
    return "\n".join(lines)


def _verdict_line(engine: str, figures: dict[str, float], failed: int, goals: Sequence) -> str:
    """'  mujoco: meets all' or '  ode: misses speed>=0.44 (0.347)': the goals an engine's
    figures (per metric) miss, by missed_goals."""
    missed = [f"{g} ({figures[g.metric]:.3g})" for g in missed_goals(figures, failed, goals)]
    return f"  {engine}: " + (f"misses {', '.join(missed)}" if missed else "meets all")


def replay_seeds_table(replay: SeedReplay) -> Table:
    """`metaopt replay --seeds N`: the stored candidate beside the median and interquartile
    range (for 'fell': the rate) of its re-evaluations over N seeds."""
    source = replay.source
    done = [o for o in replay.outcomes if o.fitness is not None]
    failed = len(replay.outcomes) - len(done)
    title = (
        f"{source.label} over {len(replay.outcomes)} seeds "
        f"({_replay_setting(source, replay.problem_params)})"
        + (f", {failed} failed" if failed else "")
    )
    table = Table(title=table_title(title), title_justify="left")
    stored = _stored_scores(source)
    for column in ("", *(["stored"] if stored is not None else []), "median", "IQR"):
        table.add_column(column, justify="left" if not column else "right")
    samples = [{"fitness": o.fitness, **o.metrics} for o in done]
    names = [*(stored or {"fitness": None}), *(k for o in done for k in o.metrics)]
    for name in dict.fromkeys(names):
        median, low, high = summarize(samples, name)
        if is_rate(name):
            row = [f"{median:.0%} fell", ""]
        else:
            row = [format_number(median), f"{format_number(low)} to {format_number(high)}"]
        before = [] if stored is None else [format_number(stored.get(name))]
        table.add_row(*_plain(name, *before, *row))
    return table
