"""Convergence curves from stored evaluations: best so far, trailing mean, and quartiles over
groups of runs with the same setup.

Failed evaluations have no fitness, nor have screened ones (metaopt run --screen: only their
bound is known): they never count as a best and are left out of every mean.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from metaopt.errors import ConfigError
from metaopt.storage.run_store import RunRecord, RunStore

#: How several runs are grouped into bands: by optimizer and every parameter (optimizer's and
#: problem's), or by optimizer name alone.
GROUP_BY = ("setup", "optimizer")
#: The default trailing-mean window is this fraction of a run's evaluations (at least 1).
WINDOW_FRACTION = 0.05


@dataclass(frozen=True)
class Convergence:
    """One run's fitness in evaluation order (element i: the (i+1)-th evaluation)."""

    fitness: np.ndarray  #: each evaluation's fitness, NaN where it failed or was screened
    best: np.ndarray  #: best successful fitness so far (NaN before the first success)
    mean: np.ndarray  #: mean successful fitness of the last ``window`` evaluations
    window: int
    maximize: bool
    screened: int = 0  #: evaluations of which only the screen ran (NaN, but not failed)

    @property
    def evaluations(self) -> np.ndarray:
        """1, 2, ..., n: the x axis."""
        return np.arange(1, len(self.fitness) + 1)

    @property
    def failed(self) -> int:
        """Evaluations without a fitness that were not screened."""
        return int(np.isnan(self.fitness).sum()) - self.screened


def convergence(
    fitness: np.ndarray, maximize: bool, window: int | None = None, screened: int = 0
) -> Convergence:
    """The curves of fitnesses in evaluation order (NaN = failed, or one of ``screened``
    screened ones); window None = 5 % of them; no fitness: empty curves."""
    fitness = np.asarray(fitness, dtype=float)
    if window is None:
        window = max(1, round(WINDOW_FRACTION * len(fitness)))
    if not len(fitness):  # a run stopped before its first evaluation (an early Ctrl-C)
        return Convergence(fitness, fitness.copy(), fitness.copy(), window, maximize, screened)
    best = (np.fmax if maximize else np.fmin).accumulate(fitness)
    padded = np.concatenate([np.full(window - 1, np.nan), fitness])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # windows of failures only: NaN
        mean = np.nanmean(np.lib.stride_tricks.sliding_window_view(padded, window), axis=1)
    return Convergence(fitness, best, mean, window, maximize, screened)


def require_evaluations(store: RunStore, run: RunRecord) -> None:
    """ConfigError (one line) for a run without a stored evaluation (stopped before its
    first, e.g. by an early Ctrl-C): it has no course to show or draw."""
    if store.evaluation_counts(run.id).stored == 0:
        raise ConfigError(f"run {run.id} has no evaluations yet; nothing to show")


def run_convergence(store: RunStore, run: RunRecord, window: int | None = None) -> Convergence:
    """The curves of a stored run."""
    records = list(store.evaluations(run.id))
    fitness = [np.nan if record.fitness is None else record.fitness for record in records]
    screened = sum(record.status == "screened" for record in records)
    return convergence(np.array(fitness, dtype=float), run.sense == "maximize", window, screened)


@dataclass(frozen=True)
class Band:
    """Median and quartiles of several runs' best-so-far curves, over their common length."""

    evaluations: np.ndarray
    lower: np.ndarray  #: 25th percentile
    median: np.ndarray
    upper: np.ndarray  #: 75th percentile
    runs: int


def best_so_far_band(curves: list[Convergence]) -> Band:
    """Quartiles at each evaluation of the runs' best so far, up to the shortest run's end
    (runs still without a success at an evaluation are left out there)."""
    return _band([curve.best for curve in curves])


def mean_band(curves: list[Convergence]) -> Band:
    """Quartiles at each evaluation of the runs' trailing mean fitness (the paper's "average
    fitness" curve of Figs. 4 and 5), up to the shortest run's end."""
    return _band([curve.mean for curve in curves])


def _band(series: list[np.ndarray]) -> Band:
    length = min(len(values) for values in series)
    table = np.array([values[:length] for values in series])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: NaN, as wanted
        lower, median, upper = np.nanpercentile(table, [25, 50, 75], axis=0)
    return Band(np.arange(1, length + 1), lower, median, upper, len(series))


def group_runs(runs: list[RunRecord], group_by: str) -> dict[str, list[RunRecord]]:
    """Runs by label: the optimizer's name, with (group_by 'setup') the parameters that take
    more than one value among the runs that have them."""
    if group_by not in GROUP_BY:
        raise ConfigError(f"unknown grouping {group_by!r}; choose from {', '.join(GROUP_BY)}")
    setups = [_setup(run) for run in runs]
    varying = sorted({key for setup in setups for key in setup if _differs(setups, key)})
    groups: dict[str, list[RunRecord]] = {}
    for run, setup in zip(runs, setups):
        shown = [f"{key}={json.dumps(setup[key])}" for key in varying if key in setup]
        label = run.optimizer if group_by == "optimizer" else " ".join([run.optimizer, *shown])
        groups.setdefault(label, []).append(run)
    return groups


def _setup(run: RunRecord) -> dict[str, Any]:
    """What a run was set up with besides its seed (problem parameters written problem.NAME)."""
    return {**run.optimizer_params, **{f"problem.{k}": v for k, v in run.problem_params.items()}}


def _differs(setups: list[dict[str, Any]], key: str) -> bool:
    return len({json.dumps(setup[key], sort_keys=True) for setup in setups if key in setup}) > 1
