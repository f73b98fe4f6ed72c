"""Where a stored gait's drift comes from: its heading, over noise seeds, on each engine
(docs/robustness.md, second search).

For each engine, over SEEDS noise seeds (the stored-gait replays' seeds, nominal world, noise
0.1): the torso's yaw turned
half-way through the walk and at its end (read from the engine every control step), the final
lateral drift, and their correlation; with ``--steer G`` also the same gait's parameters under
the steered controller's heading feedback at gain G (a stride gait only).

    python scripts/heading_drift.py robust_walk --steer 1
"""

from __future__ import annotations

import argparse

import numpy as np

from metaopt.assessment.robustness import summarize
from metaopt.seeding import EvaluationSeeds
from metaopt_problems.nao_walk.episode import heading
from metaopt_problems.nao_walk.plugin import NaoWalk
from metaopt_problems.nao_walk.robustness import UNSAMPLED
from metaopt_problems.nao_walk.stored_gaits import (
    ENGINES,
    gait_problem,
    gait_vector,
    load_gait,
    replay_over_seeds,
    with_steering,
)

NOISE = 0.1


def turned(problem: NaoWalk, x: np.ndarray, seed: int) -> tuple[float, float, float, bool]:
    """One episode: (yaw half-way, yaw at the end, both degrees; drift, m; fell)."""
    runner = problem.runner
    headings: list[float] = []

    def read_heading(_: int) -> None:
        headings.append(heading(runner.backend.root_rotation()))

    result = runner.run(
        problem.gait(x), disturbance=problem.disturbance(seed), on_step=read_heading
    )
    yaw = np.degrees(np.unwrap(headings) - headings[0])
    return float(yaw[len(yaw) // 2]), float(yaw[-1]), result.drift, result.fell


def main() -> None:
    """Print each engine's heading and drift statistics for the stored gait named on the
    command line, in the nominal world (its sampled worlds and cells left out)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("gait", help="a stored gait's name")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--steer", type=float, help="also replay it steered at this gain")
    args = parser.parse_args()
    record = load_gait(args.gait)
    x = gait_vector(record)
    draw = EvaluationSeeds(0)  # the seeds replay_over_seeds draws
    print(f"{args.gait}, {args.seeds} seeds at noise {NOISE}, nominal world")
    for engine in ENGINES:
        params = {**record["problem_params"], "noise": NOISE, **UNSAMPLED}  # as replay_over_seeds
        problem = gait_problem(params, engine)
        rows = np.array([turned(problem, x, draw(i)) for i in range(args.seeds)])
        problem.close()
        half, end, drift, fell = rows.T
        print(
            f"{engine}: |yaw| half-way max {np.abs(half).max():.1f} deg, at the end max "
            f"{np.abs(end).max():.1f} deg; median |drift| {np.median(np.abs(drift)):.2f} m; "
            f"corr(drift, final yaw) {np.corrcoef(drift, end)[0, 1]:.2f}; falls {int(fell.sum())}"
        )
        if args.steer is not None:
            samples = replay_over_seeds(
                with_steering(record, args.steer), engine, args.seeds, NOISE
            )
            print(
                f"  steered at {args.steer}: median |drift| "
                f"{summarize(samples, '|drift|')[0]:.2f} m, median speed "
                f"{summarize(samples, 'speed')[0]:.3f} m/s, falls "
                f"{sum(int(m['fell']) for m in samples)}"
            )


if __name__ == "__main__":
    main()
