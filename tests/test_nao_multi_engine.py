"""nao-walk on several engines at once (backend=mujoco+pybullet): the fitness is the worse of
the single-engine fitnesses, every engine's metrics are kept as NAME@ENGINE beside the worst
engine's, engines are built lazily, and bad engine lists are configuration errors."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from metaopt.errors import ConfigError
from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait

SHORT = {"duration": 3.0, "lock": 1.0}


def _problem(backend: str):
    info = registry().problem("nao-walk")
    return info.factory(**resolve(info.params, {"backend": backend, **SHORT}, "nao-walk"))


def _candidates() -> list[np.ndarray]:
    space = _problem("mujoco").space
    rng = np.random.default_rng(5)
    random = [space.lower + rng.random(space.dim) * (space.upper - space.lower) for _ in range(3)]
    return [gait_vector(load_gait()), *random]


def test_fitness_is_the_worse_engine_and_metrics_are_kept_per_engine() -> None:
    single = {name: _problem(name) for name in ("mujoco", "pybullet")}
    both = _problem("mujoco+pybullet")
    try:
        for x in _candidates():
            alone = {name: problem.evaluate(x, 11) for name, problem in single.items()}
            joint = both.evaluate(x, 11)
            assert joint.fitness == min(e.fitness for e in alone.values())
            worst = min(alone, key=lambda name: alone[name].fitness)
            for name, evaluation in alone.items():
                for metric, value in evaluation.metrics.items():
                    assert joint.metrics[f"{metric}@{name}"] == value
            for metric, value in alone[worst].metrics.items():
                assert joint.metrics[metric] == value
    finally:
        for problem in (*single.values(), both):
            problem.close()


def test_engines_are_built_on_first_use_and_not_pickled() -> None:
    problem = _problem("pybullet+mujoco")
    try:
        assert problem.engines == ("pybullet", "mujoco")
        assert problem.__getstate__()["_runners"] == {}
        x = _candidates()[0]
        first = problem.evaluate(x, 3)
        copy = pickle.loads(pickle.dumps(problem))
        assert copy.evaluate(x, 3) == first
        copy.close()
    finally:
        problem.close()


@pytest.mark.parametrize(
    ("backend", "message"),
    [
        ("mujoco+bulet", "unknown physics backend 'bulet'.* Installed: mujoco, ode, pybullet"),
        ("mujoco+", "unknown physics backend ''"),
        ("mujoco+mujoco", "names an engine twice"),
    ],
)
def test_a_bad_engine_list_is_a_config_error(backend: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        _problem(backend)
