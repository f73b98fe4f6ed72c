"""Benchmark functions: optimum values and locations, known values, bounds, dim parameter."""

from __future__ import annotations

import math

import numpy as np
import pytest

from metaopt import ConfigError, Sense
from metaopt.params import resolve
from metaopt.plugins import Registry, build_manager
from metaopt_problems import functions

INFOS = {info.name: info for info in functions.metaopt_problems()}
BOUNDS = {
    "sphere": (-5.12, 5.12),
    "rastrigin": (-5.12, 5.12),
    "rosenbrock": (-5.0, 10.0),
    "ackley": (-32.768, 32.768),
    "griewank": (-600.0, 600.0),
    "schwefel": (-500.0, 500.0),
}


def build(name: str, **params) -> functions.BenchmarkFunction:
    info = INFOS[name]
    return info.factory(**resolve(info.params, params, name))


def value(name: str, x) -> float:
    x = np.asarray(x, dtype=float)
    return build(name, dim=x.size).evaluate(x, seed=0).fitness


def test_every_function_is_registered_through_the_entry_point(monkeypatch):
    monkeypatch.setenv("METAOPT_LOAD_PLUGINS", "functions")
    assert set(Registry(*build_manager()).problems) == set(BOUNDS)


@pytest.mark.parametrize("name", sorted(BOUNDS))
@pytest.mark.parametrize("dim", [2, 10, 30])
def test_value_at_the_known_minimum_is_the_optimum(name, dim):
    problem = build(name, dim=dim)
    assert problem.optimum == 0.0 and problem.sense is Sense.MINIMIZE
    assert problem.key_metrics == ()
    evaluation = problem.evaluate(problem.argmin, seed=0)
    assert isinstance(evaluation.fitness, float) and evaluation.metrics == {}
    assert abs(evaluation.fitness - problem.optimum) < 1e-9
    assert problem.space.contains(problem.argmin)


@pytest.mark.parametrize("name", sorted(BOUNDS))
def test_minimum_is_lower_than_random_points(name):
    problem = build(name, dim=5)
    points = problem.space.sample(np.random.default_rng(0), 200)
    assert min(problem.evaluate(x, 0).fitness for x in points) > 1e-3


@pytest.mark.parametrize(
    ("name", "x", "expected"),
    [
        ("sphere", [1.0, 2.0, -3.0], 14.0),
        ("rastrigin", [1.0, 1.0], 2.0),
        ("rastrigin", [0.5], 20.25),
        ("rosenbrock", [0.0, 0.0, 0.0], 2.0),
        ("rosenbrock", [-1.0, 1.0], 4.0),
        ("ackley", [1.0, 1.0], 20.0 - 20.0 * math.exp(-0.2)),
        ("griewank", [math.pi], 2.0 + math.pi**2 / 4000.0),
        ("griewank", [0.0, math.pi * math.sqrt(2.0)], 2.0 + 2.0 * math.pi**2 / 4000.0),
        ("schwefel", [0.0, 0.0], 2 * 418.9829),
        ("schwefel", [-420.9687, -420.9687], 4 * 418.9829),
    ],
)
def test_known_values(name, x, expected):
    assert value(name, x) == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("name", sorted(BOUNDS))
def test_bounds_and_dim(name):
    assert INFOS[name].params[0].default == 10
    problem = build(name, dim=7)
    assert problem.space.dim == 7
    np.testing.assert_array_equal(problem.space.lower, BOUNDS[name][0])
    np.testing.assert_array_equal(problem.space.upper, BOUNDS[name][1])
    assert build(name).space.dim == 10


@pytest.mark.parametrize("name", sorted(BOUNDS))
def test_dim_zero_is_rejected(name):
    with pytest.raises(ConfigError, match="dim"):
        resolve(INFOS[name].params, {"dim": 0}, name)


def test_rosenbrock_needs_two_variables():
    with pytest.raises(ConfigError, match="dim"):
        resolve(INFOS["rosenbrock"].params, {"dim": 1}, "rosenbrock")
    assert resolve(INFOS["sphere"].params, {"dim": 1}, "sphere") == {"dim": 1}


def test_evaluation_is_pure():
    problem = build("rastrigin", dim=4)
    x = np.array([0.3, -1.2, 4.0, 2.2])
    assert problem.evaluate(x, 0) == problem.evaluate(x.copy(), 12345)
