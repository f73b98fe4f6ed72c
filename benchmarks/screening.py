"""What `metaopt run --screen` saves on the robust walk's stage 1b, side by side in one run.

Runs the same CMA-ES run twice (same seed, same settings: the robust-walk search's stage 1b,
docs/robustness/searches.md, started around the stored gait balanced_walk) on two worker
processes, once plain and once screened, and prints each one's wall time, its evaluations
per second, how many candidates were walked on PyBullet, and whether both ended in the same
CMA-ES state (they should: its update reads only the better half by rank). Usage:

    python benchmarks/screening.py [--generations G] [--seed S] [--workers W]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from metaopt.plugins import registry
from metaopt.running import RunSettings, RunSpec, run
from metaopt.storage.run_store import RunStore

POPULATION = 24
#: the search's stage 1b (docs/robustness/robust-walk-search.sh, designs N-P)
STAGE1B = {
    "controller": "balanced", "backend": "mujoco+pybullet+ode", "engine_score": "worst",
    "engine_cap": 6.0, "noise": 0.1, "fitness": "progress", "flight_penalty": 50.0,
    "flight_allowed": 0.035, "worlds": "pushes",
    "world_cells": "nominal,nominal,nominal,nominal,servo gain x1.2,latency 1",
}  # fmt: skip


def timed_run(db: Path, screen: bool, generations: int, seed: int, workers: int) -> dict:
    """One stage-1b run; its wall time, evaluations, PyBullet walks and final CMA-ES state."""
    plugins = registry()
    problem_info = plugins.problem("nao-walk")
    start = problem_info.stored_candidates()["balanced_walk"].x.tolist()
    spec = RunSpec(
        "cmaes", "nao-walk", POPULATION * generations, seed,
        optimizer_params={"population": POPULATION, "sigma0": 0.05},
        problem_params=STAGE1B,
        settings=RunSettings(start=[start], start_spread=0.05, screen=screen),
    )  # fmt: skip
    executor = plugins.executor("process").factory(workers, None)
    with RunStore(db) as store:
        began = time.perf_counter()
        result = run(spec, plugins.optimizer("cmaes"), problem_info, store, None, executor)
        wall = time.perf_counter() - began
        statuses = [e.status for e in store.evaluations(result.run_id)]
        state = store.run(result.run_id).checkpoint["state"]
    return {
        "wall": wall,
        "evaluations": len(statuses),
        "on_pybullet": len(statuses) - statuses.count("screened"),
        "best": result.best_fitness,
        "state": state,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generations", type=int, default=4)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        figures = {
            screen: timed_run(
                Path(folder) / f"{screen}.db", screen, args.generations, args.seed, args.workers
            )
            for screen in (False, True)
        }
    print(f"stage 1b, {args.generations} generations of {POPULATION}, {args.workers} workers, "
          f"seed {args.seed}")  # fmt: skip
    print(f"{'':10} {'wall s':>8} {'evals/s':>8} {'on PyBullet':>12} {'best':>10}")
    for screen, figure in figures.items():
        rate = figure["evaluations"] / figure["wall"]
        print(
            f"{'screened' if screen else 'plain':10} {figure['wall']:8.1f} {rate:8.2f} "
            f"{figure['on_pybullet']:>5} of {figure['evaluations']:<5} {figure['best']:10.4f}"
        )
    plain, screened = figures[False], figures[True]
    print(f"speed-up (plain wall / screened wall): {plain['wall'] / screened['wall']:.2f}")
    same = plain["state"] == screened["state"] and plain["best"] == screened["best"]
    print(f"same CMA-ES state and best at the end: {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
