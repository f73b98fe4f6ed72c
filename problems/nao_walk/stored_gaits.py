"""Gaits kept as data in gaits/*.json: found by an optimizer, with their provenance and metrics."""

from __future__ import annotations

import json
from importlib.resources import files

import numpy as np

from .controller import PARAM_NAMES


def load_gait(name: str = "hs_walk") -> dict:
    """The stored record gaits/NAME.json (parameters, found_by, problem_params, metrics)."""
    path = files("metaopt_problems.nao_walk") / "gaits" / f"{name}.json"
    return json.loads(path.read_text(encoding="utf-8"))


def gait_vector(record: dict) -> np.ndarray:
    """A stored gait's decision vector in the CPG's parameter order."""
    return np.array([record["parameters"][name] for name in PARAM_NAMES], dtype=float)
