"""`metaopt robustness`: a candidate over its problem's versioned perturbation table, every cell
on every engine over the same N seeds, summarized as medians, quartiles and rates; end to end
through the real command, deterministic whatever runs the evaluations."""

from __future__ import annotations

import csv
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from metaopt import ConfigError
from metaopt.assessment.candidates import Candidate, find_candidate, find_candidates
from metaopt.assessment.robustness import (
    CellResult,
    Perturbation,
    PerturbationTable,
    check_changes,
    differing_params,
    evaluate,
    figure_metrics,
    parse_goal,
    rank,
    select_cells,
    tasks,
    whole_table,
    write_ranking,
)
from metaopt.executors import base as executors_base
from metaopt.executors.base import SerialExecutor, problem_key
from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt.reporting.display import goal_verdict
from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.robustness import NOMINAL_WORLD, STANDARD_TABLE
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait, stored_gait_names
from tests.conftest import metaopt_cli, one_error_line
from tests.engines import needs_ode

TINY = ("hs_walk", "--engines", "mujoco+pybullet", "--seeds", "2", "--cells",
        "nominal,latency 1", "--set", "duration=4", "--set", "lock=1")  # fmt: skip


def test_a_cell_scales_or_sets_the_candidates_parameters() -> None:
    cell = Perturbation("x", "", scale={"friction": 0.7}, set={"push": 1.0})
    assert cell.apply({"friction": 2.0, "push": 0.0, "noise": 0.3}) == pytest.approx(
        {"friction": 1.4, "push": 1.0, "noise": 0.3}
    )


def test_the_standard_table_is_versioned_and_names_the_issues_perturbations() -> None:
    info = registry().problem("nao-walk")
    assert info.perturbations is STANDARD_TABLE
    assert STANDARD_TABLE.version == "nao-walk-3"
    names = [cell.name for cell in STANDARD_TABLE.cells]
    assert names[0] == "nominal" and len(set(names)) == len(names) == 11
    assert STANDARD_TABLE.metrics == ("speed", "|drift|", "fell", "flight", "time_to_fall")


def test_every_cell_and_engine_uses_the_same_seeds_and_checked_parameters() -> None:
    info = registry().problem("nao-walk")
    candidate, _ = find_candidate("hs_walk", registry().problems, "none.db")
    plan = tasks(candidate, info, STANDARD_TABLE, ("mujoco", "pybullet"), 3, seed=4)
    planned = plan.tasks
    assert len(planned) == 11 * 2 * 3 and plan.left_out == []
    seeds = {(cell, engine): [] for cell, engine, _ in planned}
    for cell, engine, task in planned:
        seeds[cell, engine].append(task.seed)
        assert task.params["backend"] == engine
        assert task.params["measure_flight"] is True
    assert len({tuple(s) for s in seeds.values()}) == 1
    by_cell = {cell: task.params for cell, _, task in planned}
    assert by_cell["friction x0.7"]["friction_scale"] == pytest.approx(0.7)
    assert by_cell["mass x1.1"]["mass_scale"] == pytest.approx(1.1)
    assert by_cell["push sideways"]["push_direction"] == 90.0
    assert by_cell["noise 0.5"]["noise"] == 0.5 and by_cell["nominal"]["noise"] == 0.1
    with pytest.raises(ConfigError, match="friction"):  # MuJoCo's limit is 3
        tasks(Candidate("c", "nao-walk", {**candidate.params, "friction": 2.5},
                        candidate.x), info, STANDARD_TABLE, ("mujoco",), 1, 0)  # fmt: skip


def test_a_gait_searched_in_a_perturbed_world_is_tried_in_the_tables_worlds() -> None:
    """Each cell starts from the nominal world: a gait's own push, latency, mass or friction
    scale or sampled worlds do not carry into the cells (they did until nao-walk-3), and its
    evaluation in a cell is that of the same gait given no perturbation of its own."""
    info = registry().problem("nao-walk")
    plain, _ = find_candidate("hs_walk", registry().problems, "none.db")
    short = {**plain.params, "duration": 4.0, "lock": 1.0}
    perturbed = {**short, "push": 1.0, "push_time": 2.0, "latency": 2, "mass_scale": 1.1,
                 "friction_scale": 0.8, "worlds": "standard"}  # fmt: skip
    cells = select_cells(STANDARD_TABLE, ["nominal", "mass x1.1", "latency 1"])
    plans = [
        tasks(Candidate(name, "nao-walk", params, plain.x), info, cells, ("mujoco",), 1, 5)
        for name, params in (("plain", short), ("perturbed", perturbed))
    ]
    by_cell = [{cell: task for cell, _, task in plan.tasks} for plan in plans]
    unused = {"push_time"}  # with no push
    for cell in ("nominal", "mass x1.1", "latency 1"):
        params = [{k: v for k, v in c[cell].params.items() if k not in unused} for c in by_cell]
        assert params[0] == params[1]
    params = by_cell[1]["latency 1"].params
    assert (params["push"], params["latency"], params["worlds"]) == (0.0, 1, "none")
    assert by_cell[1]["mass x1.1"].params["mass_scale"] == pytest.approx(1.1)
    # the episodes themselves: the perturbed gait's nominal cell walks the plain gait's walk
    walks = []
    for plan in plans:
        task = next(task for cell, _, task in plan.tasks if cell == "nominal")
        problem = info.factory(**task.params)
        try:
            walks.append(problem.evaluate(task.x, task.seed).metrics)
        finally:
            problem.close()
    assert walks[0] == walks[1]
    problem = info.factory(**resolve(info.params, {**perturbed, "worlds": "none",
                                                   "measure_flight": True, "noise": 0.1},
                                     "nao-walk"))  # fmt: skip
    try:
        assert problem.evaluate(plain.x, by_cell[0]["nominal"].seed).metrics != walks[0]
    finally:
        problem.close()


def test_every_stored_gait_starts_from_the_nominal_world_so_its_table_is_unchanged() -> None:
    """nao-walk-3 differs from nao-walk-2 only for gaits with perturbations of their own: the
    stored gaits have none, so their nao-walk-2 tables (docs/robustness) stand."""
    info = registry().problem("nao-walk")
    for name in stored_gait_names():
        candidate, _ = find_candidate(name, registry().problems, "none.db")
        params = resolve(info.params, candidate.params, name)
        # worlds was reset by nao-walk-2 already; the others are new in nao-walk-3. world_cells
        # only names the cells a search's sampled worlds draw from, and cell_durations how long
        # those cells walk: nao-walk-2's worlds=none refuses both, so a gait searched with them
        # (balanced_cells_walk, hazard_walk, quarter_walk) has nao-walk-3 tables only
        sampling = ("worlds", "world_cells", "cell_durations")
        added = {key: value for key, value in NOMINAL_WORLD.items() if key not in sampling}
        assert {key: params[key] for key in added} == added, name


def test_robustness_refuses_a_change_the_table_overrides(tmp_path: Path) -> None:
    """--set of a parameter the table sets in every cell would do nothing: refused in one line,
    before any work."""
    check_changes({"fitness": "robust", "duration": 8.0}, STANDARD_TABLE)
    done = metaopt_cli("robustness", "hs_walk", "--set", "latency=1", "--csv", "r.csv",
                       cwd=tmp_path)  # fmt: skip
    one_error_line(done, "--set latency=1:", "sets latency=0 in every cell")
    assert list(tmp_path.iterdir()) == []


def test_summaries_are_medians_quartiles_and_rates() -> None:
    result = CellResult("c", "e", [{"speed": v, "drift": -v, "fell": float(v > 2)}
                                   for v in (1.0, 2.0, 3.0, 4.0)], 1)  # fmt: skip
    assert result.summary("speed") == (2.5, 1.75, 3.25)
    assert result.summary("|drift|") == (2.5, 1.75, 3.25)
    assert result.summary("fell") == (0.5, 0.5, 0.5)
    assert np.isnan(result.summary("flight")[0])


def test_the_whole_table_pools_every_cells_episodes_per_engine() -> None:
    """A goal "over the standard table" is a statistic over all its episodes, per engine."""
    results = [
        CellResult("a", "e1", [{"speed": 1.0, "fell": 0.0}, {"speed": 2.0, "fell": 1.0}], 0),
        CellResult("a", "e2", [{"speed": 9.0, "fell": 0.0}], 1),
        CellResult("b", "e1", [{"speed": 3.0, "fell": 0.0}, {"speed": 4.0, "fell": 0.0}], 1),
    ]
    totals = whole_table(results)
    assert [(t.cell, t.engine, len(t.samples), t.failed) for t in totals] == [
        ("whole table", "e1", 4, 1), ("whole table", "e2", 1, 1)
    ]  # fmt: skip
    assert totals[0].summary("speed")[0] == 2.5 and totals[0].summary("fell")[0] == 0.25
    assert [len(r.samples) for r in results] == [2, 1, 2]  # the cells are left as they were


def test_select_cells_keeps_table_order_and_refuses_unknown_names() -> None:
    table = select_cells(STANDARD_TABLE, ["latency 1", "nominal"])
    assert [c.name for c in table.cells] == ["nominal", "latency 1"]
    assert table.version == STANDARD_TABLE.version
    with pytest.raises(ConfigError, match="accepted: nominal"):
        select_cells(STANDARD_TABLE, ["gravity"])


def test_select_cells_keeps_every_other_field_of_the_table() -> None:
    """--cells keeps the table's only_when (and common, metrics): a goal on time_to_fall built
    from the selected table holds for a gait that never fell, as on the whole table."""
    table = select_cells(STANDARD_TABLE, ["nominal"])
    assert table == replace(STANDARD_TABLE, cells=STANDARD_TABLE.cells[:1])
    assert table.only_when == {"time_to_fall": "fell"}
    goal = parse_goal("time_to_fall>=5", table.metrics, table.version, table.only_when)
    assert goal.only_when == "fell"
    assert goal.margin(CellResult("all", "mujoco", [{"speed": 0.5, "fell": 0.0}] * 2, 0)) > 0


def test_evaluate_closes_the_problems_it_built_in_this_process() -> None:
    """With the serial executor the episodes' problems are built here and cached per (cell,
    engine); evaluate releases them at its end rather than holding engines for the command."""
    info = registry().problem("nao-walk")
    stored, _ = find_candidate("hs_walk", registry().problems, "none.db")
    candidate = replace(stored, params={**stored.params, "duration": 1.0, "lock": 0.2})
    plan = tasks(candidate, info, select_cells(STANDARD_TABLE, ["nominal"]), ("mujoco",), 1, 0)
    built = {problem_key(task.factory, task.params) for _, _, task in plan.tasks}
    with SerialExecutor() as executor:
        ((result,),) = evaluate([plan], executor)
    assert len(result.samples) == 1 and result.failed == 0
    assert not built & set(executors_base._problems)


def test_find_candidate_takes_stored_gaits_by_name() -> None:
    candidate, info = find_candidate("stride_mujoco", registry().problems, "none.db")
    assert info.name == "nao-walk" and candidate.params["controller"] == "stride"
    assert np.array_equal(candidate.x, gait_vector(load_gait("stride_mujoco")))
    assert candidate.target == "stride_mujoco"  # what names it again on a command line
    with pytest.raises(ConfigError, match="neither a stored candidate"):
        find_candidate("no_such_gait", registry().problems, "none.db")


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.mark.slow
def test_robustness_command_end_to_end_and_deterministic(tmp_path: Path) -> None:
    serial = metaopt_cli("robustness", *TINY, "--csv", "serial.csv", "--figure", "r.png",
                         "--goal", "speed>=5", "--goal", "fell<=1", cwd=tmp_path)  # fmt: skip
    assert serial.returncode == 0, serial.stderr
    assert "nao-walk-3" in serial.stdout and "latency 1" in serial.stdout
    # the verdict against the goals: no walk reaches 5 m/s, every one falls at most always
    assert "hs_walk against the goals speed>=5, fell<=1:" in serial.stdout
    for engine in ("mujoco", "pybullet"):
        assert f"  {engine}: misses speed>=5 (0." in serial.stdout
    assert (tmp_path / "r.png").stat().st_size > 1000
    rows = _rows(tmp_path / "serial.csv")
    assert [(r["cell"], r["engine"]) for r in rows] == [
        (cell, engine) for cell in ("nominal", "latency 1", "whole table")
        for engine in ("mujoco", "pybullet")
    ]  # fmt: skip
    assert "whole table" in serial.stdout
    for row in rows:
        assert row["table_version"] == "nao-walk-3" and row["candidate"] == "hs_walk"
        assert (row["seeds"], row["failed"]) == ("4" if row["cell"] == "whole table" else "2", "0")
        assert float(row["fell"]) in (0.0, 0.5, 1.0)
        low, median, high = (float(row[f"speed_{k}"]) for k in ("q25", "median", "q75"))
        assert low <= median <= high
    # the same numbers from two worker processes
    pooled = metaopt_cli("robustness", *TINY, "--csv", "pooled.csv", "--workers", "2",
                         cwd=tmp_path)  # fmt: skip
    assert pooled.returncode == 0, pooled.stderr
    assert _rows(tmp_path / "pooled.csv") == rows


def test_time_to_fall_is_the_median_over_the_episodes_that_fell_of_the_time_they_walked() -> None:
    """The table says when a gait falls: over the episodes that fell alone (a median over
    every episode would be the walk's full length wherever most of them walked it)."""
    info = registry().problem("nao-walk")
    stored, _ = find_candidate("stride_mujoco", registry().problems, "none.db")
    candidate = replace(stored, params={**stored.params, "duration": 15.0})
    table = select_cells(STANDARD_TABLE, ["servo gain x1.2"])
    plan = tasks(candidate, info, table, ("mujoco",), 6, seed=0)
    with SerialExecutor() as executor:
        ((result,),) = evaluate([plan], executor)
    fallen = [s["time_walked"] for s in result.samples if s["fell"]]
    assert 0 < len(fallen) < len(result.samples)  # some fell, some walked the whole 12 s
    assert all(("time_to_fall" in s) == bool(s["fell"]) for s in result.samples)
    median, low, high = result.summary("time_to_fall")
    assert median == pytest.approx(float(np.median(fallen)))
    assert (low, high) == pytest.approx(tuple(np.percentile(fallen, [25, 75])))
    assert median < 15.0 - 3.0  # before the walk's end, which most episodes' time_walked is


def test_a_goal_on_the_time_to_fall_holds_for_a_gait_that_never_fell() -> None:
    """time_to_fall is measured on the episodes that fell alone: with none fallen a bound on
    it holds (+inf margin), not fails on a median of nothing; one that fell is judged by the
    median of its falls; a metric nothing measured still misses (-inf)."""
    (later,) = [parse_goal("time_to_fall>=5", STANDARD_TABLE.metrics, STANDARD_TABLE.version,
                           STANDARD_TABLE.only_when)]  # fmt: skip
    assert later.only_when == "fell"
    steady = CellResult("all", "mujoco", [{"speed": 0.5, "fell": 0.0}] * 4, 0)
    falling = CellResult("all", "mujoco", [
        {"speed": 0.5, "fell": 1.0, "time_to_fall": t} for t in (2.0, 3.0, 4.0)
    ] + [{"speed": 0.5, "fell": 0.0}], 0)  # fmt: skip
    assert later.margin(steady) == math.inf
    assert later.margin(falling) == pytest.approx((3.0 - 5.0) / 5.0)
    assert later.margin(CellResult("all", "mujoco", [{"fell": 0.0}] * 2, 1)) == -math.inf
    unmeasured = parse_goal("flight<=0.05", STANDARD_TABLE.metrics, STANDARD_TABLE.version,
                            STANDARD_TABLE.only_when)  # fmt: skip
    assert unmeasured.only_when is None and unmeasured.margin(steady) == -math.inf


def test_the_goal_verdict_judges_a_time_to_fall_goal_as_the_ranking_does() -> None:
    """The printed verdict counts a goal's only_when rate like Goal.margin: a gait that never
    fell meets time_to_fall>=5 (no '(nan)' miss), one whose falls came early misses it."""
    goals = [
        parse_goal(text, STANDARD_TABLE.metrics, STANDARD_TABLE.version, STANDARD_TABLE.only_when)
        for text in ("time_to_fall>=5", "speed>=0.4")
    ]
    steady = CellResult("whole table", "mujoco", [{"speed": 0.5, "fell": 0.0}] * 4, 0)
    falling = CellResult("whole table", "ode", [
        {"speed": 0.5, "fell": 1.0, "time_to_fall": t} for t in (2.0, 3.0, 4.0)
    ] + [{"speed": 0.5, "fell": 0.0}], 0)  # fmt: skip
    assert [g.margin(steady) > 0 for g in goals] == [True, True]
    assert goal_verdict("g", [steady, falling], goals).splitlines() == [
        "g against the goals time_to_fall>=5, speed>=0.4:",
        "  mujoco: meets all",
        "  ode: misses time_to_fall>=5 (3)",
    ]


def test_robustness_command_refuses_bad_input_in_one_line(tmp_path: Path) -> None:
    for args, message in (
        (("no_such_gait",), "neither a stored candidate"),
        (("hs_walk", "--engines", "bullet"), "bullet"),
        (("hs_walk", "--cells", "gravity"), "no perturbation 'gravity'"),
        (("hs_walk", "--set", "friction=5", "--engines", "mujoco"), "friction"),
        (("hs_walk", "--goal", "speed>0.44"), "goal 'speed>0.44': write METRIC>=VALUE"),
    ):
        result = metaopt_cli("robustness", *args, "--csv", "out.csv", cwd=tmp_path)
        assert result.returncode == 2, (args, result.stderr)
        assert message in result.stderr and "Traceback" not in result.stderr
        assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("engine", ["mujoco", "pybullet", "ode"])
def test_the_friction_cells_change_the_friction_the_engine_holds(engine: str) -> None:
    """friction_scale multiplies each engine's own default friction, read back from the engine;
    on ODE as the server (unlimited friction) there is no coefficient to scale."""
    info = registry().physics_backends[engine]
    if info.unavailable:
        pytest.skip(info.unavailable)
    problem_info = registry().problem("nao-walk")
    read = {}
    for scale in (1.0, 0.7):
        problem = problem_info.factory(backend=engine, friction_scale=scale)
        try:
            read[scale] = problem.runner.backend.ground_friction()
        finally:
            problem.close()
    if engine == "ode":
        assert read[1.0] == read[0.7] == float("inf")
    else:
        assert read[1.0] == pytest.approx(info.default_friction)
        assert read[0.7] == pytest.approx(0.7 * info.default_friction)


def test_the_friction_cells_are_left_out_where_the_friction_is_unlimited() -> None:
    """On ODE at its default (unlimited) friction the friction cells would repeat the nominal
    world, counted three times in the whole table: the plan leaves them out there, saying why;
    at a finite friction (hs_walk's 1) they run on ODE too, and ODE holds the scaled one."""
    if registry().physics_backends["ode"].unavailable:
        pytest.skip(registry().physics_backends["ode"].unavailable)
    info = registry().problem("nao-walk")
    friction_cells = ["friction x0.7", "friction x1.3"]
    plans = {}
    for name, left_out in (("goal_walk", friction_cells), ("hs_walk", [])):
        candidate, _ = find_candidate(name, registry().problems, "none.db")
        plan = plans[name] = tasks(candidate, info, STANDARD_TABLE, ("mujoco", "ode"), 1, seed=0)
        assert [(cell, engine) for cell, engine, _ in plan.left_out] == [
            (cell, "ode") for cell in left_out
        ]
        assert all("unlimited" in reason for _, _, reason in plan.left_out)
        ran = {(cell, engine) for cell, engine, _ in plan.tasks}
        assert len(ran) == 2 * 11 - len(left_out)
    # the cell that runs on ODE at hs_walk's finite friction: ODE holds 1 x 0.7
    (cell_params,) = [task.params for cell, engine, task in plans["hs_walk"].tasks
                      if (cell, engine) == ("friction x0.7", "ode")]  # fmt: skip
    scaled = info.factory(**cell_params)
    try:
        assert scaled.runner.backend.ground_friction() == pytest.approx(0.7)
    finally:
        scaled.close()
    # nothing left to run on ODE: refused, naming the cells and why
    goal_walk, _ = find_candidate("goal_walk", registry().problems, "none.db")
    friction_only = select_cells(STANDARD_TABLE, friction_cells)
    with pytest.raises(ConfigError, match=r"changes nothing on ode \(friction x0\.7: its ground"):
        tasks(goal_walk, info, friction_only, ("mujoco", "ode"), 1, seed=0)


def test_a_left_out_cell_is_named_and_absent_from_the_csv_and_the_whole_table(
    tmp_path: Path,
) -> None:
    if registry().physics_backends["ode"].unavailable:
        pytest.skip(registry().physics_backends["ode"].unavailable)
    result = metaopt_cli("robustness", "goal_walk", "--engines", "ode", "--cells",
                         "nominal,friction x0.7", "--seeds", "2", "--set", "duration=5",
                         "--csv", "t.csv", "--figure", "t.png", cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    shown = " ".join(result.stdout.split())
    assert "2 cells x 1 engines x 2 seeds, 2 evaluations (left out: 1 x a cell" in shown
    assert "left out on ode (friction x0.7): its ground friction is unlimited" in shown
    rows = _rows(tmp_path / "t.csv")
    assert [(r["cell"], r["engine"], r["seeds"]) for r in rows] == [
        ("nominal", "ode", "2"), ("whole table", "ode", "2")
    ]  # fmt: skip
    assert (tmp_path / "t.png").stat().st_size > 1000
    # nothing left to run on an engine: one line, exit 2, no file
    empty = metaopt_cli("robustness", "goal_walk", "--engines", "ode", "--cells",
                        "friction x0.7", "--csv", "e.csv", cwd=tmp_path)  # fmt: skip
    assert empty.returncode == 2 and "Traceback" not in empty.stderr
    assert "changes nothing on ode" in empty.stderr and not (tmp_path / "e.csv").exists()


def _cells(engine_fitnesses: dict[str, list[float]], failed: int = 0) -> list[CellResult]:
    return [
        CellResult(
            "nominal", engine, [{} for _ in values], failed if engine == "e2" else 0, list(values)
        )
        for engine, values in engine_fitnesses.items()
    ]


def test_candidates_rank_by_their_worst_engines_mean_fitness() -> None:
    """The score is the worst engine's mean over the table: a candidate fast on one engine and
    falling (a low fitness) on another ranks below one that holds on both; a failed evaluation
    makes its engine the worst; ties keep the given order; minimizing turns it round."""

    def c(label: str) -> Candidate:
        return Candidate(label, "p", {}, np.zeros(1))

    tables = [
        (c("one-engine"), _cells({"e1": [9.0, 9.0], "e2": [-3.0, 1.0]})),  # worst mean -1
        (c("both"), _cells({"e1": [2.0, 2.0], "e2": [1.0, 2.0]})),  # worst mean 1.5
        (c("failed"), _cells({"e1": [5.0], "e2": [5.0]}, failed=1)),
        (c("tie"), _cells({"e1": [1.5, 1.5], "e2": [3.0, 3.0]})),  # 1.5, after "both"
    ]
    ranked = rank(tables, maximize=True)
    assert [r.candidate.label for r in ranked] == ["both", "tie", "one-engine", "failed"]
    assert [r.score for r in ranked[:3]] == [1.5, 1.5, -1.0] and ranked[3].score == -np.inf
    minimized = rank(tables, maximize=False)  # worst = highest mean
    assert [(r.candidate.label, r.score) for r in minimized[:3]] == [
        ("both", 2.0), ("tie", 3.0), ("one-engine", 9.0)
    ]  # fmt: skip


def test_goals_rank_by_the_smallest_margin_then_by_fitness(tmp_path: Path) -> None:
    """With goals a candidate is scored by its smallest relative margin to any goal on any
    engine over the whole table (speed beyond the goal buys nothing, one engine's falls sink
    it); equal margins fall back to the fitness order; a failed evaluation is outside every
    goal (on every engine it failed on), and each counts the (goal, engine) pairs it misses.
    The ranking's CSV keeps that order and says which meet every goal."""

    def c(label: str, speeds: dict[str, list[float]], fell: dict[str, list[float]], fit: float,
          failed: int = 0) -> tuple[Candidate, list[CellResult]]:  # fmt: skip
        rows = [
            CellResult("nominal", engine, [{"speed": v, "fell": f} for v, f in
                                           zip(speeds[engine], fell[engine], strict=True)],
                       failed if engine == "e2" else 0, [fit] * len(speeds[engine]))
            for engine in speeds
        ]  # fmt: skip
        return Candidate(label, "p", {}, np.zeros(1)), rows

    table = PerturbationTable("t-1", (), ("speed", "fell"))
    goals = [
        parse_goal(text, table.metrics, table.version) for text in ("speed>=0.5", " fell <= 0.25")
    ]
    assert [str(g) for g in goals] == ["speed>=0.5", "fell<=0.25"]
    fast_but_falls = c(
        "fast",
        {"e1": [0.9] * 4, "e2": [0.9] * 4},
        {"e1": [0, 0, 0, 0], "e2": [1, 1, 0, 0]},
        fit=9.0,
    )  # fell 0.5: -1.0
    steady = c(
        "steady", {"e1": [0.6] * 4, "e2": [0.55] * 4}, {"e1": [0] * 4, "e2": [0] * 4}, fit=2.0
    )  # speed 0.55 on e2: +0.1
    steady_fitter = c(
        "steady, fitter",
        {"e1": [0.6] * 4, "e2": [0.55] * 4},
        {"e1": [0] * 4, "e2": [0] * 4},
        fit=3.0,
    )  # +0.1 as well
    failed = c("failed", {"e1": [0.9] * 4, "e2": [0.9] * 4},
               {"e1": [0] * 4, "e2": [0] * 4}, fit=9.0, failed=1)  # fmt: skip
    crawl = c(
        "crawl", {"e1": [0.3] * 4, "e2": [0.3] * 4}, {"e1": [0] * 4, "e2": [0] * 4}, fit=1.0
    )  # speed 0.3 on both engines: two misses, -0.4
    ranked = rank([fast_but_falls, steady, crawl, steady_fitter, failed], True, goals)
    # the smallest margin decides: "crawl" misses two pairs by less than "fast" misses one
    assert [r.candidate.label for r in ranked] == [
        "steady, fitter", "steady", "crawl", "fast", "failed"]  # fmt: skip
    assert [r.missed for r in ranked] == [0, 0, 2, 1, 2]
    assert [r.margin for r in ranked[:4]] == pytest.approx([0.1, 0.1, -0.4, -1.0])
    assert ranked[4].margin == -np.inf
    assert [r.candidate.label for r in rank([fast_but_falls, steady], True)] == ["fast", "steady"]
    write_ranking(tmp_path / "ranking.csv", ranked)
    assert [(r["rank"], r["candidate"], r["goals_missed"], r["meets_goals"]) for r in
            _rows(tmp_path / "ranking.csv")] == [
        ("1", "steady, fitter", "0", "True"), ("2", "steady", "0", "True"),
        ("3", "crawl", "2", "False"), ("4", "fast", "1", "False"),
        ("5", "failed", "2", "False")]  # fmt: skip
    for bad in ("speed=0.5", "speed>=fast", "height>=1", "fell<=inf", ""):
        with pytest.raises(ConfigError, match=r"METRIC>=VALUE or METRIC<=VALUE .*speed, fell"):
            parse_goal(bad, table.metrics, table.version)


def test_a_ranking_names_the_parameters_its_candidates_differ_in() -> None:
    """Not the engine, not what the table sets for every cell (its noise, measure_flight)."""
    base = {"backend": "mujoco", "noise": 0.0, "flight_penalty": 20.0, "duration": 15.0}
    others = [{**base, "backend": "ode", "noise": 0.3}, {**base, "flight_penalty": 100.0}]
    candidates = [Candidate(str(k), "nao-walk", params, np.zeros(1))
                  for k, params in enumerate([base, *others])]  # fmt: skip
    assert differing_params(candidates, STANDARD_TABLE, "backend") == ["flight_penalty"]
    assert differing_params(candidates[:2], STANDARD_TABLE, "backend") == []


@pytest.fixture(scope="module")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store holding one short nao-walk run on MuJoCo (8 evaluations of 4 s episodes)."""
    where = tmp_path_factory.mktemp("top")
    made = metaopt_cli("run", "-o", "hs", "-p", "nao-walk", "--budget", "8", "--seed", "3",
                       "--set", "duration=4", "--set", "lock=1", "--set", "backend=mujoco",
                       "--set", "hms=4", "--db", "runs.db", cwd=where)  # fmt: skip
    assert made.returncode == 0, made.stderr
    return where


def test_find_candidates_takes_a_runs_top_or_one_candidate_by_number(short_run: Path) -> None:
    db = str(short_run / "runs.db")
    with RunStore(db) as store:
        run = store.run(1)
        best = store.best_candidates(run, 3)
        numbers = [r.number for r in best]
    top, info = find_candidates("1", registry().problems, db, 3)
    assert info.name == "nao-walk"
    assert [c.label for c in top] == [f"run 1 candidate {n}" for n in numbers]
    assert all(np.array_equal(c.x, r.x) for c, r in zip(top, best, strict=True))
    (one,), _ = find_candidates(f"1:{numbers[2]}", registry().problems, db, 1)
    assert one.label == f"run 1 candidate {numbers[2]}" and np.array_equal(one.x, best[2].x)
    assert find_candidate("1", registry().problems, db)[0].label == "run 1"
    latest, _ = find_candidates("1", registry().problems, db, 2, last=3)  # of candidates 0-7
    with RunStore(db) as store:
        expected = store.best_candidates(store.run(1), 2, last=3)
    assert [c.target for c in latest] == [f"1:{r.number}" for r in expected]
    assert all(r.number >= 5 for r in expected) and len(expected) == 2
    (alone,), _ = find_candidates("1", registry().problems, db, 1, last=3)
    assert alone.label == f"run 1 candidate {expected[0].number}"  # not the run's best
    for bad in ("1:x", "x:1"):
        with pytest.raises(
            ConfigError, match=r"nor a run \(RUN, RUN:CANDIDATE or RUN:recommended\)"
        ):
            find_candidates(bad, registry().problems, db, 1)


@pytest.mark.slow
def test_robustness_top_ranks_a_runs_best_candidates_and_each_can_be_named(
    short_run: Path,
) -> None:
    """`metaopt robustness RUN --top 3`: three candidates over the table, ranked, every one in
    the CSV; `RUN:CANDIDATE` names one of them and gives the same figures (same seeds)."""
    cells = ("--engines", "mujoco", "--seeds", "2", "--cells", "nominal,latency 1",
             "--db", "runs.db")  # fmt: skip
    top = metaopt_cli("robustness", "1", "--top", "3", *cells, "--csv", "top.csv",
                      "--ranking", "ranking.csv", cwd=short_run)  # fmt: skip
    assert top.returncode == 0, top.stderr
    assert "x 3 candidates" in top.stdout and "candidates ranked" in top.stdout
    rows = _rows(short_run / "top.csv")
    labels = list(dict.fromkeys(r["candidate"] for r in rows))
    assert len(labels) == 3 and all(label.startswith("run 1 candidate ") for label in labels)
    assert len(rows) == 3 * 3  # two cells and the whole table each
    ranked_first = top.stdout.index(labels[0])
    assert ranked_first < top.stdout.index(labels[1]) < top.stdout.index(labels[2])
    # the ranking names each candidate as another command takes it (RUN:CANDIDATE)
    ranking = _rows(short_run / "ranking.csv")
    assert [r["candidate"] for r in ranking] == labels and ranking[0]["meets_goals"] == ""
    assert [r["target"] for r in ranking] == [f"1:{label.rsplit(' ', 1)[1]}" for label in labels]
    alone = metaopt_cli("robustness", ranking[1]["target"], *cells, "--csv", "one.csv",
                        cwd=short_run)  # fmt: skip
    assert alone.returncode == 0, alone.stderr
    assert _rows(short_run / "one.csv") == [r for r in rows if r["candidate"] == labels[1]]
    # --last: the ranking's targets are the run's best among its latest candidates
    latest = metaopt_cli("robustness", "1", "--top", "2", "--last", "3", *cells, "--seeds", "1",
                         "--ranking", "latest.csv", cwd=short_run)  # fmt: skip
    assert latest.returncode == 0, latest.stderr
    with RunStore(short_run / "runs.db") as store:
        expected = store.best_candidates(store.run(1), 2, last=3)
    assert sorted(r["target"] for r in _rows(short_run / "latest.csv")) == sorted(
        f"1:{r.number}" for r in expected
    )
    missing = metaopt_cli("robustness", "1:999", *cells, "--seeds", "1", cwd=short_run)
    assert missing.returncode == 2 and "run 1 has no candidate 999" in missing.stderr
    # a stored gait and a run of the same problem rank together, warned that their parameters
    # differ
    mixed = metaopt_cli("robustness", "1", "hs_walk", "--set", "fitness=paper", *cells,
                        "--seeds", "1", cwd=short_run)  # fmt: skip
    assert mixed.returncode == 0, mixed.stderr
    assert "differ in" in mixed.stderr and "Traceback" not in mixed.stderr
    assert "x 2 candidates" in mixed.stdout and "hs_walk" in mixed.stdout


def test_the_figures_draw_speed_against_the_first_fall_rate_or_refuse_a_table_without_one():
    """Both figures (robustness --figure, robustness-summary --figure) ask this one function,
    and `metaopt robustness` asks it before any evaluation: a table without a fall rate is one
    ConfigError naming the table and its metrics."""
    info = registry().problem("nao-walk")
    speed, fell = figure_metrics(info.perturbations.metrics, info.perturbations.version)
    assert speed == info.perturbations.metrics[0] == "speed" and fell.startswith("fell")
    assert figure_metrics(("pace", "fell_early", "fell"), "t-2") == ("pace", "fell_early")
    with pytest.raises(
        ConfigError, match=r"table t-1 has no fall rate \(metrics: speed, \|drift\|\)"
    ):
        figure_metrics(("speed", "|drift|"), "t-1")


STEADY = ("steady_walk", "--cells", "nominal", "--seeds", "1", "--set", "duration=7",
          "--set", "lock=1")  # fmt: skip


@needs_ode  # steady_walk's stored backend and --engines name ODE
def test_robustness_refuses_a_backend_setting_an_engine_twice_and_a_changed_space(
    tmp_path: Path,
) -> None:
    """--set backend=X would be overridden by --engines, an engine named twice would count its
    seeds twice, and a --set that changes the candidate's space would evaluate its vector as
    another point: each refused in one line, before any work."""
    with pytest.raises(ConfigError, match="use --engines ode"):
        check_changes({"backend": "ode"}, STANDARD_TABLE)
    for args, needles in (
        (("--engines", "mujoco", "--set", "backend=ode"),
         ("--set backend=ode: robustness runs every engine in --engines; use --engines ode",)),
        (("--engines", "ode+ode"), ("--engines names ode twice",)),
        (("--engines", "ode", "--set", "controller=stride"),
         ("--set controller=stride changes the space to 14 variables",
          "the candidate has 15 variables")),
    ):  # fmt: skip
        done = metaopt_cli("robustness", *STEADY, *args, "--csv", "out.csv", cwd=tmp_path)
        one_error_line(done, *needles)
        assert list(tmp_path.iterdir()) == []


@needs_ode  # steady_walk's stored backend and --engines name ODE
def test_robustness_keeps_an_unchanged_space_and_prints_paths_as_written(tmp_path: Path) -> None:
    """A --set that leaves the space as it was runs; 'wrote PATH' shows '[final]' as given."""
    done = metaopt_cli("robustness", *STEADY, "--engines", "ode", "--set", "controller=steered",
                       "--csv", "x[final].csv", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "wrote x[final].csv" in done.stdout
    assert [r["engine"] for r in _rows(tmp_path / "x[final].csv")] == ["ode", "ode"]
