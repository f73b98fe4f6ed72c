"""Keep a stored run's best nao-walk gait as data: problems/nao_walk/gaits/NAME.json.

The record holds the decision vector by parameter name, how it was found (the command, the
optimizer and its parameters, seed, budget, the evaluation's index), the problem parameters it
was found with, what it does on every physics engine (its episode re-run on each, one engine
at a time), the engines' versions, and the claims tests/test_stored_gait.py checks: on each
engine named with --claim, a distance at least a little below what it walks and a drift bound.

    python scripts/store_gait.py RUN --db faster-walk.db --name extended_mujoco \\
        --command "metaopt compare docs/faster-walk/mujoco.toml --workers 2" \\
        --description "..." --claim mujoco

After a change of an engine, ``--remeasure NAME --why "..."`` re-runs a record's episode on
every engine and re-records what it does now: its metrics, and on every engine it claimed, a
walking claim from the new metrics or, where it now falls, a claim that it falls. The metrics it
replaces are kept under ``earlier_metrics`` with the reason.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import math
import sys
from pathlib import Path

from metaopt_problems.nao_walk.stored_gaits import ENGINES, gait_metrics, load_gait, replay_gait

ROOT = Path(__file__).resolve().parent.parent
GAITS = ROOT / "problems" / "nao_walk" / "gaits"
#: A claim sits this far below the measured distance (and the drift bound this far above the
#: measured drift), so that a small, harmless change of an engine does not break the test
#: while a gait that no longer walks does.
DISTANCE_MARGIN = 0.9
DRIFT_SLACK = 0.05


def claim(metrics: dict) -> dict:
    """What the test will demand: a little less distance, a little more drift, no fall; of a
    gait that falls, that it falls."""
    if metrics["fell"]:
        return {"fell": 1}
    return {
        "min_distance": math.floor(DISTANCE_MARGIN * metrics["distance"] * 100) / 100,
        "max_drift": math.ceil((abs(metrics["drift"]) + DRIFT_SLACK) * 100) / 100,
        "fell": 0,
    }


def record(db: Path, run_id: int, command: str, description: str, claims: list[str]) -> dict:
    """The gait record of the best evaluation of run ``run_id`` in ``db``."""
    from metaopt.params import resolve
    from metaopt.plugins import registry
    from metaopt.store import RunStore

    with RunStore(db) as store:
        run = store.run(run_id)
        best = store.best_evaluation(run)
    if best is None:
        raise SystemExit(f"run {run_id} has no successful evaluation")
    info = registry().problem("nao-walk")
    problem_params = resolve(info.params, run.problem_params, "nao-walk")
    names = [variable["name"] for variable in run.space]
    metrics = {e: gait_metrics(problem_params, best.x, best.seed, e) for e in ENGINES}
    for engine in claims:
        if metrics[engine]["fell"]:
            raise SystemExit(f"the gait falls on {engine}: nothing to claim")
    return {
        "description": description,
        "found_by": {
            "command": command,
            "optimizer": run.optimizer,
            "optimizer_params": run.optimizer_params,
            "settings": run.settings,
            "seed": run.seed,
            "budget": run.budget,
            "run_evaluation_index": best.index,
            "evaluation_seed": best.seed,
            "metaopt_version": run.versions.get("metaopt"),
        },
        "problem_params": problem_params,
        "parameters": {name: float(value) for name, value in zip(names, best.x)},
        "metrics": metrics,
        "claims": {engine: claim(metrics[engine]) for engine in claims},
        "engine_versions": {engine: importlib.metadata.version(engine) for engine in ENGINES},
    }


def remeasured(gait: dict, why: str) -> dict:
    """The record gait with what it does on every engine now (see the module's docstring)."""
    metrics = {engine: replay_gait(gait, engine) for engine in ENGINES}
    earlier = {"why": why, "metrics": gait["metrics"], "engine_versions": gait["engine_versions"]}
    return {
        **gait,
        "metrics": metrics,
        "claims": {engine: claim(metrics[engine]) for engine in gait["claims"]},
        "engine_versions": {engine: importlib.metadata.version(engine) for engine in ENGINES},
        "earlier_metrics": [*gait.get("earlier_metrics", []), earlier],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=int, nargs="?", help="run id in the store")
    parser.add_argument("--db", type=Path)
    parser.add_argument("--name", help="the record's name: gaits/NAME.json")
    parser.add_argument("--command", help="the command that found it")
    parser.add_argument("--description")
    parser.add_argument(
        "--claim", action="append", default=[], choices=ENGINES, help="an engine it walks on"
    )
    parser.add_argument("--remeasure", metavar="NAME", help="re-record gaits/NAME.json")
    parser.add_argument("--why", help="with --remeasure: what changed in the engines")
    args = parser.parse_args(argv)
    if args.remeasure:
        if not args.why or not (GAITS / f"{args.remeasure}.json").is_file():
            parser.error("--remeasure needs an existing record's name and --why")
        path = GAITS / f"{args.remeasure}.json"
        gait = remeasured(load_gait(args.remeasure), args.why)
    else:
        if args.run is None or not all((args.db, args.name, args.command, args.description)):
            parser.error("a new record needs RUN, --db, --name, --command and --description")
        gait = record(args.db, args.run, args.command, args.description, args.claim)
        path = GAITS / f"{args.name}.json"
    path.write_text(json.dumps(gait, indent=2) + "\n")
    for engine, metrics in gait["metrics"].items():
        print(f"{engine}: distance {metrics['distance']:.3f} m, drift {metrics['drift']:+.3f} m, "
              f"fell {metrics['fell']:.0f}")  # fmt: skip
    print(f"wrote {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
