"""Cross-engine transfer: each finished run's best candidate replayed on every installed physics
engine it was not found on, beside what it scored where it was found."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from metaopt.assessment.replay import Replay, replay_candidate, run_source
from metaopt.comparison.experiment import Experiment
from metaopt.comparison.summary import (
    CellRuns,
    center,
    describe,
    finished_runs,
    problem_traits,
    shown_metrics,
)
from metaopt.errors import ConfigError
from metaopt.params import resolve
from metaopt.physics import engine_names
from metaopt.plugins import Registry
from metaopt.reporting.recent import is_flag
from metaopt.reporting.result_table import Column, ResultTable, Row
from metaopt.storage.experiment_store import ExperimentStore


@dataclass(frozen=True)
class Transfer:
    """A cell's runs, found on ``found_on``, replayed on ``replayed_on``."""

    cell: CellRuns
    found_on: str
    replayed_on: str
    replays: list[Replay]


def replay_on_other_engines(
    experiment: Experiment, store: ExperimentStore, plugins: Registry
) -> list[Transfer]:
    """Every cell's finished runs replayed on each installed engine its backend does not name."""
    info = plugins.problem(experiment.problem)
    if "backend" not in {p.name for p in info.params}:
        raise ConfigError(
            f"--transfer replays on other physics engines, but problem {info.name!r} has no "
            "'backend' parameter"
        )
    transfers = []
    for cell in finished_runs(experiment, store, problem_traits(experiment, plugins)):
        found_on = resolve(info.params, cell.cell.problem_params, info.name)["backend"]
        runs = [r for r in cell.runs if r.best_fitness is not None]
        for engine in plugins.available_physics_backends():
            if engine not in engine_names(found_on):
                replays = [
                    replay_candidate(run_source(store, r.run.id), plugins, {"backend": engine})
                    for r in runs
                ]
                transfers.append(Transfer(cell, found_on, engine, replays))
    return transfers


def transfer_table(
    experiment: Experiment, transfers: Sequence[Transfer], plugins: Registry
) -> ResultTable:
    """Per cell and other engine: medians found -> replayed of the fitness and the key metrics
    (rates for flags such as 'fell'), the median per-run fitness gap found - replayed, and the
    number of replays that failed."""
    replays = [replay for t in transfers for replay in t.replays]
    key_metrics = problem_traits(experiment, plugins).key_metrics
    metrics = [m for m in shown_metrics(key_metrics, (r.source.metrics for r in replays))
               if "@" not in m]  # fmt: skip
    flags = {
        name: is_flag(
            metrics[name]
            for replay in replays
            for metrics in (replay.source.metrics, replay.replayed.metrics)
            if name in metrics
        )
        for name in metrics
    }
    columns = [
        Column("optimizer", ("optimizer",)),
        Column("setting", ("setting",)),
        Column("found on → replayed on", ("found_on", "replayed_on"), "{} → {}"),
        Column("runs", ("runs",)),
        Column("fitness median\nfound → replayed", ("fitness_found", "fitness_replayed"),
               "{} → {}"),
        Column("gap\nmedian", ("fitness_gap",)),
        *(
            Column(f"{name}{' rate' if flags[name] else ' median'}\nfound → replayed",
                   (f"{name}_found", f"{name}_replayed"), "{} → {}", percent=flags[name])
            for name in metrics
        ),
        Column("failed\nreplays", ("failed",)),
    ]  # fmt: skip
    rows = [_row(t, metrics, flags) for t in transfers]
    title = f"experiment {describe(experiment)}: each run's best replayed on the other engines"
    return ResultTable(title, columns, rows)


def _row(transfer: Transfer, metrics: list[str], flags: dict[str, bool]) -> Row:
    done = [r for r in transfer.replays if r.replayed.fitness is not None]
    row: Row = {
        "optimizer": transfer.cell.cell.optimizer.label,
        "setting": transfer.cell.cell.setting or None,
        "found_on": transfer.found_on,
        "replayed_on": transfer.replayed_on,
        "runs": len(transfer.replays),
        "fitness_found": center([r.source.fitness for r in transfer.replays], False),
        "fitness_replayed": center([r.replayed.fitness for r in done], False),
        "fitness_gap": center([r.source.fitness - r.replayed.fitness for r in done], False),
        "failed": len(transfer.replays) - len(done),
    }
    for name in metrics:
        found = [r.source.metrics[name] for r in transfer.replays if name in r.source.metrics]
        replayed = [r.replayed.metrics[name] for r in done if name in r.replayed.metrics]
        row[f"{name}_found"] = center(found, flags[name])
        row[f"{name}_replayed"] = center(replayed, flags[name])
    return row
