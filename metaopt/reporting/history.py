"""A run's course, window by window: for each window of consecutive evaluations its median
fitness and quartiles, the best fitness so far, and chosen metrics' medians (a 0/1 metric's
share, e.g. of falls) and, where asked, how far apart its candidates are. The best-so-far curve
of a noisy run rises on lucky scores alone; the windows' medians show whether the search as a
whole still climbed when it stopped, what it traded on the way, and the spread whether it still
stepped far enough to climb (`metaopt history`)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from metaopt.errors import ConfigError
from metaopt.reporting.convergence import convergence
from metaopt.reporting.recent import completed, fitness_quartiles, is_flag, metric_value
from metaopt.space import Space
from metaopt.storage.run_store import EvaluationRecord


@dataclass(frozen=True)
class HistoryWindow:
    """One window of a run's evaluations: index range, how many succeeded, their fitness
    quartiles (None: none succeeded), the best fitness of every evaluation up to the window's
    last (None: none yet), and each shown metric's median or share (None: none reported it),
    over its completed evaluations; screened ones (metaopt run --screen) are counted apart.
    ``spread`` (asked for: candidate_spread) is over every candidate the window asked for."""

    first: int
    last: int
    evaluations: int
    succeeded: int
    fitness_quartiles: tuple[float, float, float] | None
    best_so_far: float | None
    metrics: dict[str, float | None]
    screened: int = 0
    spread: float | None = None


@dataclass(frozen=True)
class RunHistory:
    """A run's windows, the metrics they show, and which of those are shares (0/1 metrics)."""

    window: int
    metrics: tuple[str, ...]
    shares: frozenset[str]
    windows: tuple[HistoryWindow, ...]
    spread: bool = False

    def kind(self, name: str) -> str:
        """How a shown metric is summarised per window: "share" (a 0/1 metric) or "median"."""
        return "share" if name in self.shares else "median"


def candidate_spread(records: Sequence[EvaluationRecord], space: Space) -> float | None:
    """How far apart the records' candidates are: the median over the variables of their
    standard deviation, each as a share of the variable's range (a candidate evaluated several
    times counts once); None for fewer than two candidates. CMA-ES's step shrinks it; a climb
    that levels off as it nears 0 stopped stepping, not necessarily climbing."""
    distinct = {record.candidate: record.x for record in records}
    if len(distinct) < 2:
        return None
    points = np.array(list(distinct.values()), dtype=float)
    return float(np.median(points.std(axis=0, ddof=1) / space.width))


def run_history(
    evaluations: Iterable[EvaluationRecord],
    window: int,
    maximize: bool,
    metrics: Sequence[str] | None = None,
    space: Space | None = None,
) -> RunHistory:
    """The run's evaluations (in index order) in consecutive windows of ``window`` (the last may
    be shorter). ``metrics`` names the metrics to show; None shows the run's 0/1 metrics (a
    metric is a share when it is 0 or 1 in every evaluation of the run that reports it).
    ``space``, the run's, adds each window's candidate_spread.
    ConfigError for a name the run's evaluations never report, with the names they do."""
    if window < 1:
        raise ConfigError(f"a history window must hold at least 1 evaluation; got {window}")
    records = list(evaluations)
    reported: dict[str, list[float]] = {}
    for record in completed(records):
        for name, value in record.metrics.items():
            reported.setdefault(name, []).append(float(value))
    shares = frozenset(name for name, values in reported.items() if is_flag(values))
    if metrics is None:
        shown = tuple(name for name in reported if name in shares)
    else:
        unknown = [name for name in metrics if name not in reported]
        if unknown:
            known = ", ".join(sorted(reported)) or "none"
            raise ConfigError(
                f"no metric {unknown[0]!r} in this run's evaluations; they report: {known}"
            )
        shown = tuple(dict.fromkeys(metrics))
    fitness = [math.nan if r.fitness is None else r.fitness for r in records]
    best = convergence(fitness, maximize, window=1).best  # NaN before the first success
    windows = []
    for start in range(0, len(records), window):
        chunk = records[start : start + window]
        whole = completed(chunk)
        fitnesses = [r.fitness for r in whole if r.fitness is not None]
        best_so_far = float(best[start + len(chunk) - 1])
        figures = {}
        for name in shown:
            values = [float(r.metrics[name]) for r in whole if name in r.metrics]
            figures[name] = metric_value(values, name in shares) if values else None
        windows.append(
            HistoryWindow(
                first=chunk[0].index,
                last=chunk[-1].index,
                evaluations=len(chunk),
                succeeded=len(fitnesses),
                fitness_quartiles=fitness_quartiles(fitnesses),
                best_so_far=None if math.isnan(best_so_far) else best_so_far,
                metrics=figures,
                screened=len(chunk) - len(whole),
                spread=None if space is None else candidate_spread(chunk, space),
            )
        )
    return RunHistory(
        window, shown, shares & frozenset(shown), tuple(windows), spread=space is not None
    )
