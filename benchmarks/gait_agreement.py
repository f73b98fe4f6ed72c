"""Do the engines agree on gaits? The stored gait sample (benchmarks/data/gait_sample.json)
walked once on every installed engine, and again with every mass × (1 + 10⁻⁶) (the chaos
baseline): per engine how far the gaits walk, the rank correlation of their distances between
engines beside each engine's with itself, and how often a gait walking N m on one engine walks
as far on another (docs/robustness.md, "Do the engines agree on gaits?").

    python benchmarks/gait_agreement.py [--engines mujoco+pybullet+ode+ode@4] [--workers 2]
        [--threshold 3] [--sample FILE] [--limit N]

An engine written NAME@N takes N physics steps a control period instead of its default (ode@4:
ODE at 5 ms steps beside the server's one 20 ms step).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from metaopt.cli.common import build_executor
from metaopt.plugins import registry
from metaopt_problems.nao_walk.gait_agreement import (
    GaitSample,
    Walks,
    engine_setups,
    rank_agreement,
    transfer_rates,
    twin_rates,
    walk,
)
from metaopt_problems.nao_walk.stored_gaits import ENGINES

SAMPLE = Path(__file__).parent / "data" / "gait_sample.json"


def report(walks: Walks, thresholds: list[float]) -> str:
    """The figures as markdown tables."""
    names, first = walks.engines, thresholds[0]
    lines = [
        f"| engine | median distance (m) | falls | walks {first:g} m |",
        "|---|--:|--:|--:|",
    ]
    for k, name in enumerate(names):
        walked = (walks.distance[:, k] >= first) & (walks.fell[:, k] == 0)
        lines.append(f"| {name} | {np.median(walks.distance[:, k]):.2f} | "
                     f"{walks.fell[:, k].mean():.0%} | {walked.mean():.0%} |")  # fmt: skip
    spearman = rank_agreement(walks)
    lines += ["", "Rank correlation of distance (Spearman); diagonal: the engine with itself "
              "at every mass × (1 + 1e-6)", "",
              "| | " + " | ".join(names) + " |", "|---|" + "--:|" * len(names)]  # fmt: skip
    for a, name in enumerate(names):
        lines.append(f"| {name} | " + " | ".join(f"{v:.2f}" for v in spearman[a]) + " |")
    for threshold in thresholds:
        rates = transfer_rates(walks.distance, walks.fell, threshold)
        twins = twin_rates(walks, threshold)
        lines += ["", f"Of the gaits walking {threshold:g} m without a fall on A, the share that "
                  "does on B (diagonal: on A again, masses × (1 + 1e-6))", "",
                  "| A | gaits | " + " | ".join(f"then on {n}" for n in names) + " |",
                  "|---|--:|" + "--:|" * len(names)]  # fmt: skip
        for a, name in enumerate(names):
            cells = [_share(twins[a] if b == a else rates[a, b]) for b in range(len(names))]
            lines.append(f"| {name} | {rates[a, a]:.0f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _installed() -> tuple[str, ...]:
    """The engines that run here, the project's three first in their usual order."""
    names = registry().available_physics_backends()
    return tuple(sorted(names, key=lambda n: ENGINES.index(n) if n in ENGINES else len(ENGINES)))


def _share(rate: float) -> str:
    return "–" if np.isnan(rate) else f"{rate:.0%}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--engines", default=None, help="NAME or NAME@STEPS joined by '+' [every installed one]"
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--threshold", type=float, nargs="+", default=[3.0, 4.0], help="m")
    parser.add_argument("--sample", type=Path, default=SAMPLE)
    parser.add_argument("--limit", type=int, default=None, help="only the first N gaits")
    args = parser.parse_args()
    try:
        engines = engine_setups(args.engines or "+".join(_installed()))
    except ValueError as error:
        parser.error(str(error))
    sample = GaitSample.load(args.sample)
    if args.limit is not None:
        sample = GaitSample(sample.controller, sample.vectors[: args.limit],
                            sample.origins[: args.limit], sample.source)  # fmt: skip
    started = time.perf_counter()
    with build_executor(None, args.workers, None) as executor:
        walks = walk(sample, engines, executor)
    print(f"{len(sample.vectors)} gaits ({sample.controller} controller): {sample.source}")
    print(f"{2 * len(sample.vectors) * len(engines)} episodes in "
          f"{time.perf_counter() - started:.0f} s\n")  # fmt: skip
    print(report(walks, args.threshold))


if __name__ == "__main__":
    main()
