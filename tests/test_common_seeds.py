"""`--common-seeds`: with resampling, every candidate is evaluated on the same K seeds (common
random numbers), so two candidates' fitnesses differ by what the candidates do, not by the
seeds they drew; without it every evaluation has its own seed. `--common-seeds batch` shares
the seeds within each sync batch only, with fresh seeds per batch."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from metaopt import ConfigError, Evaluation, Problem, ProblemInfo, Sense, Space
from metaopt.errors import SettingWarning
from metaopt.plugins import registry
from metaopt.running import RunSettings, RunSpec, run
from metaopt.storage.run_store import RunStore
from tests.conftest import metaopt_cli


class NoisyLine(Problem):
    """sum(x) plus a standard normal error drawn from the seed."""

    space = Space.from_bounds([-1.0, -1.0], [1.0, 1.0])
    sense = Sense.MINIMIZE

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        error = float(np.random.default_rng(seed).standard_normal())
        return Evaluation(float(np.sum(x)) + error, {"error": error})


def _run(path, common_seeds: bool | str, resample: int = 3, batch: int = 0, budget: int = 30):
    info = ProblemInfo("noisy-line", "test", factory=NoisyLine)
    settings = RunSettings(resample=resample, common_seeds=common_seeds, batch=batch)
    spec = RunSpec("random", "noisy-line", budget, 5, settings=settings)
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
        assert store.run(first.run_id).settings["common_seeds"] == "run"


def test_a_run_stored_with_common_seeds_true_reads_as_run_wide_seeds() -> None:
    assert RunSettings(common_seeds=True).common_seeds == "run"
    assert RunSettings(common_seeds=False).common_seeds == "off"


@pytest.mark.parametrize("resample", [1, 2])
def test_common_seeds_per_batch_are_shared_within_a_batch_and_fresh_for_each(
    tmp_path, resample: int
) -> None:
    _, evaluations = _run(tmp_path / "a.db", "batch", resample, batch=4, budget=12 * resample)
    seeds_by_batch: dict[int, set[tuple[int, ...]]] = {}
    for candidate in range(12):
        seeds = tuple(e.seed for e in evaluations if e.candidate == candidate)
        assert len(set(seeds)) == resample
        seeds_by_batch.setdefault(candidate // 4, set()).add(seeds)
    assert [len(seeds) for seeds in seeds_by_batch.values()] == [1, 1, 1]
    batch_seeds = [next(iter(seeds)) for seeds in seeds_by_batch.values()]
    assert len({seed for seeds in batch_seeds for seed in seeds}) == 3 * resample
    _, again = _run(tmp_path / "b.db", "batch", resample, batch=4, budget=12 * resample)
    assert [(e.x.tobytes(), e.fitness, e.seed) for e in evaluations] == [
        (e.x.tobytes(), e.fitness, e.seed) for e in again
    ]


def test_common_seeds_per_batch_of_one_candidate_are_flagged_as_seeds_of_its_own(tmp_path):
    info = ProblemInfo("noisy-line", "test", factory=NoisyLine)
    spec = RunSpec("hs", "noisy-line", 40, 5, settings=RunSettings(common_seeds="batch"))
    with RunStore(tmp_path / "a.db") as store, pytest.warns(SettingWarning, match="--batch N"):
        run(spec, registry().optimizer("hs"), info, store)
    with RunStore(tmp_path / "b.db") as store, warnings.catch_warnings():
        warnings.simplefilter("error", SettingWarning)
        batched = RunSpec(
            "hs", "noisy-line", 40, 5, settings=RunSettings(common_seeds="batch", batch=3)
        )
        run(batched, registry().optimizer("hs"), info, store)


def test_common_seeds_refuse_an_unknown_value_and_batches_in_async_mode() -> None:
    with pytest.raises(ConfigError, match="sync mode"):
        RunSettings(common_seeds="batch", mode="async").check(30)
    with pytest.raises(ConfigError, match="accepted: off, run, batch"):
        RunSettings(common_seeds="generation").check(30)


def test_cli_common_seeds_flag(tmp_path) -> None:
    done = metaopt_cli("run", "-o", "random", "-p", "sphere", "--budget", "12", "--resample",
                       "3", "--common-seeds", "--seed", "2", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    with RunStore(tmp_path / "metaopt.db") as store:
        seeds = [e.seed for e in store.evaluations(1)]
    assert seeds == seeds[:3] * 4 and len(set(seeds)) == 3


def test_cli_common_seeds_per_batch(tmp_path) -> None:
    done = metaopt_cli("run", "-o", "random", "-p", "sphere", "--budget", "12", "--batch", "4",
                       "--common-seeds", "batch", "--seed", "2", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    with RunStore(tmp_path / "metaopt.db") as store:
        seeds = [e.seed for e in store.evaluations(1)]
    assert [len(set(seeds[i : i + 4])) for i in (0, 4, 8)] == [1, 1, 1] and len(set(seeds)) == 3
    shown = metaopt_cli("show", "1", cwd=tmp_path)
    assert "common seeds per batch" in shown.stdout, shown.stdout
    refused = metaopt_cli("run", "-o", "random", "-p", "sphere", "--common-seeds", "batch",
                          "--mode", "async", cwd=tmp_path)  # fmt: skip
    assert refused.returncode == 2 and "sync mode" in refused.stderr
    assert "Traceback" not in refused.stderr
