"""The gaits kept as data (problems/nao_walk/gaits/*.json) still do what their records say.

Each record was made by scripts/store_gait.py from the best evaluation of a run (the command
that found it is in the record). On every engine its record *claims* (for hs_walk: MuJoCo; for
the extended and stride controllers' gaits: docs/faster-walk.md) it must walk the 12 s walking
phase without falling, at least the claimed distance (a little below what it reached) and with at
most the claimed drift. On every engine, claimed or not, every metric must equal the stored
record: the episode is deterministic, so any change is a change of the simulation or the
controller; on an engine it does not claim the record documents the cross-engine transfer.
"""

from __future__ import annotations

import importlib.metadata
import math

import pytest

from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt_problems.nao_walk.plugin import CONTROLLERS
from metaopt_problems.nao_walk.stored_gaits import (
    ENGINES,
    controller_params,
    load_gait,
    replay_gait,
    stored_gait_names,
)

GAITS = stored_gait_names()


def _assert_equal_record(
    measured: dict[str, float], record: dict[str, float], engine: str, recorded_version: str
) -> None:
    """Exact equality holds for the engine version the record was made with; another version
    integrates differently (a chaotic system diverges), so the check is skipped, visibly."""
    installed = importlib.metadata.version(engine)
    if installed != recorded_version:
        pytest.skip(f"record made with {engine} {recorded_version}, installed {installed}")
    assert set(measured) == set(record)
    for name, value in record.items():
        assert math.isclose(measured[name], value, rel_tol=1e-9, abs_tol=1e-9), (
            name, measured[name], value,
        )  # fmt: skip


def test_every_controller_has_a_kept_gait_and_a_gait_walks_fast_on_both_engines() -> None:
    assert "hs_walk" in GAITS
    controllers = {load_gait(name)["problem_params"]["controller"] for name in GAITS}
    assert controllers == set(CONTROLLERS)
    # docs/faster-walk.md's goal on both engines: 0.3 m/s over the 12 s walking phase
    assert any(
        set(gait["claims"]) == set(ENGINES)
        and all(claim["min_distance"] >= 0.3 * 12 for claim in gait["claims"].values())
        for gait in map(load_gait, GAITS)
    )


@pytest.mark.parametrize("name", GAITS)
def test_stored_gait_is_complete(name: str) -> None:
    gait = load_gait(name)
    params = gait["problem_params"]
    # every stored parameter is valid; ones added to nao-walk since take their defaults
    resolved = resolve(registry().problem("nao-walk").params, params, "nao-walk")
    assert {name: resolved[name] for name in params} == params
    assert list(gait["parameters"]) == list(controller_params(params["controller"]))
    found_by = gait["found_by"]
    assert found_by["command"].startswith("metaopt ")
    assert registry().optimizer(found_by["optimizer"])
    assert set(gait["metrics"]) == set(ENGINES) == set(gait["engine_versions"])
    assert gait["claims"] and set(gait["claims"]) <= set(ENGINES)
    for engine, claim in gait["claims"].items():
        measured = gait["metrics"][engine]
        assert claim["min_distance"] <= measured["distance"]
        assert abs(measured["drift"]) <= claim["max_drift"]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", GAITS)
def test_stored_gait_does_what_its_record_says(name: str, engine: str) -> None:
    gait = load_gait(name)
    metrics = replay_gait(gait, engine)
    claim = gait["claims"].get(engine)
    if claim is not None:
        assert metrics["fell"] == claim["fell"] == 0
        assert metrics["time_walked"] == pytest.approx(12.0)
        assert metrics["distance"] >= claim["min_distance"] > 0.5
        assert abs(metrics["drift"]) <= claim["max_drift"]
    _assert_equal_record(metrics, gait["metrics"][engine], engine, gait["engine_versions"][engine])
