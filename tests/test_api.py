"""metaopt from Python: minimize/maximize a function, create_optimizer, and the run's target."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

import metaopt
from metaopt.storage.run_store import RunStore


def sphere(x: np.ndarray) -> float:
    return float(np.sum((x - 0.5) ** 2))


def test_minimize_finds_the_minimum_and_returns_the_history():
    result = metaopt.minimize(sphere, [(-5.0, 5.0)] * 4, budget=3000, seed=1)
    assert result.fitness < 1e-4 and np.abs(result.x - 0.5).max() < 0.01
    assert result.evaluations == 3000 and result.failed == 0 and result.run_id is None
    history = result.history
    assert history.x.shape == (3000, 4) and history.fitness.shape == (3000,)
    np.testing.assert_array_equal(history.best, np.minimum.accumulate(history.fitness))
    assert history.fitness.min() == result.fitness == sphere(result.x)
    again = metaopt.minimize(sphere, [(-5.0, 5.0)] * 4, budget=3000, seed=1)
    np.testing.assert_array_equal(again.history.x, history.x)  # same seed, same run


def test_a_run_without_a_store_leaves_no_file(tmp_path, monkeypatch):
    """store=None keeps the run in memory: no file (one named ':memory:' included) is made."""
    monkeypatch.chdir(tmp_path)
    assert metaopt.minimize(sphere, [(-5.0, 5.0)] * 2, budget=50, seed=1).run_id is None
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kind", ["file", "folder"])
def test_a_run_without_a_store_ignores_a_file_named_memory_in_the_folder(
    tmp_path, monkeypatch, kind
):
    """SQLite's in-memory store is not the file ':memory:' of the working folder: a file or a
    folder of that name is neither refused nor touched."""
    monkeypatch.chdir(tmp_path)
    named = tmp_path / ":memory:"
    if kind == "folder":
        named.mkdir()
    else:
        named.write_text("not a database")
    assert metaopt.minimize(sphere, [(-5.0, 5.0)] * 2, budget=50, seed=1).run_id is None
    assert list(tmp_path.iterdir()) == [named]
    assert kind == "folder" or named.read_text() == "not a database"


def test_maximize_any_optimizer_with_named_variables_and_its_parameters():
    bounds = {"width": (0.0, 2.0), "height": (-1.0, 1.0)}
    result = metaopt.maximize(
        lambda x: -sphere(x), bounds, "ga", budget=2000, seed=3, population=20
    )
    assert result.fitness > -1e-3 and result.fitness == result.history.best[-1]
    np.testing.assert_array_equal(
        result.history.best, np.maximum.accumulate(result.history.fitness)
    )


def test_the_target_stops_the_run_at_the_first_fitness_that_good():
    result = metaopt.minimize(sphere, [(-5.0, 5.0)] * 3, budget=50_000, seed=2, target=1e-2)
    assert result.fitness <= 1e-2 < result.history.fitness[:-1].min()
    assert result.evaluations == len(result.history.fitness) < 50_000
    with pytest.raises(metaopt.ConfigError, match="target must be a finite fitness"):
        metaopt.minimize(sphere, [(0.0, 1.0)], target=float("nan"))


def test_max_time_stops_the_run_with_what_it_has_done():
    def slow(x: np.ndarray) -> float:
        time.sleep(0.01)
        return sphere(x)

    result = metaopt.minimize(slow, [(-5.0, 5.0)] * 2, budget=100_000, seed=2, max_time=0.5)
    assert 0 < result.evaluations == len(result.history.fitness) < 100  # 100 take a second
    assert result.fitness == result.history.best[-1]
    with pytest.raises(metaopt.ConfigError, match="max time must be positive"):
        metaopt.minimize(sphere, [(0.0, 1.0)], max_time=0)


def test_a_stored_run_is_in_the_store_for_runs_show_and_report(tmp_path):
    db = tmp_path / "api.db"
    result = metaopt.minimize(sphere, [(-1.0, 1.0)] * 2, budget=200, seed=4, store=db)
    with RunStore(db) as store:
        record = store.run(result.run_id)
        stored = [e.fitness for e in store.evaluations(result.run_id)]
    assert record.problem == "python:sphere" and record.optimizer == "hs"
    assert record.status == "finished" and record.optimizer_params["budget"] == 200
    np.testing.assert_array_equal(stored, result.history.fitness)


@pytest.mark.parametrize(
    ("optimizer", "params", "message"),
    [
        ("nosuch", {}, "unknown optimizer 'nosuch'"),
        ("hs", {"par_min": 0.9, "par_max": 0.1}, "par_min"),  # refused as the optimizer is built
    ],
)
def test_a_refused_run_leaves_no_store_behind(tmp_path, optimizer, params, message):
    db = tmp_path / "api.db"
    with pytest.raises(metaopt.ConfigError, match=message):
        metaopt.minimize(sphere, [(-1.0, 1.0)], optimizer, budget=50, store=db, **params)
    assert list(tmp_path.iterdir()) == []


def test_a_run_its_store_refuses_gives_the_error_alone_and_a_run_that_starts_its_warning(
    tmp_path,
):
    """A setting's warning (a budget that only fills HS's memory) comes once nothing refuses
    the run: not before the store's error, and once when it runs."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(metaopt.StoreError, match="cannot use"):
            metaopt.minimize(
                sphere, [(-1.0, 1.0)], budget=5, seed=1, store=tmp_path / "no" / "a.db"
            )
    assert caught == []
    with pytest.warns(metaopt.SettingWarning, match=r"^hs: hms 20 is not smaller") as warned:
        metaopt.minimize(sphere, [(-1.0, 1.0)], budget=5, seed=1, store=tmp_path / "a.db")
    assert len(warned) == 1


def test_failed_evaluations_count_and_a_function_that_always_fails_is_reported():
    def half_broken(x: np.ndarray) -> float:
        if x[0] < 0:
            raise ValueError("cannot evaluate left of 0")
        return float(x[0])

    result = metaopt.minimize(half_broken, [(-1.0, 1.0)], budget=300, seed=1)
    assert 0 < result.failed < 300 and result.fitness >= 0.0
    assert np.isnan(result.history.fitness).sum() == result.failed

    def broken(x: np.ndarray) -> float:
        raise ValueError("no")

    with pytest.raises(metaopt.RunFailed, match=r"all 10 evaluations failed.*ValueError: no"):
        metaopt.minimize(broken, [(0.0, 1.0)], budget=20, seed=1, hms=5)


def test_create_optimizer_fills_defaults_validates_and_passes_the_budget():
    for name in ("hs", "ga", "random"):
        optimizer = metaopt.create_optimizer(name, [(0.0, 1.0)] * 3, seed=1, budget=500)
        batch = optimizer.ask(optimizer.batch_size)
        optimizer.tell(batch, batch.sum(axis=1))
    hs = metaopt.create_optimizer("hs", [(0.0, 1.0)], budget=500, hms=5)
    assert hs.budget == 500 and hs.hms == 5 and hs.pitch_adjust == "ihs"
    assert metaopt.create_optimizer("ga", [(0.0, 1.0)], budget=700).budget == 700


@pytest.mark.parametrize(
    ("name", "bounds", "params", "message"),
    [
        ("hss", [(0, 1)], {}, "unknown optimizer 'hss'. Did you mean 'hs'"),
        ("hs", [(0, 1)], {"hmc": 0.5}, "no parameter 'hmc'. Did you mean 'hmcr'"),
        ("hs", [(0, 1)], {"hmcr": 2.0}, r"expected a float in \[0, 1\]"),
        ("hs", [(1, 0)], {}, "lower bound 1.0 >= upper bound 0.0"),
        ("hs", [1, 2], {}, r"sequence of \(lower, upper\) pairs"),
        ("hs", 5, {}, r"sequence of \(lower, upper\) pairs"),
        ("hs", None, {}, r"sequence of \(lower, upper\) pairs"),
        # a generator of pairs is read once, as bounds: what is refused is the hmcr
        ("hs", ((0, 1) for _ in range(2)), {"hmcr": 2.0}, r"expected a float in \[0, 1\]"),
    ],
)
def test_bad_input_is_one_clear_metaopt_error(name, bounds, params, message):
    with pytest.raises(metaopt.MetaoptError, match=message):
        metaopt.create_optimizer(name, bounds, **params)
    with pytest.raises(metaopt.ConfigError, match="f must be a function of x"):
        metaopt.minimize("f", [(0, 1)])


def _two_part(x: np.ndarray) -> float:
    """A cheap part (the sphere, its bound) plus a penalty past 1, never negative."""
    return sphere(x) + float(np.sum(np.maximum(x - 1.0, 0.0)))


def test_a_bound_screens_cmaes_without_changing_its_run_and_calls_f_less():
    calls = []

    def counted(x: np.ndarray) -> float:
        calls.append(x)
        return _two_part(x)

    bounds, settings = [(-2.0, 2.0)] * 4, {"budget": 480, "seed": 3, "population": 16}
    plain = metaopt.minimize(_two_part, bounds, "cmaes", **settings)
    screened = metaopt.minimize(counted, bounds, "cmaes", bound=sphere, **settings)
    assert screened.fitness == plain.fitness and np.array_equal(screened.x, plain.x)
    np.testing.assert_array_equal(screened.history.x, plain.history.x)  # the same asks
    assert (plain.screened, plain.history.screened.any()) == (0, False)
    assert 480 // 4 < screened.screened == screened.history.screened.sum() < 480 // 2 + 1
    assert len(calls) == 480 - screened.screened and screened.failed == 0
    shown = screened.history.fitness
    np.testing.assert_array_equal(np.isnan(shown), screened.history.screened)
    kept = ~screened.history.screened
    np.testing.assert_array_equal(shown[kept], plain.history.fitness[kept])


def test_maximize_screens_with_an_upper_bound():
    def score(x: np.ndarray) -> float:
        return -_two_part(x)

    def ceiling(x: np.ndarray) -> float:
        return -sphere(x)

    plain = metaopt.maximize(score, [(-2.0, 2.0)] * 3, "cmaes", budget=240, seed=5)
    screened = metaopt.maximize(score, [(-2.0, 2.0)] * 3, "cmaes", budget=240, seed=5,
                                bound=ceiling)  # fmt: skip
    assert screened.fitness == plain.fitness and screened.screened > 0


def test_a_bound_that_f_beats_stops_the_run_naming_the_candidate():
    with pytest.raises(metaopt.RunFailed, match=r"candidate \d+'s fitness .* is better than its "
                       "screen's .* no bound on its fitness"):  # fmt: skip
        metaopt.minimize(sphere, [(-2.0, 2.0)] * 3, "cmaes", budget=120, seed=1,
                         bound=lambda x: sphere(x) + 1.0)  # fmt: skip


def test_a_bound_needs_an_optimizer_that_reads_only_its_best_ranks():
    with pytest.raises(metaopt.ConfigError, match="reads every candidate's fitness"):
        metaopt.minimize(_two_part, [(0.0, 1.0)] * 2, "hs", budget=50, bound=sphere)
    with pytest.raises(metaopt.ConfigError, match="bound must be a function of x or None"):
        metaopt.minimize(_two_part, [(0.0, 1.0)] * 2, "cmaes", budget=50, bound=1.0)
