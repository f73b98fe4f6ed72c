"""nao-walk's `noise` parameter: noise 0 is the deterministic episode exactly; noise > 0 draws
the episode's Disturbance from the evaluation's seed, so (x, seed) still fixes every number, in
any process, while different seeds differ; and the stored HS gait still walks at noise 1."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from metaopt import ConfigError
from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt.seeding import EvaluationSeeds
from metaopt_problems.nao_walk.episode import (
    FRICTION_SPREAD,
    PUSH_STD,
    SENSOR_STD,
    Disturbance,
)
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait

BACKENDS = ("mujoco", "pybullet")
SHORT = {"duration": 4.0, "lock": 1.0}
REPO = Path(__file__).resolve().parents[1]
#: 63-bit seeds as the run loop hands them out
SEEDS = [EvaluationSeeds(7)(i) for i in range(5)]


def _problem(backend: str, **params: object):
    info = registry().problem("nao-walk")
    return info.factory(**resolve(info.params, {"backend": backend, **params}, "nao-walk"))


def noisy_metrics(backend: str, seed: int) -> dict[str, float]:
    """The stored gait's short episode at noise 1 under seed, from a fresh problem (the
    subprocess test compares these numbers across processes)."""
    problem = _problem(backend, noise=1.0, **SHORT)
    try:
        return dict(problem.evaluate(gait_vector(load_gait()), seed).metrics)
    finally:
        problem.close()


def test_noise_below_zero_is_rejected() -> None:
    params = registry().problem("nao-walk").params
    with pytest.raises(ConfigError, match="noise"):
        resolve(params, {"noise": -0.1}, "nao-walk")
    noise = next(p for p in params if p.name == "noise")
    with pytest.raises(ConfigError, match="noise"):
        noise.parse("-1", "nao-walk")
    assert noise.default == 0.0


def test_disturbance_is_a_pure_function_of_its_arguments_with_documented_scales() -> None:
    draw = Disturbance.draw(2.0, SEEDS[0], 1.0, 3000)
    assert draw == Disturbance.draw(2.0, SEEDS[0], 1.0, 3000)
    assert draw != Disturbance.draw(2.0, SEEDS[1], 1.0, 3000)
    errors = np.array(draw.sensor_errors)
    assert errors.shape == (3000, 2)
    assert errors.std() == pytest.approx(2.0 * SENSOR_STD, rel=0.05)
    frictions = [Disturbance.draw(2.0, s, 0.8, 1).friction for s in range(200)]
    bound = math.exp(2.0 * FRICTION_SPREAD)
    assert 0.8 / bound <= min(frictions) < max(frictions) <= 0.8 * bound
    pushes = np.array([Disturbance.draw(2.0, s, 1.0, 1).push for s in range(200)])
    assert np.all(pushes[:, 2] == 0.0)
    assert pushes[:, :2].std() == pytest.approx(2.0 * PUSH_STD, rel=0.15)
    # friction and push do not depend on the episode's length
    short = Disturbance.draw(2.0, SEEDS[0], 1.0, 10)
    assert (short.friction, short.push) == (draw.friction, draw.push)


@pytest.mark.parametrize("backend", BACKENDS)
def test_noise_zero_is_the_deterministic_episode_exactly(backend: str) -> None:
    problem = _problem(backend, **SHORT)
    gait = problem.gait(gait_vector(load_gait()))
    try:
        plain = problem.runner.run(gait).metrics()
        assert problem.evaluate(gait_vector(load_gait()), SEEDS[0]).metrics == plain
        assert problem.evaluate(gait_vector(load_gait()), SEEDS[1]).metrics == plain
        # a disturbance of zeros takes the noisy path and changes nothing
        steps = problem.runner.walk_steps
        zero = Disturbance(problem.physics.friction, (0.0, 0.0, 0.0), [[0.0, 0.0]] * steps)
        assert problem.runner.run(gait, disturbance=zero).metrics() == plain
        # a noisy episode leaves nothing behind: the next noise-free one is unchanged
        problem.runner.run(gait, disturbance=Disturbance.draw(3.0, SEEDS[2], 1.0, steps))
        assert problem.runner.run(gait).metrics() == plain
        with pytest.raises(ValueError, match="walking steps"):
            problem.runner.run(gait, disturbance=Disturbance.draw(1.0, 1, 1.0, steps - 1))
    finally:
        problem.close()


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_seed_same_metrics_different_seeds_differ(backend: str) -> None:
    fresh = noisy_metrics(backend, SEEDS[0])
    problem = _problem(backend, noise=1.0, **SHORT)
    x = gait_vector(load_gait())
    try:
        others = [problem.evaluate(x, seed).metrics for seed in SEEDS[1:]]
        assert problem.evaluate(x, SEEDS[0]).metrics == fresh  # from the cached lock phase
        assert problem.evaluate(x, SEEDS[1]).metrics == others[0]
    finally:
        problem.close()
    distances = {m["distance"] for m in [fresh, *others]}
    assert len(distances) == len(SEEDS)


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_seed_same_metrics_in_another_process(backend: str) -> None:
    here = noisy_metrics(backend, SEEDS[3])
    code = (
        "import json; from tests.test_nao_noise import noisy_metrics as m; "
        f"print(json.dumps(m({backend!r}, {SEEDS[3]})))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True
    )
    assert json.loads(out.stdout.strip().splitlines()[-1]) == here


#: Measured at noise 1 over SEEDS (full 15 s episodes), on the engines corrected by issue 14:
#: MuJoCo 0.167 to 0.199 m, PyBullet 0.313 to 0.416 m, no fall (noise-free: 0.181 and 0.390 m).
@pytest.mark.parametrize("backend", BACKENDS)
def test_stored_gait_still_walks_at_noise_one(backend: str) -> None:
    problem = _problem(backend, noise=1.0)
    x = gait_vector(load_gait())
    try:
        metrics = [problem.evaluate(x, seed).metrics for seed in SEEDS]
    finally:
        problem.close()
    assert all(m["fell"] == 0 for m in metrics)
    distances = [m["distance"] for m in metrics]
    assert min(distances) >= 0.15
    assert 0 < max(distances) - min(distances) < 0.15
