"""Do the engines agree on gaits? Over a sample of gaits, each walked once on every engine:
how often a gait that walks on one engine walks on another (transfer rates) and how alike the
engines rank the gaits by distance (Spearman), beside each engine's agreement with itself when
every mass is scaled by 1 + 10⁻⁶ (a walk is chaotic: this is as close as two runs of one engine
come, the baseline for two engines).

The engine agreement suite (metaopt.physics.agreement) checks what an engine holds and does in
simple experiments (masses, friction, motors, contact forces, free flight); this checks the
sum of them where it matters, on walking gaits. benchmarks/gait_agreement.py prints it for a
stored sample (benchmarks/data/gait_sample.json), scripts/engine_transfer.py the transfer rates
over every episode a run store holds on several engines.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from metaopt.executors.base import EvaluationTask, Executor
from metaopt.plugins import registry

#: The twin episode's mass scale: a change far below any physical meaning.
TWIN_MASS_SCALE = 1.0 + 1e-6


@dataclass(frozen=True)
class GaitSample:
    """Decision vectors of one nao-walk controller, each with where it came from."""

    controller: str
    vectors: list[np.ndarray]
    origins: list[str]
    source: str

    @classmethod
    def load(cls, path: Path) -> GaitSample:
        """Read a sample written as JSON: controller, source, gaits: [{origin, x}, ...]."""
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        gaits = data["gaits"]
        return cls(
            data["controller"],
            [np.asarray(g["x"], dtype=float) for g in gaits],
            [g["origin"] for g in gaits],
            data["source"],
        )


@dataclass(frozen=True)
class Walks:
    """Each gait's distance (m) and fall (0/1) per engine, shape (gaits, engines), from the
    nominal episodes and from the twins (every mass × TWIN_MASS_SCALE)."""

    engines: tuple[str, ...]
    distance: np.ndarray
    fell: np.ndarray
    twin_distance: np.ndarray
    twin_fell: np.ndarray


def engine_setups(spec: str) -> dict[str, dict[str, object]]:
    """Engines to walk on, joined by '+': a name (its default physics step) or NAME@N (N
    physics steps a control period), each to the nao-walk parameters that choose it."""
    setups: dict[str, dict[str, object]] = {}
    for label in spec.split("+"):
        name, at, steps = label.strip().partition("@")
        if not name or (at and not steps.isdigit()):
            raise ValueError(f"engine {label!r}: write NAME or NAME@STEPS, e.g. ode@4")
        setups[label.strip()] = {"backend": name, "substeps": int(steps or 0)}
    return setups


def walk(
    sample: GaitSample,
    engines: Mapping[str, Mapping[str, object]],
    executor: Executor,
    **params: object,
) -> Walks:
    """Every gait of the sample, one noise-free episode (seed 0) on each engine and its twin,
    with nao-walk's defaults for the sample's controller, ``params`` and each engine's own
    parameters (``engines``: label to parameters, e.g. from engine_setups)."""
    info = registry().problem("nao-walk")
    plan = []
    for own in engines.values():
        for mass_scale in (1.0, TWIN_MASS_SCALE):
            given = {**params, **own, "controller": sample.controller, "mass_scale": mass_scale}
            plan += [
                EvaluationTask(len(plan) + i, x, 0, info.factory, given)
                for i, x in enumerate(sample.vectors)
            ]
    futures = [executor.submit(task) for task in plan]
    outcomes = [future.result() for future in futures]
    for outcome in outcomes:
        if outcome.fitness is None:
            raise RuntimeError(f"gait episode {outcome.index} failed: {outcome.error}")
    shape = (len(engines), 2, len(sample.vectors))
    distance = np.array([o.metrics["distance"] for o in outcomes]).reshape(shape)
    fell = np.array([o.metrics["fell"] for o in outcomes]).reshape(shape)
    return Walks(tuple(engines), distance[:, 0].T, fell[:, 0].T, distance[:, 1].T, fell[:, 1].T)


def transfer_rates(distance: np.ndarray, fell: np.ndarray, threshold: float) -> np.ndarray:
    """Matrix (A, B): the share of the gaits (episodes) walking ``threshold`` m on A without a
    fall that do so on B too (NaN where none walk on A); the diagonal holds the count on A."""
    walks = (distance >= threshold) & (fell == 0)
    counts = walks.sum(axis=0)
    rates = np.full((walks.shape[1],) * 2, np.nan)
    for a in range(walks.shape[1]):
        if counts[a]:
            rates[a] = walks[walks[:, a]].mean(axis=0)
        rates[a, a] = counts[a]
    return rates


def rank_agreement(walks: Walks) -> np.ndarray:
    """Matrix (A, B): Spearman's rank correlation of the gaits' distances on A and on B; the
    diagonal holds each engine's correlation with its own twins (the chaos baseline)."""
    n = len(walks.engines)
    matrix = np.empty((n, n))
    for a in range(n):
        for b in range(n):
            other = walks.twin_distance[:, a] if a == b else walks.distance[:, b]
            matrix[a, b] = spearmanr(walks.distance[:, a], other).statistic
    return matrix


def twin_rates(walks: Walks, threshold: float) -> np.ndarray:
    """Per engine: the share of gaits walking ``threshold`` m without a fall whose twin does
    too (NaN where none walk)."""
    ok = (walks.distance >= threshold) & (walks.fell == 0)
    twin = (walks.twin_distance >= threshold) & (walks.twin_fell == 0)
    counts = ok.sum(axis=0)
    with np.errstate(invalid="ignore"):
        return np.where(counts > 0, (ok & twin).sum(axis=0) / np.maximum(counts, 1), np.nan)
