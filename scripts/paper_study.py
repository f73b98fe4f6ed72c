"""What the paper's study needs beyond `metaopt compare` and `metaopt report`.

The study itself is the experiment files in docs/paper-reproduction/experiments/, run, resumed
and tabulated by `metaopt compare` and drawn by `metaopt report` (docs/paper-reproduction.md
gives the commands). Two analyses are particular to the paper's controller and stay here:

* ``swing-bounds``: how far Table 2's box lets the CPG's hip and knee targets swing at all
  (free oscillators drawn from the box, JSON);
* ``rhythms FILE...``: each cell's best gaits replayed with a recorded trajectory: period and
  joint swings (nao-walk's rhythm.py) of every seed's best, as a markdown table, to set beside
  the paper's 0.1 s period.

    python scripts/paper_study.py swing-bounds > docs/paper-reproduction/swing-bounds.json
    python scripts/paper_study.py rhythms docs/paper-reproduction/experiments/*.toml \\
        --db /work/studies/paper.db
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

import numpy as np

from metaopt.assessment.replay import replay_params, stored_candidate
from metaopt.comparison.experiment import load_experiment
from metaopt.plugins import Registry, registry
from metaopt.storage.experiment_store import ExperimentStore
from metaopt_problems.nao_walk.controller import (
    MatsuokaCpg,
    cpg_space,
    oscillation_conditions_hold,
)
from metaopt_problems.nao_walk.rhythm import Rhythm, rhythm

#: Joint limits wide enough never to clip the free oscillator's targets, radians.
UNCLIPPED = (-3.0, 3.0)


def swing_bounds(samples: int = 400, seed: int = 0) -> dict[str, float]:
    """Peak-to-peak output y of free (alpha = 0) oscillators drawn uniformly from Table 2's box
    where Matsuoka's conditions hold, after 5 s of settling, and the hip and knee target swings
    it gives with the largest weights the box allows (|w11| = 4, |w12| = 5 degrees per unit)."""
    space = cpg_space()
    rng = np.random.default_rng(seed)
    swings, drawn = [], 0
    while len(swings) < samples:
        x = space.lower + rng.random(len(space.names)) * (space.upper - space.lower)
        x[space.names.index("alpha")] = 0.0
        drawn += 1
        if not oscillation_conditions_hold(x):
            continue
        cpg = MatsuokaCpg(list(x), UNCLIPPED, UNCLIPPED, UNCLIPPED)
        outputs = []
        for _ in range(750):
            cpg.step(0.0, 0.0)
            outputs.append(cpg.outputs[0])
        swings.append(float(np.ptp(outputs[250:])))
    result: dict[str, float] = {"samples": samples, "oscillating_fraction": samples / drawn}
    for name, q in (("median", 50), ("p90", 90), ("max", 100)):
        y = float(np.percentile(swings, q))
        result.update({f"y_swing_{name}": y, f"hip_swing_{name}": 4.0 * y,
                       f"knee_swing_{name}": 5.0 * y})  # fmt: skip
    return result


def best_rhythm(store: ExperimentStore, run_id: int, plugins: Registry) -> tuple[float, Rhythm]:
    """A run's best candidate replayed with its first sample's seed, recording the walk: its
    distance and rhythm (the walk `metaopt report` draws)."""
    run, best = stored_candidate(store, run_id)
    info, params = replay_params(run, plugins, {})
    problem = info.factory(**params)
    try:
        seed = best.samples[0].seed
        result = problem.runner.run(
            problem.gait(np.asarray(best.x)), record=True, disturbance=problem.disturbance(seed)
        )
    finally:
        problem.close()
    return result.distance, rhythm(result.trajectory)


def _median(values: list[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return statistics.median(finite) if finite else math.nan


def rhythms_table(paths: list[Path], db: Path) -> str:
    """Markdown: per cell of each experiment, over the seeds' best gaits, the median period,
    how many have a rhythm, and median measured and commanded hip and knee swings."""
    plugins = registry()
    lines = [
        "| experiment | optimizer | setting | gaits | median period, s | with a rhythm "
        "| hip swing, ° (commanded) | knee swing, ° (commanded) |",
        "|---|---|---|--:|--:|--:|--:|--:|",
    ]
    with ExperimentStore(db) as store:
        for path in paths:
            experiment = load_experiment(path, plugins)
            for cell in experiment.cells():
                found = []
                for seed in experiment.seeds:
                    record = store.member(experiment.name, cell.key, seed)
                    if record is not None and record.status == "finished":
                        found.append(best_rhythm(store, record.id, plugins)[1])
                if not found:
                    continue
                rhythmic = sum(not math.isnan(r.period) for r in found)
                lines.append(
                    f"| {experiment.name} | {cell.optimizer.label} | {cell.setting or '-'} "
                    f"| {len(found)} | {_median([r.period for r in found]):.3f} "
                    f"| {rhythmic} of {len(found)} "
                    f"| {_median([r.hip_swing for r in found]):.1f} "
                    f"({_median([r.hip_target_swing for r in found]):.1f}) "
                    f"| {_median([r.knee_swing for r in found]):.1f} "
                    f"({_median([r.knee_target_swing for r in found]):.1f}) |"
                )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("swing-bounds", help="Table 2's swing of the hip and knee targets (JSON)")
    rhythms = commands.add_parser("rhythms", help="period and swings of each cell's best gaits")
    rhythms.add_argument("files", nargs="+", type=Path, help="experiment files")
    rhythms.add_argument("--db", type=Path, default=Path("metaopt.db"), help="the run store")
    args = parser.parse_args(argv)
    if args.command == "swing-bounds":
        print(json.dumps(swing_bounds(), indent=2))
    else:
        print(rhythms_table(args.files, args.db))
    return 0


if __name__ == "__main__":
    sys.exit(main())
