"""Harmony Search plugin: memory rules, pitch variants, bounds, convergence, JSON state."""

from __future__ import annotations

import json

import numpy as np
import pytest

from metaopt import ConfigError, Space
from metaopt.params import resolve
from metaopt.plugins import LOAD_PLUGINS_ENV, Registry, build_manager
from metaopt_plugins.harmony_search import PITCH_ADJUSTMENTS, HarmonySearch, metaopt_optimizers

INFO = metaopt_optimizers()[0]
SPHERE_SPACE = Space.from_bounds([-5.12] * 10, [5.12] * 10)
#: Variables of very different widths, one of them narrow.
MIXED_SPACE = Space.from_bounds([-100.0, 0.0, 5.0, -1e-3], [-99.0, 1e-6, 1000.0, 1e-3])


def build(space: Space = SPHERE_SPACE, seed: int = 0, **given) -> HarmonySearch:
    """An optimizer built the way the run loop builds it: declared params, validated."""
    return INFO.factory(space, seed, **resolve(INFO.params, given, "hs"))


def sphere(x: np.ndarray) -> np.ndarray:
    return np.sum(np.atleast_2d(x) ** 2, axis=1)


def run(optimizer: HarmonySearch, evaluations: int, batch: int = 1) -> np.ndarray:
    """A minimal ask/tell loop on the sphere; returns every asked candidate in order."""
    asked = []
    for _ in range(-(-evaluations // batch)):
        candidates = optimizer.ask(batch)
        optimizer.tell(candidates, sphere(candidates))
        asked.append(candidates)
    return np.concatenate(asked)


def fill(optimizer: HarmonySearch, memory: np.ndarray, fitness: np.ndarray | None = None) -> None:
    """Fill the memory with chosen rows (tell accepts any candidates)."""
    optimizer.tell(memory, np.arange(len(memory), dtype=float) if fitness is None else fitness)


def in_column(values: np.ndarray, memory: np.ndarray) -> np.ndarray:
    """For each value, whether it equals a memory value of the same variable."""
    return (values[:, None, :] == memory[None, :, :]).any(axis=1)


def test_registered_through_its_entry_point(monkeypatch):
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "harmony_search")
    manager, sources = build_manager()
    info = Registry(manager, sources).optimizer("hs")
    assert info.factory is HarmonySearch
    assert HarmonySearch.steady_state and build().batch_size == 1


@pytest.mark.parametrize(
    "given",
    [
        {"hmcr": 1.5},
        {"hmcr": -0.1},
        {"par": 2.0},
        {"hms": 0},
        {"bandwidth": 0.0},
        {"pitch_adjust": "wobble"},
        {"budget": 0},
        {"bandwidth_min": 0.0},
        {"repair": "wrap"},
    ],
)
def test_bad_parameters_rejected(given):
    with pytest.raises(ConfigError):
        resolve(INFO.params, given, "hs")


def test_inverted_schedule_bounds_rejected():
    with pytest.raises(ConfigError, match="par_min"):
        build(par_min=0.9, par_max=0.1)
    with pytest.raises(ConfigError, match="bandwidth_min"):
        build(bandwidth_min=0.1, bandwidth_max=0.01)


def test_harmonies_come_from_the_memory_as_it_is_when_asked():
    optimizer = build(hms=2, hmcr=1.0, par=0.0, pitch_adjust="bandwidth")
    fill(optimizer, np.array([[1.0] * 10, [2.0] * 10]), np.array([1.0, 2.0]))
    for _ in range(40):  # harmonies are built ahead in batches: some are waiting now
        assert np.isin(optimizer.ask(1), [1.0, 2.0]).all()
    optimizer.tell(np.full((1, 10), 3.0), np.array([0.5]))  # replaces the row of 2.0
    later = np.concatenate([optimizer.ask(1) for _ in range(100)])
    assert np.isin(later, [1.0, 3.0]).all()


def test_random_points_until_memory_is_full():
    optimizer = build(hms=5)
    first = optimizer.ask(8)  # more than hms asked before any result: all random
    optimizer.tell(first[:4], sphere(first[:4]))
    optimizer.ask(3)
    assert optimizer.improvisations == 0
    optimizer.tell(first[4:5], sphere(first[4:5]))  # the fifth result fills the memory
    np.testing.assert_array_equal(optimizer.harmony_memory, first[:5])
    optimizer.ask(1)
    assert optimizer.improvisations == 1


@pytest.mark.parametrize("pitch_adjust", PITCH_ADJUSTMENTS)
def test_hmcr_one_par_zero_only_recombines_memory(pitch_adjust):
    optimizer = build(hms=7, hmcr=1.0, par=0.0, par_min=0.0, par_max=0.0, pitch_adjust=pitch_adjust)
    run(optimizer, 7)
    harmonies = optimizer.ask(3000)
    memory = optimizer.harmony_memory
    assert in_column(harmonies, memory).all()
    is_memory_row = (harmonies[:, None, :] == memory[None]).all(axis=2).any(axis=1)
    assert not is_memory_row.all()  # values are recombined, not whole rows copied


@pytest.mark.parametrize("repair", ["clip", "reflect"])
@pytest.mark.parametrize("pitch_adjust", PITCH_ADJUSTMENTS)
def test_everything_stays_in_bounds(pitch_adjust, repair):
    optimizer = build(
        MIXED_SPACE,
        hms=5,
        hmcr=0.9,
        par=1.0,
        par_min=1.0,
        par_max=1.0,
        bandwidth=1.0,
        bandwidth_min=1.0,
        bandwidth_max=1.0,
        pitch_adjust=pitch_adjust,
        repair=repair,
    )
    asked = run(optimizer, 3000, batch=3)
    assert MIXED_SPACE.contains(asked)
    assert MIXED_SPACE.contains(optimizer.harmony_memory)


def test_worst_replaced_only_by_strictly_better():
    optimizer = build(hms=4)
    memory = SPHERE_SPACE.sample(np.random.default_rng(1), 4)
    fill(optimizer, memory, np.array([3.0, 1.0, 7.0, 2.0]))
    newcomer = np.full((1, 10), 0.5)
    optimizer.tell(newcomer, np.array([7.5]))
    optimizer.tell(newcomer, np.array([7.0]))  # equal to the worst: not better
    np.testing.assert_array_equal(optimizer.harmony_memory, memory)
    np.testing.assert_array_equal(optimizer.harmony_fitness, [3.0, 1.0, 7.0, 2.0])
    optimizer.tell(newcomer, np.array([6.0]))
    np.testing.assert_array_equal(optimizer.harmony_memory[2], newcomer[0])
    np.testing.assert_array_equal(optimizer.harmony_fitness, [3.0, 1.0, 6.0, 2.0])
    optimizer.tell(newcomer * 2, np.array([2.5]))  # now the worst is row 2 again (6.0)
    np.testing.assert_array_equal(optimizer.harmony_fitness, [3.0, 1.0, 2.5, 2.0])


def test_nan_while_filling_counts_as_the_worst():
    optimizer = build(hms=3)
    memory = SPHERE_SPACE.sample(np.random.default_rng(6), 3)
    fill(optimizer, memory, np.array([1.0, np.nan, 2.0]))
    assert optimizer.harmony_fitness[1] == np.inf
    optimizer.tell(np.zeros((1, 10)), np.array([5.0]))
    np.testing.assert_array_equal(optimizer.harmony_fitness, [1.0, 5.0, 2.0])


def test_bandwidth_moves_within_bandwidth_times_range():
    space = Space.from_bounds([0.0, -50.0], [1.0, 50.0])
    optimizer = build(space, hms=3, hmcr=1.0, par=1.0, bandwidth=0.05, pitch_adjust="bandwidth")
    memory = space.lower + np.array([[0.25], [0.5], [0.75]]) * space.width
    fill(optimizer, memory)
    steps = optimizer.ask(4000)[:, None, :] - memory[None]
    nearest = np.take_along_axis(steps, np.abs(steps).argmin(axis=1)[:, None, :], 1)[:, 0]
    relative = nearest / (0.05 * space.width)
    assert np.abs(relative).max() <= 1.0
    assert np.abs(relative).max() > 0.99  # the whole bandwidth is used ...
    assert abs(np.mean(np.abs(relative) < 0.5) - 0.5) < 0.05  # ... uniformly
    assert abs(relative.mean()) < 0.05


def test_resample_draws_uniformly_over_the_whole_range():
    space = Space.from_bounds([0.0, -50.0], [1.0, 50.0])
    optimizer = build(space, hms=3, hmcr=1.0, par=1.0, pitch_adjust="resample")
    corner = space.lower + np.array([[0.01], [0.02], [0.03]]) * space.width
    fill(optimizer, corner)
    unit = (optimizer.ask(5000) - space.lower) / space.width
    for column in unit.T:
        counts = np.histogram(column, bins=10, range=(0.0, 1.0))[0]
        assert np.all(np.abs(counts - 500) < 5 * np.sqrt(500 * 0.9))


def test_ghs_takes_values_from_the_best_harmony():
    optimizer = build(hms=6, hmcr=1.0, par_min=1.0, par_max=1.0, pitch_adjust="ghs")
    memory = SPHERE_SPACE.sample(np.random.default_rng(2), 6)
    fill(optimizer, memory, np.array([5.0, 4.0, 0.5, 3.0, 2.0, 1.0]))
    harmonies = optimizer.ask(2000)
    best = memory[2]
    assert np.isin(harmonies, best).all()
    # a random variable of the best: each of its values shows up in every variable
    for column in harmonies.T:
        assert set(np.unique(column)) == set(best)


def test_ghs_par_rises_from_par_min_to_par_max():
    optimizer = build(hms=4, hmcr=1.0, par_min=0.0, par_max=1.0, budget=1004, pitch_adjust="ghs")
    memory = SPHERE_SPACE.sample(np.random.default_rng(3), 4)
    fill(optimizer, memory, np.array([1.0, 2.0, 3.0, 4.0]))
    harmonies = optimizer.ask(1000)
    # A value of another variable of the best harmony: PAR * 9/10 of the values.
    moved = ~in_column(harmonies, memory)
    assert moved[:100].mean() < 0.12  # PAR 0 .. 0.1
    assert moved[-100:].mean() > 0.75  # PAR 0.9 .. 1


def test_ihs_schedules_at_start_middle_and_end():
    optimizer = build(
        hms=10,
        budget=1010,
        pitch_adjust="ihs",
        par_min=0.2,
        par_max=0.8,
        bandwidth_min=1e-4,
        bandwidth_max=1e-1,
    )
    # Mahdavi et al. 2007: gn = 1..NI with NI = budget - hms improvisations.
    np.testing.assert_allclose(optimizer.par_at(0), 0.2 + 0.6 / 1000)
    np.testing.assert_allclose(optimizer.par_at(499), 0.5)
    np.testing.assert_allclose(optimizer.par_at(999), 0.8)
    np.testing.assert_allclose(optimizer.par_at(5000), 0.8)
    np.testing.assert_allclose(optimizer.bandwidth_at(0), 1e-1 * 1e-3 ** (1 / 1000))
    np.testing.assert_allclose(optimizer.bandwidth_at(499), np.sqrt(1e-4 * 1e-1))  # geometric
    np.testing.assert_allclose(optimizer.bandwidth_at(999), 1e-4)
    np.testing.assert_allclose(optimizer.bandwidth_at(5000), 1e-4)


def test_ihs_improvisations_follow_the_schedules():
    space = Space.from_bounds([0.0] * 4, [1.0] * 4)
    optimizer = build(
        space,
        hms=3,
        hmcr=1.0,
        budget=2003,
        pitch_adjust="ihs",
        par_min=0.1,
        par_max=0.9,
        bandwidth_min=1e-3,
        bandwidth_max=1e-1,
    )
    memory = np.array([[0.25] * 4, [0.5] * 4, [0.75] * 4])
    fill(optimizer, memory)
    harmonies = optimizer.ask(2000)
    distance = np.abs(harmonies[:, None, :] - memory[None]).min(axis=1)
    pitched = distance > 0
    assert abs(pitched[:200].mean() - 0.14) < 0.05  # PAR 0.1 .. 0.18 at the start
    assert abs(pitched[-200:].mean() - 0.86) < 0.05  # PAR 0.82 .. 0.9 at the end
    assert distance[:200].max() > 0.05  # wide steps early ...
    assert distance[-200:].max() <= optimizer.bandwidth_at(1800)  # ... narrow ones late


def test_reaches_the_sphere_optimum_and_beats_random_sampling():
    budget = 20_000
    hs_best = [sphere(run(build(seed=seed), budget)).min() for seed in range(3)]
    rng = np.random.default_rng(0)
    random_best = sphere(SPHERE_SPACE.sample(rng, budget)).min()
    assert max(hs_best) < 1e-2
    assert max(hs_best) * 1e3 < random_best


@pytest.mark.parametrize("pitch_adjust", PITCH_ADJUSTMENTS)
@pytest.mark.parametrize("stop_after", [3, 10, 500, 900])
@pytest.mark.parametrize("restart_after", [0, 25])
def test_json_state_round_trip_continues_identically(pitch_adjust, stop_after, restart_after):
    given = {"hms": 8, "pitch_adjust": pitch_adjust, "budget": 2000, "restart_after": restart_after}
    reference = build(seed=5, **given)
    interrupted = build(seed=5, **given)
    run(reference, stop_after, batch=3)
    run(interrupted, stop_after, batch=3)
    # a failed evaluation (+inf) in memory and two candidates asked but not yet told
    reference.tell(np.zeros((1, 10)), np.array([np.inf]))
    interrupted.tell(np.zeros((1, 10)), np.array([np.inf]))
    pending = interrupted.ask(2)
    np.testing.assert_array_equal(reference.ask(2), pending)

    saved = json.dumps(interrupted.state_dict(), allow_nan=False)
    resumed = build(seed=99, **given)
    resumed.load_state_dict(json.loads(saved))
    for optimizer in (reference, resumed):
        optimizer.tell(pending, sphere(pending))
    np.testing.assert_array_equal(run(resumed, 1000, batch=7), run(reference, 1000, batch=7))
    np.testing.assert_array_equal(resumed.harmony_memory, reference.harmony_memory)
    np.testing.assert_array_equal(resumed.harmony_fitness, reference.harmony_fitness)
    assert resumed.state_dict() == reference.state_dict()
    assert (resumed.restarts > 0) == (restart_after > 0)


def test_same_seed_same_sequence_different_seeds_differ():
    first, again, other = (run(build(seed=s), 300, batch=2) for s in (1, 1, 2))
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first[:20], other[:20])
    assert not np.array_equal(first[-20:], other[-20:])


def test_a_batch_is_improvised_from_one_memory():
    batched, single = build(seed=4), build(seed=4)
    run(batched, 20)
    run(single, 20)
    batch = batched.ask(2000)  # spans several blocks of pre-drawn choices
    one_by_one = np.concatenate([single.ask(1) for _ in range(2000)])
    np.testing.assert_array_equal(batch, one_by_one)
    assert batched.improvisations == 2000


def test_restart_refills_the_memory_after_restart_after_stalled_harmonies():
    space = Space.from_bounds([0.0] * 3, [1.0] * 3)
    optimizer = build(space, seed=2, hms=4, restart_after=50, budget=1000, pitch_adjust="ihs")
    memory = space.sample(np.random.default_rng(0), 4)
    fill(optimizer, memory, np.array([0.0, 1.0, 2.0, 3.0]))
    # 49 harmonies no better than the best: the memory takes some, the best stays
    stalled = optimizer.ask(49)
    optimizer.tell(stalled, np.full(49, 0.5))
    assert optimizer.restarts == 0
    assert len(optimizer.harmony_memory) == 4
    # an improvement starts the count again
    optimizer.tell(optimizer.ask(1), np.array([-1.0]))
    optimizer.tell(optimizer.ask(49), np.full(49, 0.0))
    assert optimizer.restarts == 0
    optimizer.tell(optimizer.ask(1), np.array([0.0]))  # the 50th in a row: restart
    assert optimizer.restarts == 1
    assert len(optimizer.harmony_memory) == 0
    # the memory refills with uniform random points, then improvisation starts again
    refill = optimizer.ask(4)
    assert not in_column(refill, memory).any()
    optimizer.tell(refill, np.arange(4.0))
    np.testing.assert_array_equal(optimizer.harmony_memory, refill)
    # the ihs schedules start again over the 1000 - 104 told - 4 evaluations left
    first = optimizer.improvisations
    np.testing.assert_allclose(optimizer.par_at(first), 0.01 + 0.98 / 892)
    np.testing.assert_allclose(optimizer.bandwidth_at(first + 891), 1e-5)
    harmonies = optimizer.ask(200)  # improvised from the new memory only
    assert in_column(harmonies, refill).mean() > 0.7  # hmcr 0.9, PAR 0.01 .. 0.23
    assert not in_column(harmonies, memory).any()


def test_harmonies_told_after_a_restart_from_the_old_memory_do_not_refill_the_new_one():
    """A restart in the middle of a told batch (or with harmonies in flight): the rest of the
    batch was improvised from the memory just emptied, and is left out of the new one, which
    refills with the random points asked after the restart, as at the start."""
    space = Space.from_bounds([0.0] * 3, [1.0] * 3)
    optimizer = build(space, seed=2, hms=3, restart_after=2, budget=1000, pitch_adjust="ihs")
    fill(optimizer, space.sample(np.random.default_rng(0), 3), np.array([0.0, 1.0, 2.0]))
    old = optimizer.ask(6)
    optimizer.tell(old, np.full(6, 5.0))  # the 2nd stalls it: restart; 4 more told after
    assert optimizer.restarts == 1 and len(optimizer.harmony_memory) == 0
    fresh = optimizer.ask(5)
    assert not in_column(fresh, old).any()
    optimizer.tell(fresh[:3], np.arange(3.0))
    np.testing.assert_array_equal(optimizer.harmony_memory, fresh[:3])
    # saved and restored on the way, the same holds
    again = build(space, seed=2, hms=3, restart_after=2, budget=1000, pitch_adjust="ihs")
    fill(again, space.sample(np.random.default_rng(0), 3), np.array([0.0, 1.0, 2.0]))
    again.tell(again.ask(6)[:2], np.full(2, 5.0))  # restart with 4 still in flight
    in_flight = old[2:]
    resumed = build(space, seed=9, hms=3, restart_after=2, budget=1000, pitch_adjust="ihs")
    resumed.load_state_dict(json.loads(json.dumps(again.state_dict())))
    refill = resumed.ask(3)
    resumed.tell(np.concatenate([in_flight, refill]), np.arange(7.0))
    np.testing.assert_array_equal(resumed.harmony_memory, refill)


def test_no_restart_by_default_and_restarts_escape_a_stalled_memory():
    """A trap: fitness 0 on most of the box, a narrow well of fitness -1 elsewhere.
    Without restarts a memory filled on the plateau stays there; with them it finds the well."""
    space = Space.from_bounds([0.0, 0.0], [1.0, 1.0])

    def trap(x: np.ndarray) -> np.ndarray:
        return np.where(np.all(np.abs(x - 0.9) < 0.05, axis=1), -1.0, 0.0)

    def best_found(**given) -> float:
        optimizer = build(space, seed=7, hms=10, hmcr=1.0, par=0.0, budget=3000, **given)
        best = np.inf
        for _ in range(3000):
            candidates = optimizer.ask(1)
            fitness = trap(candidates)
            optimizer.tell(candidates, fitness)
            best = min(best, float(fitness[0]))
        return best

    assert best_found() == 0.0  # hmcr 1, par 0: only recombines its first random memory
    assert best_found(restart_after=20) == -1.0


def test_a_state_saved_before_restarts_existed_still_resumes():
    given = {"hms": 8, "pitch_adjust": "ihs", "budget": 2000}
    reference, old = build(seed=5, **given), build(seed=5, **given)
    run(reference, 300, batch=3)
    run(old, 300, batch=3)
    state = old.state_dict()
    for key in ("told", "stalled", "restarts", "schedule"):
        del state[key]
    resumed = build(seed=1, **given)
    resumed.load_state_dict(state)
    np.testing.assert_array_equal(run(resumed, 500, batch=3), run(reference, 500, batch=3))
