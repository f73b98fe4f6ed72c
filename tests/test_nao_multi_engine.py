"""nao-walk on several engines at once (backend=mujoco+pybullet): the fitness is the worse of
the single-engine fitnesses (or their mean, engine_score=mean), every engine's metrics are
kept as NAME@ENGINE beside the worst engine's, engines are built lazily, and bad engine lists
are configuration errors."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from metaopt.errors import ConfigError
from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt_problems.nao_walk.episode import FLIGHT_ALLOWED
from metaopt_problems.nao_walk.plugin import NaoWalk
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait

SHORT = {"duration": 3.0, "lock": 1.0}


def _problem(backend: str, **params: object):
    info = registry().problem("nao-walk")
    given = {"backend": backend, **SHORT, **params}
    return info.factory(**resolve(info.params, given, "nao-walk"))


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


def test_engine_score_mean_is_the_engines_mean_and_keeps_the_worst_metrics() -> None:
    single = {name: _problem(name) for name in ("mujoco", "ode")}
    mean = _problem("mujoco+ode", engine_score="mean")
    worst = _problem("mujoco+ode")
    try:
        fitnesses = []
        for x in _candidates():
            alone = {name: problem.evaluate(x, 11) for name, problem in single.items()}
            joint = mean.evaluate(x, 11)
            assert joint.fitness == pytest.approx(np.mean([e.fitness for e in alone.values()]))
            assert joint.metrics == worst.evaluate(x, 11).metrics
            fitnesses.append({name: e.fitness for name, e in alone.items()})
        assert any(f["mujoco"] != f["ode"] for f in fitnesses)  # the mean is not the worst
    finally:
        for problem in (*single.values(), mean, worst):
            problem.close()


def test_engine_cap_caps_each_engine_before_the_mean_or_the_worst() -> None:
    walk = {"controller": "steered", "duration": 6.0}  # 3 s of walking
    single = {name: _problem(name, **walk) for name in ("mujoco", "ode")}
    space = single["mujoco"].space
    rng = np.random.default_rng(5)
    random = [space.lower + rng.random(space.dim) * space.width for _ in range(3)]
    candidates = [gait_vector(load_gait("capped_walk")), *random]
    try:
        alone = [{n: p.evaluate(x, 11).fitness for n, p in single.items()} for x in candidates]
        cap = float(np.mean(list(alone[0].values())))  # between the stored gait's two engines
        assert min(alone[0].values()) < cap < max(alone[0].values())
        capped = {
            score: _problem("mujoco+ode", engine_score=score, engine_cap=cap, **walk)
            for score in ("mean", "worst")
        }
        uncapped = _problem("mujoco+ode", engine_score="mean", engine_cap=0.0, **walk)
        try:
            for x, fitnesses in zip(candidates, alone):
                kept = [min(f, cap) for f in fitnesses.values()]
                assert capped["mean"].evaluate(x, 11).fitness == pytest.approx(np.mean(kept))
                assert capped["worst"].evaluate(x, 11).fitness == min(kept)
                plain = np.mean(list(fitnesses.values()))
                assert uncapped.evaluate(x, 11).fitness == pytest.approx(plain)  # 0: no cap
        finally:
            for problem in (*capped.values(), uncapped):
                problem.close()
    finally:
        for problem in single.values():
            problem.close()


def test_the_flight_penalty_is_charged_past_the_cap() -> None:
    """engine_cap caps an engine's progress, then its flight penalty is charged: a gait that
    runs past the cap still pays for running (a cap taken after the penalty let the fast
    engine's flight grow unpriced, as long as its progress stayed past the cap)."""
    walk = {"controller": "stride", "duration": 6.0, "measure_flight": True}  # 3 s walked
    x = gait_vector(load_gait("stride_mujoco"))  # fast, and runs
    single = {name: _problem(name, **walk) for name in ("mujoco", "ode")}
    joint = None
    try:
        alone = {name: problem.evaluate(x, 11) for name, problem in single.items()}
        base = {name: e.fitness for name, e in alone.items()}
        flight = {name: e.metrics["flight"] for name, e in alone.items()}
        assert flight["mujoco"] > FLIGHT_ALLOWED + 0.05 and base["mujoco"] > 1.0, alone
        cap, penalty = 0.5, 50.0
        joint = _problem("mujoco+ode", engine_score="mean", engine_cap=cap,
                         flight_penalty=penalty, **walk)  # fmt: skip
        charged = [
            min(base[name], cap) - penalty * max(0.0, flight[name] - FLIGHT_ALLOWED)
            for name in single
        ]
        assert joint.evaluate(x, 11).fitness == pytest.approx(np.mean(charged))
        assert min(charged) < cap - 2.0  # the penalty shows below the cap
    finally:
        for problem in (*single.values(), *([joint] if joint else [])):
            problem.close()


def test_an_unknown_engine_score_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"engine_score.*'best'.*one of worst, mean"):
        _problem("mujoco+ode", engine_score="best")
    with pytest.raises(ConfigError, match="engine_score 'best'; accepted: worst, mean"):
        NaoWalk(backend="mujoco+ode", engine_score="best")  # from Python, past the CLI's check


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
