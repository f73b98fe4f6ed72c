"""Gaits kept as data in gaits/*.json: found by an optimizer, with their provenance, metrics
and claims. A claim is a statistic over noise seeds (median distance and |drift|, fall rate,
and for a gait searched with its flight measured the median flight share), not one chaotic
trajectory."""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from metaopt.assessment.robustness import summarize
from metaopt.problem import StoredCandidate
from metaopt.seeding import EvaluationSeeds

from .plugin import CONTROLLER_KINDS, NaoWalk
from .robustness import BACKGROUND_NOISE, UNSAMPLED

if TYPE_CHECKING:
    from importlib.resources.abc import Traversable

#: The engines a record's metrics cover.
ENGINES = ("mujoco", "pybullet", "ode")
#: A claim's episodes: this many seeds (EvaluationSeeds(0)) at the robustness table's
#: background noise.
CLAIM_SEEDS = 5
CLAIM_NOISE = BACKGROUND_NOISE


def controller_params(controller: str) -> tuple[str, ...]:
    """A controller's parameter names, in decision-vector order."""
    return tuple(CONTROLLER_KINDS[controller].space().names)


def stored_gait_names() -> list[str]:
    """The names of the stored gaits (gaits/NAME.json), sorted."""
    folder = files("metaopt_problems.nao_walk") / "gaits"
    return sorted(
        p.name.removesuffix(".json") for p in folder.iterdir() if p.name.endswith(".json")
    )


def load_gait(name: str = "hs_walk") -> dict:
    """The stored record gaits/NAME.json (parameters, found_by, problem_params, metrics)."""
    return read_gait(files("metaopt_problems.nao_walk") / "gaits" / f"{name}.json")


def read_gait(path: Path | Traversable) -> dict:
    """A gait record read from its file (UTF-8 JSON), wherever it is kept."""
    return json.loads(path.read_text(encoding="utf-8"))


def gait_vector(record: dict) -> np.ndarray:
    """A stored gait's decision vector in its controller's parameter order."""
    names = controller_params(record["problem_params"].get("controller", "paper"))
    return np.array([record["parameters"][name] for name in names], dtype=float)


def gait_seed(record: dict) -> int:
    """The seed of the evaluation a stored gait was found with (older records name only the
    run's seed)."""
    found_by = record["found_by"]
    return found_by.get("evaluation_seed", found_by["seed"])


def with_steering(record: dict, gain: float) -> dict:
    """A stride gait's record as the steered controller's: the same parameters, and the
    heading feedback at ``gain`` (docs/nao-walk.md, the steered controller)."""
    controller = record["problem_params"].get("controller", "paper")
    if controller != "stride":
        raise ValueError(f"only a stride gait can be steered, not a {controller} one")
    return {
        **record,
        "problem_params": {**record["problem_params"], "controller": "steered"},
        "parameters": {**record["parameters"], "steer": gain},
    }


def stored_candidates() -> dict[str, StoredCandidate]:
    """Every stored gait as nao-walk announces it (for ``metaopt robustness GAIT``)."""
    records = {name: load_gait(name) for name in stored_gait_names()}
    return {
        name: StoredCandidate(record["problem_params"], gait_vector(record), gait_seed(record))
        for name, record in records.items()
    }


def gait_problem(problem_params: dict, engine: str) -> NaoWalk:
    """A fresh nao-walk problem made with problem_params, backend replaced by engine."""
    from metaopt.params import resolve
    from metaopt.plugins import registry

    info = registry().problem("nao-walk")
    return info.factory(**resolve(info.params, {**problem_params, "backend": engine}, "nao-walk"))


def gait_metrics(problem_params: dict, x: np.ndarray, seed: int, engine: str) -> dict:
    """Decision vector x's episode metrics on one engine, from a fresh nao-walk problem made
    with problem_params (backend replaced by engine)."""
    problem = gait_problem(problem_params, engine)
    try:
        return dict(problem.evaluate(x, seed).metrics)
    finally:
        problem.close()


def replay_gait(record: dict, engine: str) -> dict:
    """A stored gait's metrics on engine, re-run as it was found (its evaluation's seed; older
    records name only the run's seed)."""
    return gait_metrics(record["problem_params"], gait_vector(record), gait_seed(record), engine)


def replay_over_seeds(
    record: dict, engine: str, seeds: int, noise: float, run_seed: int = 0
) -> list[dict]:
    """A stored gait's metrics on engine over ``seeds`` seeds (EvaluationSeeds(run_seed)) at
    ``noise``, from one fresh problem, in the nominal world (a gait searched over sampled
    worlds, ``worlds`` and ``world_cells``, meets the perturbations in its robustness table
    instead)."""
    draw = EvaluationSeeds(run_seed)
    params = {**record["problem_params"], "noise": noise, **UNSAMPLED}
    problem = gait_problem(params, engine)
    try:
        return [dict(problem.evaluate(gait_vector(record), draw(i)).metrics) for i in range(seeds)]
    finally:
        problem.close()


def claim_statistics(samples: list[dict]) -> dict[str, float]:
    """What a claim bounds: the median distance and |drift| and the fall rate of episodes, and
    the median flight share where the episodes measured it."""
    stats = {
        "median_distance": summarize(samples, "distance")[0],
        "median_drift": summarize(samples, "|drift|")[0],
        "fall_rate": summarize(samples, "fell")[0],
    }
    if all("flight" in sample for sample in samples):
        stats["median_flight"] = summarize(samples, "flight")[0]
    return stats
