"""footfalls(): how a gait uses its feet, on both engines, from real episodes."""

from __future__ import annotations

import pytest

from metaopt.physics import PhysicsSettings
from metaopt.plugins import registry
from metaopt_problems.nao_walk.episode import EpisodeRunner, EpisodeSettings, SineGait
from metaopt_problems.nao_walk.footfalls import SETTLE_S, footfalls
from metaopt_problems.nao_walk.robot import nao

WALK_S = 8.0


def runner(engine: str) -> EpisodeRunner:
    backend = registry().physics_backend(engine).factory(nao(), PhysicsSettings())
    return EpisodeRunner(backend, EpisodeSettings(duration=1.0 + WALK_S, lock=1.0))


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_a_standing_robot_stands_on_both_feet_without_slipping(engine):
    feet = footfalls(runner(engine), SineGait(hip=0.0, knee=0.0))
    assert feet.contact == (1.0, 1.0) and feet.double_support == 1.0 and feet.flight == 0.0
    assert feet.slip_speed < 0.005
    assert abs(feet.stride_length) < 0.01


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
@pytest.mark.parametrize("period", [0.5, 0.8])
def test_the_stride_frequency_is_the_gaits_rhythm(engine, period):
    feet = footfalls(runner(engine), SineGait(period=period))
    resolution = 1.0 / (WALK_S - SETTLE_S)  # one bin of the spectrum
    assert feet.stride_frequency == pytest.approx(1.0 / period, abs=resolution)
    assert 0.0 < feet.double_support < 1.0 and min(feet.contact) > 0.3
