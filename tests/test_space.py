import numpy as np
import pytest

from metaopt import ConfigError, Space, Variable


def test_bounds_must_be_ordered_and_finite():
    with pytest.raises(ConfigError, match=r"lower bound 2\.0 >= upper bound 1\.0"):
        Space([Variable("a", 2.0, 1.0)])
    with pytest.raises(ConfigError, match="finite"):
        Space([Variable("a", 0.0, float("inf"))])
    with pytest.raises(ConfigError, match="unique"):
        Space([Variable("a", 0, 1), Variable("a", 0, 2)])


def test_sample_stays_inside_and_covers_the_box():
    space = Space.from_bounds([-1.0, 10.0], [1.0, 10.5])
    points = space.sample(np.random.default_rng(0), 5000)
    assert space.contains(points)
    assert points[:, 0].min() < -0.99 and points[:, 0].max() > 0.99
    assert points[:, 1].min() < 10.01 and points[:, 1].max() > 10.49


@pytest.mark.parametrize("method", ["clip", "reflect"])
def test_repair_brings_any_value_inside(method):
    space = Space.from_bounds([-2.0, 0.0], [3.0, 1e-3])
    wild = np.random.default_rng(1).normal(0, 100, (1000, 2))
    repaired = space.repair(wild, method)
    assert repaired.shape == wild.shape
    assert space.contains(repaired)
    inside = np.array([[0.5, 5e-4]])
    np.testing.assert_array_equal(space.repair(inside, method), inside)


def test_reflect_mirrors_a_small_overshoot_and_clip_pins_it():
    space = Space.from_bounds([0.0], [1.0])
    np.testing.assert_allclose(space.repair(np.array([1.2]), "reflect"), [0.8])
    np.testing.assert_allclose(space.repair(np.array([-0.3]), "reflect"), [0.3])
    np.testing.assert_allclose(space.repair(np.array([1.2]), "clip"), [1.0])
    with pytest.raises(ConfigError, match="accepted: clip, reflect"):
        space.repair(np.array([0.5]), "wrap")


def test_json_round_trip_and_named_view():
    space = Space([Variable("tau", 0.1, 25.0, "steps"), Variable("c", 2.0, 4.0)])
    again = Space.from_json(space.to_json())
    assert again.names == ("tau", "c")
    np.testing.assert_array_equal(again.lower, space.lower)
    assert space.as_dict(np.array([1.0, 3.0])) == {"tau": 1.0, "c": 3.0}
