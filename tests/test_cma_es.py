"""The built-in CMA-ES (``cmaes``): it learns a step shape, starts where a warm start puts it,
and keeps a told candidate it did not sample from throwing it off.

The conformance kit (tests/test_conformance.py) checks its contract: shapes, failed
evaluations, the JSON state, the same seed giving the same candidates."""

from __future__ import annotations

import json

import numpy as np
import pytest

from metaopt import Space, create_optimizer, minimize
from metaopt_plugins.cma_es import CMAES, default_population
from tests.conftest import metaopt_cli, one_error_line

BOX = [(-5.0, 5.0)] * 10


def ellipsoid(x: np.ndarray) -> float:
    """An axis-aligned ellipsoid of condition 1e6, optimum at 1: needs a learned step shape."""
    scales = 1e6 ** (np.arange(len(x)) / (len(x) - 1))
    return float(np.sum(scales * (np.asarray(x) - 1.0) ** 2))


def rosenbrock(x: np.ndarray) -> float:
    x = np.asarray(x)
    return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2))


def evaluations_to(target: float, f, seed: int, limit: int = 20000) -> int:
    """How many evaluations the default cmaes needs for a value below target on BOX."""
    optimizer = create_optimizer("cmaes", BOX, seed=seed, budget=limit)
    spent = 0
    while spent < limit:
        batch = optimizer.ask(optimizer.batch_size)
        values = np.array([f(x) for x in batch])
        spent += len(batch)
        optimizer.tell(batch, values)
        if values.min() < target:
            return spent
    return spent


def test_the_default_population_is_4_plus_3_ln_n():
    assert default_population(10) == 10 and default_population(4) == 8
    assert create_optimizer("cmaes", BOX, seed=1).batch_size == 10
    assert create_optimizer("cmaes", BOX, seed=1, population=16).batch_size == 16


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_it_learns_an_ill_conditioned_ellipsoid(seed):
    # Measured: 5660-6170 evaluations to 1e-8 on seeds 0-4 (pycma 4.5, with active CMA:
    # 3900-4590). HS does not reach 1e-8 here in 20,000 evaluations.
    assert evaluations_to(1e-8, ellipsoid, seed) < 8000


def test_it_beats_harmony_search_on_rosenbrock_at_the_same_budget():
    cma = minimize(rosenbrock, BOX, "cmaes", budget=3000, seed=1).fitness
    hs = minimize(rosenbrock, BOX, "hs", budget=3000, seed=1).fitness
    assert cma < 2.0 and hs > 4 * cma


def test_a_warm_start_puts_the_distribution_at_the_start():
    start = [4.0, -4.0, 3.0, -3.0, 2.0, -2.0, 1.0, -1.0, 4.5, -4.5]
    optimizer = create_optimizer("cmaes", BOX, seed=7, sigma0=0.01)
    # The run loop tells the warm start's points as if they had been asked (metaopt.warm_start);
    # the start itself is the best of them here.
    points = np.array(start) + np.random.default_rng(0).uniform(-0.5, 0.5, (10, 10))
    points[0] = start
    values = np.array([float(np.sum((p - np.array(start)) ** 2)) for p in points])
    optimizer.tell(points, values)
    asked = optimizer.ask(50)
    # sigma0 0.01 of a range of 10: 0.1 per variable; the mean is the weighted best of the points.
    assert np.abs(asked - np.array(start)).max() < 1.5
    assert np.abs(asked.mean(axis=0) - np.array(start)).max() < 0.5


def test_the_first_generation_is_uniform_then_the_distribution_starts_at_its_best():
    optimizer = create_optimizer("cmaes", BOX, seed=3)
    first = optimizer.ask(10)
    optimizer.tell(first, np.array([ellipsoid(x) for x in first]))
    assert optimizer.generation == 1 and optimizer.sigma == 0.3
    best_five = first[np.argsort([ellipsoid(x) for x in first])[:5]]
    unit_mean = optimizer.constants.weights @ ((best_five + 5.0) / 10.0)
    assert np.allclose(optimizer.mean, unit_mean)


def test_a_far_candidate_it_did_not_sample_moves_it_by_a_bounded_step():
    optimizer = create_optimizer("cmaes", BOX, seed=2)
    for _ in range(60):
        batch = optimizer.ask(10)
        optimizer.tell(batch, np.array([ellipsoid(x) for x in batch]))
    mean, sigma = optimizer.mean.copy(), optimizer.sigma
    axes, scales = optimizer._axes.copy(), optimizer._scales.copy()

    def length(unit_step: np.ndarray) -> float:
        """A step's length in the distribution's metric, in units of sigma."""
        return float(np.linalg.norm((axes.T @ unit_step) / scales)) / sigma

    batch = optimizer.ask(10)
    batch[0] = [5.0] * 10  # a told point far outside the distribution, ranked best
    values = np.array([ellipsoid(x) for x in batch])
    values[0] = -1.0
    assert length((batch[0] + 5.0) / 10.0 - mean) > 10 * optimizer.constants.max_step
    optimizer.tell(batch, values)
    # Every step is at most max_step long and the weights sum to 1: so is the mean's move.
    assert length(optimizer.mean - mean) <= optimizer.constants.max_step * (1 + 1e-9)


def test_batches_that_divide_the_population_give_the_same_run():
    whole = create_optimizer("cmaes", BOX, seed=11)
    pairs = create_optimizer("cmaes", BOX, seed=11)
    for _ in range(8):
        batch = whole.ask(10)
        whole.tell(batch, np.array([rosenbrock(x) for x in batch]))
        halves = []
        for _ in range(5):
            two = pairs.ask(2)
            pairs.tell(two, np.array([rosenbrock(x) for x in two]))
            halves.append(two)
        assert np.array_equal(np.concatenate(halves), batch)


def test_failed_evaluations_rank_last_and_the_state_stays_json():
    optimizer = CMAES(Space.from_bounds([-1.0] * 3, [1.0] * 3), 1, population=6, sigma0=0.3,
                      repair="clip", budget=100)  # fmt: skip
    first = optimizer.ask(6)
    values = np.array([float(np.sum(x**2)) for x in first])
    failed = int(np.argmin(values))  # the best point fails: it must not enter the mean
    values[failed] = np.inf
    optimizer.tell(first, values)
    parents = first[np.argsort(values)[:3]]
    assert np.allclose(optimizer.mean, optimizer.constants.weights @ ((parents + 1.0) / 2.0))
    for generation in range(4):
        batch = optimizer.ask(6)
        values = np.array([float(np.sum(x**2)) for x in batch])
        values[generation % 6] = np.inf
        optimizer.tell(batch, values)
    state = json.loads(json.dumps(optimizer.state_dict(), allow_nan=False))
    assert np.isfinite(optimizer.sigma) and np.all(np.isfinite(optimizer.cov))
    assert state["generation"] == 5  # the first generation and four updates


def test_a_population_of_one_is_refused_in_one_line(tmp_path):
    done = metaopt_cli(
        "run", "-o", "cmaes", "-p", "sphere", "--set", "population=1", "--budget", "20",
        "--db", str(tmp_path / "runs.db"), cwd=tmp_path,
    )  # fmt: skip
    one_error_line(done, "population", "at least 2")


@pytest.mark.parametrize(
    ("setting", "needles"),
    [
        ("sigma0=inf", ["'sigma0' = inf", "(0, 1]"]),
        ("sigma0=1e308", ["'sigma0' = 1e+308", "(0, 1]"]),
        ("sigma0=1.5", ["'sigma0' = 1.5", "(0, 1]"]),
        ("population=10000000000", ["'population' = 10000000000", "[0, 1e+06]"]),
    ],
)
def test_a_step_past_the_range_or_a_population_past_memory_is_refused_in_one_line(
    tmp_path, setting, needles
):
    """sigma0 is a share of each range (at most 1: inf ended in a LinAlgError and a failed
    run); a population of 10**10 ended in a MemoryError traceback. Both are refused, nothing
    stored."""
    done = metaopt_cli(
        "run", "-o", "cmaes", "-p", "sphere", "--budget", "60", "--seed", "1", "--set", setting,
        "--set", "dim=3", "--db", str(tmp_path / "runs.db"), cwd=tmp_path,
    )  # fmt: skip
    one_error_line(done, *needles)
    assert not (tmp_path / "runs.db").exists()


def test_a_step_of_the_whole_range_runs(tmp_path):
    done = metaopt_cli(
        "run", "-o", "cmaes", "-p", "sphere", "--budget", "30", "--seed", "1", "--set",
        "sigma0=1", "--set", "dim=3", "--db", str(tmp_path / "runs.db"), cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
