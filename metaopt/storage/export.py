"""Writing a run's evaluations as CSV or JSON."""

from __future__ import annotations

import csv
import json
import math
from typing import Any, TextIO

from metaopt.errors import ConfigError
from metaopt.storage.run_store import RunStore

FORMATS = ("csv", "json")


def finite_json(value: Any) -> Any:
    """``value`` with every infinite or NaN float written as the string float() reads back
    ("inf", "-inf", "nan"): strict JSON has no such numbers, and Python's ``Infinity`` breaks
    other readers (a problem parameter of ``inf``, a metric that diverged)."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, dict):
        return {key: finite_json(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [finite_json(item) for item in value]
    return value


def dump_json(value: Any, out: TextIO) -> None:
    """``value`` as strict JSON (see finite_json) with a final newline: objects indented one
    space a level, and each element of a list on a line of its own (a run's evaluations one per
    line, written by json's C encoder, which indenting everything would bypass)."""
    _write_json(value, out, "")
    out.write("\n")


def _write_json(value: Any, out: TextIO, indent: str) -> None:
    """One value of dump_json's layout at ``indent``."""
    inner = indent + " "
    if isinstance(value, dict) and value:
        out.write("{\n")
        for position, (key, item) in enumerate(value.items()):
            if position:
                out.write(",\n")
            out.write(f"{inner}{json.dumps(str(key))}: ")
            _write_json(item, out, inner)
        out.write(f"\n{indent}}}")
    elif isinstance(value, list | tuple) and value:
        rows = ",\n".join(inner + strict_json(item) for item in value)
        out.write(f"[\n{rows}\n{indent}]")
    else:
        out.write(strict_json(value))


def strict_json(value: Any) -> str:
    """``value`` as one line of strict JSON (see finite_json); finite_json's walk is paid only
    by a value that holds an infinite or NaN float."""
    try:
        return json.dumps(value, allow_nan=False)
    except ValueError:  # a float out of JSON's range somewhere in it
        return json.dumps(finite_json(value), allow_nan=False)


def export_run(store: RunStore, run_id: int | str, fmt: str, out: TextIO) -> int:
    """Write every evaluation of a run to ``out``, each with its candidate (resampled runs
    evaluate a candidate several times), and in JSON the run's settings; return how many
    evaluations were written."""
    if fmt not in FORMATS:
        raise ConfigError(f"unknown export format {fmt!r}; accepted: {', '.join(FORMATS)}")
    run = store.run(run_id)
    names = [v["name"] for v in run.space]
    evaluations = list(store.evaluations(run.id))
    if fmt == "json":
        dump_json(
            {
                "run": {
                    "id": run.id,
                    "optimizer": run.optimizer,
                    "optimizer_params": run.optimizer_params,
                    "problem": run.problem,
                    "problem_params": run.problem_params,
                    "seed": run.seed,
                    "budget": run.budget,
                    "sense": run.sense,
                    "status": run.status,
                    "message": run.message,
                    "settings": run.settings,
                    "wall_time": run.wall_time,
                    "space": run.space,
                    "versions": run.versions,
                },
                "evaluations": [
                    {
                        "index": e.index,
                        "candidate": e.candidate,
                        "status": e.status,
                        "fitness": e.fitness,
                        "x": dict(zip(names, e.x.tolist())),
                        "metrics": e.metrics,
                        "error": e.error,
                        "seed": e.seed,
                        "wall_time": e.wall_time,
                    }
                    for e in evaluations
                ],
            },
            out,
        )
        return len(evaluations)
    metric_names = sorted({name for e in evaluations for name in e.metrics})
    writer = csv.writer(out, lineterminator="\n")
    header = ["index", "candidate", "status", "fitness", *names, *metric_names]
    writer.writerow([*header, "seed", "wall_time", "error"])
    for e in evaluations:
        writer.writerow(
            [
                e.index,
                e.candidate,
                e.status,
                "" if e.fitness is None else repr(e.fitness),
                *(repr(v) for v in e.x.tolist()),
                *(e.metrics.get(m, "") for m in metric_names),
                e.seed,
                f"{e.wall_time:.6g}",
                e.error or "",
            ]
        )
    return len(evaluations)
