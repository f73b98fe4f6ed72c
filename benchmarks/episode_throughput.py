"""Episode throughput per physics backend: how close the episode loop runs to the engine's limit.

For each backend, prints simulated seconds per wall second for
  * episodes: full 15 s episodes of a fixed walking gait (SineGait), the lock phase simulated
    once and restored, as nao-walk evaluates candidates;
  * physics: the same engine replaying the same joint targets open-loop from the same restored
    state, with no controller, metrics or fall checks (the limit: what the engine alone costs
    for exactly the same motion);
and their ratio, counting the 12 s walking phase each actually simulates (the lock phase is
simulated once per process). Usage:

    python benchmarks/episode_throughput.py [--episodes N] [--backends mujoco,pybullet]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from metaopt.physics import PhysicsSettings
from metaopt.plugins import registry
from metaopt_problems.nao_walk.episode import (
    DRIVEN_JOINTS,
    EpisodeRunner,
    EpisodeSettings,
    SineGait,
)
from metaopt_problems.nao_walk.robot import nao


def measure(backend: str, episodes: int) -> dict[str, float]:
    """Best-of-`episodes` wall time of a walking episode and of its open-loop replay, taken
    alternately so that load from other processes hits both alike."""
    engine = registry().physics_backend(backend).factory(nao(), PhysicsSettings())
    runner = EpisodeRunner(engine, EpisodeSettings())
    recorded = runner.run(SineGait(), record=True)  # also simulates and stores the lock phase
    assert not recorded.fell, "the reference gait should walk the whole episode"
    sequence = np.tile(engine.robot.rest_angles, (len(recorded.trajectory["time"]), 1))
    for name in DRIVEN_JOINTS:
        sequence[:, engine.robot.joint_index(name)] = recorded.trajectory[f"{name}_target"]
    lock_state = engine.save_state()
    episode_wall = physics_wall = float("inf")
    for _ in range(episodes):
        start = time.perf_counter()
        runner.run(SineGait())
        episode_wall = min(episode_wall, time.perf_counter() - start)
        start = time.perf_counter()
        engine.restore_state(lock_state)
        for targets in sequence:
            engine.step(targets)
        physics_wall = min(physics_wall, time.perf_counter() - start)
    engine.close()
    return {
        "episode_s": episode_wall,
        "episode_rate": recorded.time_walked / episode_wall,
        "physics_rate": recorded.time_walked / physics_wall,
        "ratio": physics_wall / episode_wall,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--backends", default=",".join(registry().physics_backends))
    args = parser.parse_args()
    print(f"{'backend':<10} {'best episode':>12} {'episode sim-s/s':>16} "
          f"{'physics sim-s/s':>16} {'ratio':>6}")  # fmt: skip
    for name in args.backends.split(","):
        m = measure(name, args.episodes)
        print(f"{name:<10} {m['episode_s']:>11.3f}s {m['episode_rate']:>16.1f} "
              f"{m['physics_rate']:>16.1f} {m['ratio']:>6.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
