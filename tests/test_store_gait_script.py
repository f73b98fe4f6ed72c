"""scripts/store_gait.py keeps a stored run's gait as a record that replays to what it says on
every engine, and refuses a request it cannot do in one line, writing nothing."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.stored_gaits import (
    ENGINES,
    controller_params,
    load_gait,
    replay_gait,
)
from tests.engines import ODE_MISSING
from tests.walk_runs import store_walk_run

SCRIPT = Path(__file__).parents[1] / "scripts" / "store_gait.py"
COMMAND = "metaopt run --optimizer hs --problem nao-walk --set duration=3 --set lock=1"


def store_gait(*args: str | Path) -> subprocess.CompletedProcess:
    """The script run with args, as a user runs it."""
    return subprocess.run(
        [sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=600
    )


@pytest.fixture(scope="module")
def walk_store(tmp_path_factory) -> tuple[Path, int]:
    """A store holding a short nao-walk run whose best candidate is the stored HS gait."""
    db = tmp_path_factory.mktemp("store") / "walk.db"
    return db, store_walk_run(db)


def store_args(db: Path, target: str, gaits: Path, *more: str) -> list[str | Path]:
    return [target, "--db", db, "--name", "kept", "--command", COMMAND,
            "--description", "a test's gait", "--gaits", gaits, *more]  # fmt: skip


@pytest.mark.skipif(bool(ODE_MISSING), reason=ODE_MISSING or "ODE is installed")
def test_a_stored_record_replays_to_its_metrics_on_every_engine(walk_store, tmp_path):
    """The record's episode re-run from the record alone (its parameters by name, its problem
    parameters, its evaluation's seed) gives exactly the metrics it holds, on every engine; a
    --set change walks with the record and is kept as found_by.walked_with."""
    db, run_id = walk_store
    done = store_gait(*store_args(db, str(run_id), tmp_path, "--set", "duration=3.5"))
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "kept.json").read_text())
    assert record["found_by"]["walked_with"] == {"duration": 3.5}
    assert record["problem_params"]["duration"] == 3.5
    assert record["found_by"]["run_candidate"] == 1  # the HS gait, not the lower bounds
    controller = record["problem_params"]["controller"]
    assert tuple(record["parameters"]) == controller_params(controller)
    assert record["parameters"] == load_gait()["parameters"]
    assert record["claims"] == {} and set(record["metrics"]) == set(ENGINES)
    for engine in ENGINES:
        assert replay_gait(record, engine) == record["metrics"][engine], engine
    assert [p.name for p in tmp_path.iterdir()] == ["kept.json"]  # no temporary file left


@pytest.mark.skipif(bool(ODE_MISSING), reason=ODE_MISSING or "ODE is installed")
def test_remeasure_re_records_a_record_kept_in_another_folder(walk_store, tmp_path):
    """--remeasure reads the record from --gaits and, on the engines that made it, measures
    the same metrics again: nothing is moved to earlier_metrics."""
    db, run_id = walk_store
    assert store_gait(*store_args(db, str(run_id), tmp_path)).returncode == 0
    stored = json.loads((tmp_path / "kept.json").read_text(encoding="utf-8"))
    done = store_gait("--remeasure", "kept", "--why", "a test", "--gaits", tmp_path)
    assert done.returncode == 0, done.stderr
    again = json.loads((tmp_path / "kept.json").read_text(encoding="utf-8"))
    assert again == stored and "earlier_metrics" not in again


@pytest.mark.parametrize(
    ("more", "said"),
    [
        (["--set", "duration=abc"], "duration"),
        (["--set", "no_such_parameter=1"], "no_such_parameter"),
        (["--claim", "mujoco"], "does not walk on mujoco"),  # 2 s of walking: under 0.5 m
    ],
)
def test_a_request_it_cannot_do_is_refused_in_one_line(walk_store, tmp_path, more, said):
    db, run_id = walk_store
    done = store_gait(*store_args(db, str(run_id), tmp_path, *more))
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert said in done.stderr.strip().splitlines()[-1]
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_missing_store_run_or_problem_is_refused_in_one_line(walk_store, tmp_path):
    db, run_id = walk_store
    other = tmp_path / "other.db"
    with RunStore(other) as store:
        sphere = store.create_run(
            optimizer="hs", optimizer_params={}, problem="sphere", problem_params={},
            seed=0, budget=1, sense="minimize", space=[], settings={}, versions={},
        )  # fmt: skip
        store.add_evaluation(sphere, 0, 0, [0.0], 0.0, None, None, 0, 0.1)
    gaits = tmp_path / "gaits"
    gaits.mkdir()
    for args, said in [
        (store_args(tmp_path / "none.db", "1", gaits), "no run store at"),
        (store_args(db, str(run_id + 7), gaits), str(run_id + 7)),
        (store_args(other, str(sphere), gaits), "'sphere' run"),
        (["--remeasure", "kept", "--gaits", gaits], "--why"),
    ]:
        done = store_gait(*args)
        assert done.returncode == 2, args
        assert "Traceback" not in done.stderr
        assert said in done.stderr.strip().splitlines()[-1], (args, done.stderr)
        assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert list(gaits.iterdir()) == []
    assert not (tmp_path / "none.db").exists()
