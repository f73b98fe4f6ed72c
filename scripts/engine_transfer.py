"""How often a gait that walks on one engine walks on another, over every nao-walk episode a
run store holds on several engines at once (docs/robustness.md, fifth search).

A multi-engine nao-walk evaluation stores each engine's distance and fall (``distance@ENGINE``,
``fell@ENGINE``). Over all of them, for each engine A: how many episodes walk at least
THRESHOLD m on A without a fall, and which share of those also walk that far on each other
engine B, P(B | A). An engine with a low P(other | it) is a forgiving one: a search scored there
finds gaits the others do not walk.

    python scripts/engine_transfer.py runs.db other.db --threshold 2 3 4 5.3
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.gait_agreement import transfer_rates
from metaopt_problems.nao_walk.stored_gaits import ENGINES


def walked(stores: Iterable[Path], engines: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(distance, fell), each shape (episodes, engines), of every stored evaluation that has
    both metrics for all of ``engines``."""
    keys = [(f"distance@{e}", f"fell@{e}") for e in engines]
    rows = []
    for path in stores:
        with RunStore(path) as store:
            for run in store.runs():
                for record in store.evaluations(run.id):
                    metrics = record.metrics
                    if all(d in metrics and f in metrics for d, f in keys):
                        rows.append([[metrics[d], metrics[f]] for d, f in keys])
    table = np.array(rows, dtype=float).reshape(-1, len(engines), 2)
    return table[:, :, 0], table[:, :, 1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stores", nargs="+", type=Path, help="run stores (SQLite files)")
    parser.add_argument("--threshold", type=float, nargs="+", default=[2.0, 4.0], help="m")
    parser.add_argument("--engines", default=",".join(ENGINES))
    args = parser.parse_args()
    engines = args.engines.split(",")
    distance, fell = walked(args.stores, engines)
    print(f"{len(distance)} episodes on {', '.join(engines)}")
    print("| walks at least | on A | episodes on A | " + " | ".join(
        f"then on {e}" for e in engines) + " |")  # fmt: skip
    print("|--:|---|--:|" + "--:|" * len(engines))
    for threshold in args.threshold:
        rates = transfer_rates(distance, fell, threshold)
        for a, engine in enumerate(engines):
            cells = ["" if b == a else f"{rates[a, b]:.0%}" for b in range(len(engines))]
            print(f"| {threshold:g} m | {engine} | {rates[a, a]:.0f} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
