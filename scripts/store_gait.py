"""Keep a stored run's best nao-walk gait, or its candidate N (RUN:N), as data: gaits/NAME.json.

The record holds the decision vector by parameter name, how it was found (the command, the
optimizer and its parameters, seed, budget, the candidate's number and its first evaluation's
index and seed: a resampled run's best candidate is the best by its aggregate), the problem
parameters it was found with, what it does on every physics engine (its episode re-run on
each, one engine at a time), the engines' versions, and the claims tests/test_stored_gait.py
checks: on each engine named with --claim, statistics over CLAIM_SEEDS noise seeds
(stored_gaits.py): a median distance a little below the measured one, a median |drift| bound
and the fall rate, and for a gait searched with its flight measured a median flight share
bound.

    python scripts/store_gait.py RUN --db faster-walk.db --name extended_mujoco \\
        --command "metaopt compare docs/faster-walk/mujoco.toml --workers 2" \\
        --description "..." --claim mujoco

``--set NAME=VALUE`` stores the gait walking with a problem parameter other than the run's
(kept in found_by as walked_with): ``--set duration=15`` for a gait searched on shorter walks,
so that its record, claims and replays walk the standard 15 s its robustness table walked.

After a change of an engine (or of the claims' statistics), ``--remeasure NAME --why "..."``
re-runs a record's episode on every engine and re-records what it does now: its metrics, the
engines' versions, and its claims on every engine it claimed, measured again (a gait that now
falls there gets a claim saying how often). Metrics it replaces are kept under
``earlier_metrics`` with the reason; how it was found and its parameters stay.

``--gaits DIR`` writes (and re-records) records in another folder than the package's.
A request that cannot be done (no such store or run, a run of another problem, a bad --set, a
gait that does not walk where it would claim to) is refused in one line, exit 2, and no record
is written; a record is written whole or not at all.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from metaopt.storage.whole_file import written_whole
from metaopt_problems.nao_walk.stored_gaits import (
    CLAIM_NOISE,
    CLAIM_SEEDS,
    ENGINES,
    claim_statistics,
    gait_metrics,
    read_gait,
    replay_gait,
    replay_over_seeds,
)

ROOT = Path(__file__).resolve().parent.parent
GAITS = ROOT / "problems" / "nao_walk" / "gaits"
#: A claim sits this far below the measured distance (and the drift bound this far above the
#: measured drift), so that a small, harmless change of an engine does not break the test
#: while a gait that no longer walks does.
DISTANCE_MARGIN = 0.9
DRIFT_SLACK = 0.05
#: A flight claim sits this far above the measured median flight share.
FLIGHT_SLACK = 0.01
#: A claim needs at least this median distance over the 12 s walking phase, m.
MIN_CLAIM_DISTANCE = 0.5


def claim(record: dict, engine: str) -> dict:
    """What the test will demand on engine, measured over CLAIM_SEEDS seeds at CLAIM_NOISE: a
    little less median distance, a little more median |drift| (and flight share), no more
    falls."""
    stats = claim_statistics(replay_over_seeds(record, engine, CLAIM_SEEDS, CLAIM_NOISE))
    flight = {}
    if "median_flight" in stats:
        flight["max_median_flight"] = math.ceil((stats["median_flight"] + FLIGHT_SLACK) * 100) / 100
    return {
        "noise": CLAIM_NOISE,
        "seeds": CLAIM_SEEDS,
        "min_median_distance": math.floor(DISTANCE_MARGIN * stats["median_distance"] * 100) / 100,
        "max_median_drift": math.ceil((stats["median_drift"] + DRIFT_SLACK) * 100) / 100,
        "max_fall_rate": stats["fall_rate"],
        **flight,
    }


def record(
    db: Path,
    target: str,
    command: str,
    description: str,
    claims: list[str],
    changes: Sequence[str] = (),
) -> dict:
    """The gait record of ``target`` in ``db``: a run's best candidate (by its aggregate over
    its samples when the run resampled, as the optimizer saw it) or RUN:NUMBER, another one
    (e.g. the one `metaopt robustness RUN --top K` ranked first); ``changes`` (NAME=VALUE) are
    problem parameters it walks with instead of the run's, kept in found_by as walked_with
    (duration=15: the standard walk, for a run that searched shorter ones)."""
    from metaopt.assessment.replay import stored_candidate
    from metaopt.cli.common import require_store
    from metaopt.errors import ConfigError, MetaoptError, StoreError
    from metaopt.params import resolve
    from metaopt.plugins import registry
    from metaopt.settings import parse_problem_settings
    from metaopt.storage.run_store import RunStore

    info = registry().problem("nao-walk")
    try:
        walked_with = parse_problem_settings(changes, info)
    except ConfigError as bad:
        raise BadInput(str(bad)) from None
    try:
        require_store(str(db))
    except MetaoptError as missing:
        raise BadInput(str(missing)) from None
    with RunStore(db) as store:
        try:
            run, best = stored_candidate(store, target)
        except StoreError as missing:
            raise BadInput(str(missing)) from None
    if run.problem != "nao-walk":
        raise BadInput(f"run {run.id} is a {run.problem!r} run; a gait comes from a nao-walk run")
    problem_params = resolve(info.params, {**run.problem_params, **walked_with}, "nao-walk")
    names = [variable["name"] for variable in run.space]
    metrics = {e: gait_metrics(problem_params, best.x, best.seed, e) for e in ENGINES}
    gait = {
        "description": description,
        "found_by": {
            "command": command,
            "optimizer": run.optimizer,
            "optimizer_params": run.optimizer_params,
            "settings": run.settings,
            "seed": run.seed,
            "budget": run.budget,
            "run_evaluation_index": best.index,
            "run_candidate": best.number,
            "evaluation_seed": best.seed,
            "metaopt_version": run.versions.get("metaopt"),
            **({"walked_with": walked_with} if walked_with else {}),
        },
        "problem_params": problem_params,
        "parameters": {name: float(value) for name, value in zip(names, best.x)},
        "metrics": metrics,
        "claims": {},
        "engine_versions": engine_versions(),
    }
    gait["claims"] = {engine: claim(gait, engine) for engine in claims}
    for engine, claimed in gait["claims"].items():
        if not walks(claimed):
            raise BadInput(f"the gait does not walk on {engine} ({claimed}): nothing to claim")
    return gait


class BadInput(Exception):
    """What the command line asked for cannot be done; the message says why and what is
    accepted."""


def refused(why: str) -> int:
    """Say in one line on stderr why a request cannot be done; the exit status for bad input."""
    print(f"store_gait.py: {why}", file=sys.stderr)
    return 2


def remeasured(gait: dict, why: str) -> dict:
    """The record gait with what it does on every engine now (see the module's docstring)."""
    metrics = {e: replay_gait(gait, e) for e in ENGINES}
    versions = engine_versions()
    earlier = list(gait.get("earlier_metrics", []))
    # An engine the record did not cover yet (ODE, since issue 16) only adds to it.
    covered = gait["metrics"]
    if any(metrics[e] != covered[e] or versions[e] != gait["engine_versions"][e] for e in covered):
        earlier.append(
            {"why": why, "metrics": gait["metrics"], "engine_versions": gait["engine_versions"]}
        )
    updated = {**gait, "metrics": metrics, "engine_versions": versions}
    updated["claims"] = {engine: claim(updated, engine) for engine in gait["claims"]}
    if earlier:
        updated["earlier_metrics"] = earlier
    return updated


def engine_versions() -> dict[str, str]:
    """The installed version of every engine a record's metrics cover."""
    from metaopt.physics import engine_version
    from metaopt.plugins import registry

    return {engine: engine_version(registry().physics_backend(engine)) for engine in ENGINES}


def walks(claimed: dict) -> bool:
    """Whether a claim describes a walk: falls in under half the episodes, and a median
    distance of at least MIN_CLAIM_DISTANCE."""
    return claimed["max_fall_rate"] < 0.5 and claimed["min_median_distance"] >= MIN_CLAIM_DISTANCE


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", nargs="?", help="run id in the store, or RUN:CANDIDATE")
    parser.add_argument("--db", type=Path)
    parser.add_argument("--name", help="the record's name: gaits/NAME.json")
    parser.add_argument("--command", help="the command that found it")
    parser.add_argument("--description")
    parser.add_argument(
        "--claim", action="append", default=[], choices=ENGINES, help="an engine it walks on"
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="NAME=VALUE", dest="changes",
        help="a problem parameter the record walks with instead of the run's (duration=15)",
    )  # fmt: skip
    parser.add_argument(
        "--gaits", type=Path, default=GAITS, metavar="DIR",
        help="the folder of records (default: the package's problems/nao_walk/gaits)",
    )  # fmt: skip
    parser.add_argument("--remeasure", metavar="NAME", help="re-record gaits/NAME.json")
    parser.add_argument("--why", help="with --remeasure: what changed in the engines")
    args = parser.parse_args(argv)
    if args.remeasure:
        kept = args.gaits / f"{args.remeasure}.json"
        if not args.why or not kept.is_file():
            return refused(f"--remeasure needs a record's name in {args.gaits} and --why")
        name, gait = args.remeasure, remeasured(read_gait(kept), args.why)
    else:
        needed = {"run": args.run, "--db": args.db, "--name": args.name,
                  "--command": args.command, "--description": args.description}  # fmt: skip
        missing = [flag for flag, value in needed.items() if value is None]
        if missing:
            parser.error(f"storing a run's gait needs {', '.join(missing)}")
        name = args.name
        try:
            gait = record(
                args.db, args.run, args.command, args.description, args.claim, args.changes
            )
        except BadInput as bad:
            return refused(str(bad))
    path = args.gaits / f"{name}.json"
    with written_whole(path) as record_file:
        record_file.write(json.dumps(gait, indent=2) + "\n")
    for engine, claimed in gait["claims"].items():
        print(
            f"{engine}: over {claimed['seeds']} seeds at noise {claimed['noise']}: median "
            f"distance >= {claimed['min_median_distance']} m, median |drift| <= "
            f"{claimed['max_median_drift']} m, fall rate <= {claimed['max_fall_rate']}"
            + (f", median flight <= {claimed['max_median_flight']}"
               if "max_median_flight" in claimed else "")
        )  # fmt: skip
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
