"""pycma keeps metaopt's contract (the conformance kit) and wraps CMA-ES faithfully."""

from __future__ import annotations

import json

import numpy as np
import pytest
from metaopt_cma import CmaEs

from metaopt import ConfigError, Space
from metaopt.testing import optimizer_checks

CHECKS = optimizer_checks("pycma")
SPACE = Space.from_bounds([-3.0] * 4, [7.0] * 4)


@pytest.mark.parametrize("check", CHECKS)
def test_conforms(check):
    CHECKS[check]()


def sphere(batch: np.ndarray) -> np.ndarray:
    return ((batch - 1.0) ** 2).sum(axis=1)


def drive(optimizer: CmaEs, generations: int) -> list[np.ndarray]:
    batches = []
    for _ in range(generations):
        batch = optimizer.ask(optimizer.batch_size)
        optimizer.tell(batch, sphere(batch))
        batches.append(batch)
    return batches


def test_popsize_zero_means_cmas_default():
    assert CmaEs(SPACE, 1, sigma0=0.3, popsize=0, budget=1000).batch_size == 8  # 4 + int(3 ln 4)
    assert CmaEs(SPACE, 1, sigma0=0.3, popsize=13, budget=1000).batch_size == 13


def test_solves_a_sphere_then_restarts():
    optimizer = CmaEs(SPACE, 1, sigma0=0.3, popsize=0, budget=1000)
    best = min(sphere(b).min() for b in drive(optimizer, 250))
    assert best < 1e-12
    assert optimizer._generation > 250 - 1 and optimizer._es.countiter < 250  # restarted


def test_the_state_resumes_bit_for_bit_after_restarts():
    reference = drive(CmaEs(SPACE, 5, sigma0=0.3, popsize=0, budget=1000), 260)
    stopped = CmaEs(SPACE, 5, sigma0=0.3, popsize=0, budget=1000)
    drive(stopped, 250)
    resumed = CmaEs(SPACE, 99, sigma0=0.3, popsize=0, budget=1000)  # the state carries the seed
    resumed.load_state_dict(json.loads(json.dumps(stopped.state_dict(), allow_nan=False)))
    assert all(np.array_equal(a, b) for a, b in zip(drive(resumed, 10), reference[250:]))


def test_a_state_from_another_cma_version_is_refused():
    state = CmaEs(SPACE, 1, sigma0=0.3, popsize=0, budget=1000).state_dict()
    with pytest.raises(ConfigError, match=r"install cma==0\.0\.1 to resume"):
        CmaEs(SPACE, 1, sigma0=0.3, popsize=0, budget=1000).load_state_dict(
            {**state, "cma_version": "0.0.1"}
        )


def test_results_must_come_in_ask_order():
    optimizer = CmaEs(SPACE, 1, sigma0=0.3, popsize=0, budget=1000)
    batch = optimizer.ask(3)
    with pytest.raises(ValueError, match="order their candidates were asked"):
        optimizer.tell(batch[::-1], sphere(batch[::-1]))


def test_failed_evaluations_are_penalised_below_every_finite_fitness():
    optimizer = CmaEs(SPACE, 1, sigma0=0.3, popsize=0, budget=1000)
    batch = optimizer.ask(optimizer.batch_size)
    fitnesses = sphere(batch)
    fitnesses[::2] = np.inf
    optimizer.tell(batch, fitnesses)  # cma itself refuses inf
    assert optimizer._worst == fitnesses[1::2].max()
    drive(optimizer, 5)
