"""Random search: uniform samples inside the bounds, deterministic per seed, JSON state."""

from __future__ import annotations

import json

import numpy as np

from metaopt import Space
from metaopt.params import resolve
from metaopt.plugins import Registry, build_manager
from metaopt_plugins import random_search

SPACE = Space.from_bounds([-1.0, 10.0, 0.0], [1.0, 10.5, 1e-6])


def build(seed: int, **params) -> random_search.RandomSearch:
    (info,) = random_search.metaopt_optimizers()
    return info.factory(SPACE, seed, **resolve(info.params, params, "random"))


def test_registered_as_random_through_its_entry_point(monkeypatch):
    monkeypatch.setenv("METAOPT_LOAD_PLUGINS", "random_search")
    assert Registry(*build_manager()).optimizer("random").factory is random_search.RandomSearch


def test_samples_fill_the_box_uniformly():
    optimizer = build(0)
    x = optimizer.ask(20_000)
    assert x.shape == (20_000, 3) and SPACE.contains(x)
    unit = (x - SPACE.lower) / SPACE.width
    np.testing.assert_allclose(unit.mean(axis=0), 0.5, atol=0.01)
    np.testing.assert_allclose(unit.var(axis=0), 1 / 12, atol=0.005)


def test_batch_size_is_a_parameter():
    assert build(0).batch_size == 100
    assert build(0, batch_size=8).batch_size == 8


def test_same_seed_same_samples_different_seed_different():
    assert np.array_equal(build(4).ask(10), build(4).ask(10))
    assert not np.array_equal(build(4).ask(10), build(5).ask(10))


def test_json_state_continues_bit_for_bit():
    optimizer = build(2)
    first = optimizer.ask(7)
    optimizer.tell(first, np.full(7, np.inf))
    resumed = build(99)
    resumed.load_state_dict(json.loads(json.dumps(optimizer.state_dict())))
    assert np.array_equal(resumed.ask(50), optimizer.ask(50))
