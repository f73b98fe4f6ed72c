"""Episode throughput per physics backend: how close the episode loop runs to the engine's limit.

For each backend, prints simulated seconds per wall second for
  * episodes: full 15 s episodes of a fixed walking gait (the Matsuoka CPG with the stored HS
    gait, problems/nao_walk/gaits/hs_walk.json), the lock phase simulated once and restored,
    as nao-walk evaluates candidates;
  * physics: the same engine replaying the episode's recorded joint targets open-loop from the
    same restored state, the end of the lock phase the walking phase starts from
    (EpisodeRunner.lock_state), with no controller, metrics or fall checks (the limit: what the
    engine alone costs for exactly the same motion). The replay is checked to end where the
    episode did, bit for bit: the episode only reads the engine between steps, and sets the
    ground friction it already has;
and their ratio, counting the 12 s walking phase each actually simulates (the lock phase is
simulated once per process). Then it times the whole study the README runs,
`metaopt run --optimizer hs --problem nao-walk --budget 750`, pinned to one core (target: at
most 90 s with MuJoCo; --run-backends mujoco,ode times it on several engines). Every engine
runs at its default friction (ODE: the server's infinite friction with slip). Usage:

    python benchmarks/episode_throughput.py [--episodes N] [--backends mujoco,pybullet,ode]
                                            [--run-backends mujoco] [--seed S]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

from metaopt.physics import PhysicsBackend
from metaopt.physics.agreement import engine as physics_engine
from metaopt.plugins import registry
from metaopt_problems.nao_walk.episode import DRIVEN_JOINTS, EpisodeRunner, EpisodeSettings
from metaopt_problems.nao_walk.plugin import NaoWalk
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait


def replay(engine: PhysicsBackend, lock_state: Any, sequence: np.ndarray) -> np.ndarray:
    """The torso's final position after stepping engine through sequence's joint targets
    open-loop from lock_state, set up as an episode's walking phase starts (nominal friction)."""
    engine.restore_state(lock_state)
    engine.set_ground_friction(engine.settings.friction)
    for targets in sequence:
        engine.step(targets)
    return engine.root_position()


def measure(backend: str, episodes: int) -> dict[str, float]:
    """Best-of-`episodes` wall time of a walking episode and of its open-loop replay from the
    same end of the lock phase, taken alternately so that load from other processes hits both
    alike; AssertionError where the replay does not end where the episode did."""
    with physics_engine(backend) as engine:  # the NAO at the engine's default friction
        runner = EpisodeRunner(engine, EpisodeSettings())
        gait = NaoWalk(backend=backend).gait(gait_vector(load_gait()))
        recorded = runner.run(gait, record=True)  # also simulates and stores the lock phase
        assert not recorded.fell, "the reference gait should walk the whole episode"
        lock_state = runner.lock_state  # where every episode's walking phase starts
        assert lock_state is not None, f"{backend} does not restore its lock phase exactly"
        trajectory = recorded.trajectory
        sequence = np.tile(engine.robot.rest_angles, (len(trajectory["time"]), 1))
        for name in DRIVEN_JOINTS:
            sequence[:, engine.robot.joint_index(name)] = trajectory[f"{name}_target"]
        walked_to = [trajectory[axis][-1] for axis in "xyz"]
        replayed_to = replay(engine, lock_state, sequence).tolist()
        assert replayed_to == walked_to, (
            f"{backend}: the open-loop replay ends at {replayed_to}, the episode at {walked_to}"
        )
        episode_wall = physics_wall = float("inf")
        for _ in range(episodes):
            start = time.perf_counter()
            runner.run(gait)
            episode_wall = min(episode_wall, time.perf_counter() - start)
            start = time.perf_counter()
            replay(engine, lock_state, sequence)
            physics_wall = min(physics_wall, time.perf_counter() - start)
    return {
        "episode_s": episode_wall,
        "episode_rate": recorded.time_walked / episode_wall,
        "physics_rate": recorded.time_walked / physics_wall,
        "ratio": physics_wall / episode_wall,
    }


def time_full_run(backend: str, seed: int) -> float:
    """Wall seconds of `metaopt run -o hs -p nao-walk --budget 750`, fresh process, one core."""
    with tempfile.TemporaryDirectory() as folder:
        command = [
            sys.executable, "-m", "metaopt", "run", "--optimizer", "hs", "--problem", "nao-walk",
            "--budget", "750", "--seed", str(seed), "--set", f"backend={backend}",
            "--db", os.path.join(folder, "bench.db"),
        ]  # fmt: skip
        pin_to_one_core = lambda: os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # noqa: E731
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True, preexec_fn=pin_to_one_core)
        return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=5)
    available = registry().available_physics_backends()
    parser.add_argument("--backends", default=",".join(available))
    parser.add_argument("--run-backends", default="mujoco", help="'' to skip the 750-run timing")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    print(f"{'backend':<10} {'best episode':>12} {'episode sim-s/s':>16} "
          f"{'physics sim-s/s':>16} {'ratio':>6}")  # fmt: skip
    for name in args.backends.split(","):
        m = measure(name, args.episodes)
        print(f"{name:<10} {m['episode_s']:>11.3f}s {m['episode_rate']:>16.1f} "
              f"{m['physics_rate']:>16.1f} {m['ratio']:>6.2f}")  # fmt: skip
    print("targets: ratio >= 0.85 (mujoco), >= 0.9 (pybullet, ode)")
    for name in filter(None, args.run_backends.split(",")):
        wall = time_full_run(name, args.seed)
        command = f"metaopt run -o hs -p nao-walk --budget 750 --set backend={name}"
        print(f"{command} --seed {args.seed}, one core: {wall:.1f} s (target <= 90 s, mujoco)")


if __name__ == "__main__":
    main()
