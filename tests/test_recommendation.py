"""``RUN:recommended``: what a run's optimizer recommends beside its best evaluated candidate
(CMA-ES: the mean of its last distribution), rebuilt from the run's checkpoint and named to
`metaopt replay`, `metaopt robustness` and `metaopt run --start-from` like a candidate."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from metaopt.assessment.candidates import find_candidates
from metaopt.assessment.replay import find_source, replay_candidate
from metaopt.plugins import registry
from metaopt.space import Space
from metaopt.storage.run_store import RunStore
from metaopt_plugins.cma_es import default_population
from tests.conftest import metaopt_cli, one_error_line


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Run 1: cmaes on the 10-d sphere, 300 evaluations; run 2: hs, which recommends nothing."""
    where = tmp_path_factory.mktemp("recommended")
    for optimizer, budget in (("cmaes", "300"), ("hs", "20")):
        made = metaopt_cli("run", "-o", optimizer, "-p", "sphere", "--budget", budget,
                           "--seed", "5", "--db", "runs.db", cwd=where)  # fmt: skip
        assert made.returncode == 0, made.stderr
    return where


def _mean_in_bounds(db: str) -> np.ndarray:
    """Run 1's last CMA-ES mean, read from its stored state, in the problem's coordinates."""
    with RunStore(db) as store:
        run = store.run(1)
    space = Space.from_json(run.space)
    unit = np.array(run.checkpoint["state"]["mean"])
    return np.clip(space.lower + unit * space.width, space.lower, space.upper)


def test_a_cmaes_run_recommends_its_last_mean_which_it_never_evaluated(runs: Path) -> None:
    db = str(runs / "runs.db")
    expected = _mean_in_bounds(db)
    source = find_source("1:recommended", registry(), db)
    assert np.array_equal(source.x, expected)
    assert "recommended by cmaes" in source.label and source.fitness is None
    with RunStore(db) as store:
        best = store.best_candidate(store.run(1))
        evaluations = list(store.evaluations(1))
    generation = default_population(len(expected))  # the run left cmaes's own lambda
    last_generation = [e.fitness for e in evaluations[-generation:]]
    assert not any(np.array_equal(e.x, expected) for e in evaluations)
    assert source.samples == [(e.index, e.seed) for e in best.samples]  # the best's world
    replayed = replay_candidate(source, registry(), {}).replayed.fitness
    assert replayed == pytest.approx(float(np.sum(expected**2)))
    # The centre of a converging distribution beats what it still samples around it.
    assert replayed < np.median(last_generation)
    (candidate,), info = find_candidates("1:recommended", registry().problems, db, 3)
    assert info.name == "sphere" and candidate.label == "run 1 recommended"
    assert candidate.target == "1:recommended" and np.array_equal(candidate.x, expected)
    # named as the run's id reads, so that robustness knows '01:recommended' for the same one
    (again,), _ = find_candidates("01:recommended", registry().problems, db, 1)
    assert again.target == "1:recommended"


def test_replay_and_start_from_take_a_recommendation(runs: Path) -> None:
    replayed = metaopt_cli("replay", "1:recommended", "--db", "runs.db", cwd=runs)
    assert replayed.returncode == 0, replayed.stderr
    assert "run 1, recommended by cmaes (not evaluated" in " ".join(replayed.stdout.split())
    started = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "10", "--seed", "1",
                          "--start-from", "1:recommended", "--db", "runs.db", cwd=runs)  # fmt: skip
    assert started.returncode == 0, started.stderr
    with RunStore(str(runs / "runs.db")) as store:
        first = next(e for e in store.evaluations(3) if e.candidate == 0)
    assert np.array_equal(first.x, _mean_in_bounds(str(runs / "runs.db")))


def test_robustness_tables_a_recommendation_and_names_it_in_its_ranking(tmp_path: Path) -> None:
    made = metaopt_cli("run", "-o", "cmaes", "-p", "nao-walk", "--budget", "24", "--seed", "2",
                       "--set", "duration=4", "--set", "lock=1", "--set", "backend=mujoco",
                       "--db", "runs.db", cwd=tmp_path)  # fmt: skip
    assert made.returncode == 0, made.stderr
    tabled = metaopt_cli("robustness", "1:recommended", "1", "--cells", "nominal", "--seeds", "1",
                         "--ranking", "ranking.csv", "--db", "runs.db", cwd=tmp_path)  # fmt: skip
    assert tabled.returncode == 0, tabled.stderr
    with open(tmp_path / "ranking.csv") as handle:
        ranked = {row["target"]: row["candidate"] for row in csv.DictReader(handle)}
    assert ranked["1:recommended"] == "run 1 recommended"
    assert len(ranked) == 2


def test_a_run_whose_optimizer_recommends_nothing_is_refused_in_one_line(runs: Path) -> None:
    for command in ("replay", "robustness"):
        refused = metaopt_cli(command, "2:recommended", "--db", "runs.db", cwd=runs)
        one_error_line(refused, "run 2's optimizer 'hs' recommends nothing", "name that one (2)")
    misspelt = metaopt_cli("replay", "1:recomended", "--db", "runs.db", cwd=runs)
    one_error_line(misspelt, "RUN:recommended")
