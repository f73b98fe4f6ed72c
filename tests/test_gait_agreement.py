"""Do the engines agree on gaits: a sample of gaits walked on several engines and again with
every mass × (1 + 1e-6), summarized as rank correlations and transfer rates
(problems/nao_walk/gait_agreement.py, benchmarks/gait_agreement.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from metaopt.executors.base import SerialExecutor
from metaopt.plugins import registry
from metaopt_problems.nao_walk.gait_agreement import (
    TWIN_MASS_SCALE,
    GaitSample,
    Walks,
    engine_setups,
    rank_agreement,
    twin_rates,
    walk,
)
from tests.conftest import ROOT, load_script

SAMPLE = ROOT / "benchmarks" / "data" / "gait_sample.json"


def test_the_stored_sample_is_complete() -> None:
    sample = GaitSample.load(SAMPLE)
    info = registry().problem("nao-walk")
    problem = info.factory(controller=sample.controller)
    try:
        space = problem.space
    finally:
        problem.close()
    assert len(sample.vectors) == len(sample.origins) >= 150
    for x in sample.vectors:
        assert x.shape == (space.dim,) and space.contains(x)
    assert any("PyBullet+ODE" in o for o in sample.origins)
    assert any("on MuJoCo" in o for o in sample.origins)


def test_the_diagonal_compares_an_engine_with_its_twins() -> None:
    distance = np.array([[1.0, 4.0], [2.0, 3.0], [3.0, 2.0], [4.0, 1.0]])
    twins = np.array([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0], [4.0, 4.0]])
    fell = np.zeros_like(distance)
    walks = Walks(("a", "b"), distance, fell, twins, fell)
    matrix = rank_agreement(walks)
    assert matrix[0, 0] == pytest.approx(1.0)  # a ranks its twins as itself
    assert matrix[1, 1] == pytest.approx(-1.0)  # b's twins reversed its ranking
    assert matrix[0, 1] == matrix[1, 0] == pytest.approx(-1.0)
    # walking 3 m: a in gaits 2, 3 (their twins too); b in 0, 1 (twins walk 1 and 2 m)
    assert twin_rates(walks, 3.0).tolist() == [1.0, 0.0]
    assert np.isnan(twin_rates(walks, 9.0)).all()


def test_the_sample_walks_on_each_engine_as_its_own_episodes(tmp_path: Path) -> None:
    """walk(): each gait's episode on each engine is the nao-walk episode of that gait there
    (read back against a direct evaluation), the twin one at TWIN_MASS_SCALE; the same sample
    walks the same again."""
    full = json.loads(SAMPLE.read_text(encoding="utf-8"))
    small = tmp_path / "sample.json"
    small.write_text(json.dumps({**full, "gaits": full["gaits"][-2:]}), encoding="utf-8")
    sample = GaitSample.load(small)
    engines = engine_setups("mujoco+ode@2")
    walks = walk(sample, engines, SerialExecutor(), duration=6.0, lock=1.0)
    assert walks.engines == ("mujoco", "ode@2")
    assert walks.distance.shape == walks.twin_distance.shape == (2, 2)
    info = registry().problem("nao-walk")
    for k, (engine, steps) in enumerate((("mujoco", 0), ("ode", 2))):
        for twin, scale in ((walks.twin_distance, TWIN_MASS_SCALE), (walks.distance, 1.0)):
            problem = info.factory(controller="steered", backend=engine, substeps=steps,
                                   duration=6.0, lock=1.0, mass_scale=scale)  # fmt: skip
            try:
                expected = problem.evaluate(sample.vectors[1], 0).metrics["distance"]
            finally:
                problem.close()
            assert twin[1, k] == expected
    again = walk(sample, engines, SerialExecutor(), duration=6.0, lock=1.0)
    assert np.array_equal(again.distance, walks.distance)
    report = load_script("benchmarks/gait_agreement.py").report(walks, [1.0])
    assert "| mujoco | " in report and "then on ode@2" in report


def test_engines_are_named_with_their_physics_steps() -> None:
    assert engine_setups("mujoco+ode@4") == {
        "mujoco": {"backend": "mujoco", "substeps": 0},
        "ode@4": {"backend": "ode", "substeps": 4},
    }
    for bad in ("ode@x", "+ode", "ode@"):
        with pytest.raises(ValueError, match="NAME@STEPS"):
            engine_setups(bad)
