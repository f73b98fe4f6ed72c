"""Gaits kept as data in gaits/*.json: found by an optimizer, with their provenance and metrics."""

from __future__ import annotations

import json
from importlib.resources import files

import numpy as np

from . import controller, extended

#: Each controller's parameter names, in decision-vector order.
CONTROLLER_PARAMS = {"paper": controller.PARAM_NAMES, "extended": extended.PARAM_NAMES}


def stored_gait_names() -> list[str]:
    """The names of the stored gaits (gaits/NAME.json), sorted."""
    folder = files("metaopt_problems.nao_walk") / "gaits"
    return sorted(
        p.name.removesuffix(".json") for p in folder.iterdir() if p.name.endswith(".json")
    )


def load_gait(name: str = "hs_walk") -> dict:
    """The stored record gaits/NAME.json (parameters, found_by, problem_params, metrics)."""
    path = files("metaopt_problems.nao_walk") / "gaits" / f"{name}.json"
    return json.loads(path.read_text(encoding="utf-8"))


def gait_vector(record: dict) -> np.ndarray:
    """A stored gait's decision vector in its controller's parameter order."""
    names = CONTROLLER_PARAMS[record["problem_params"].get("controller", "paper")]
    return np.array([record["parameters"][name] for name in names], dtype=float)
