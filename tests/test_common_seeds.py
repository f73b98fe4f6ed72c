"""`--common-seeds`: with resampling, every candidate is evaluated on the same K seeds (common
random numbers), so two candidates' fitnesses differ by what the candidates do, not by the
seeds they drew; without it every evaluation has its own seed."""

from __future__ import annotations

import numpy as np
import pytest

from metaopt import Evaluation, Problem, ProblemInfo, Sense, Space
from metaopt.plugins import registry
from metaopt.run_loop import RunSettings, RunSpec, run
from metaopt.storage.run_store import RunStore
from tests.conftest import metaopt_cli


class NoisyLine(Problem):
    """sum(x) plus a standard normal error drawn from the seed."""

    space = Space.from_bounds([-1.0, -1.0], [1.0, 1.0])
    sense = Sense.MINIMIZE

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        error = float(np.random.default_rng(seed).standard_normal())
        return Evaluation(float(np.sum(x)) + error, {"error": error})


def _run(path, common_seeds: bool, resample: int = 3):
    info = ProblemInfo("noisy-line", "test", factory=NoisyLine)
    settings = RunSettings(resample=resample, common_seeds=common_seeds)
    spec = RunSpec("random", "noisy-line", 30, 5, settings=settings)
    with RunStore(path) as store:
        result = run(spec, registry().optimizer("random"), info, store)
        return result, list(store.evaluations(result.run_id))


@pytest.mark.parametrize("common_seeds", [False, True])
def test_common_seeds_give_every_candidate_the_same_k_seeds(tmp_path, common_seeds: bool):
    _, evaluations = _run(tmp_path / "a.db", common_seeds)
    seeds = [e.seed for e in evaluations]
    assert len(seeds) == 30
    if common_seeds:
        assert len(set(seeds[:3])) == 3
        assert seeds == seeds[:3] * 10
    else:
        assert len(set(seeds)) == 30


def test_with_common_seeds_candidates_differ_only_by_what_they_do(tmp_path) -> None:
    for common_seeds, same_error in ((True, True), (False, False)):
        _, evaluations = _run(tmp_path / f"{common_seeds}.db", common_seeds)
        errors = {}
        for e in evaluations:
            errors.setdefault(e.candidate, []).append(e.metrics["error"])
        means = {round(float(np.mean(v)), 12) for v in errors.values()}
        assert (len(means) == 1) is same_error


def test_a_run_with_common_seeds_is_reproducible_and_stored_as_such(tmp_path) -> None:
    first, a = _run(tmp_path / "a.db", True)
    _, b = _run(tmp_path / "b.db", True)
    assert [(e.x.tobytes(), e.fitness, e.seed) for e in a] == [
        (e.x.tobytes(), e.fitness, e.seed) for e in b
    ]
    with RunStore(tmp_path / "a.db") as store:
        assert store.run(first.run_id).settings["common_seeds"] is True


def test_cli_common_seeds_flag(tmp_path) -> None:
    done = metaopt_cli("run", "-o", "random", "-p", "sphere", "--budget", "12", "--resample",
                       "3", "--common-seeds", "--seed", "2", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    with RunStore(tmp_path / "metaopt.db") as store:
        seeds = [e.seed for e in store.evaluations(1)]
    assert seeds == seeds[:3] * 4 and len(set(seeds)) == 3
