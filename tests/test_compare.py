"""`metaopt compare`: experiments from flags and files, the grid run and resumed through the run
store, the comparison table (medians, IQR, success, rank-sum p-values) checked against the
stored data and its CSV, bad experiment files, and cross-engine transfer checked against
replays."""

from __future__ import annotations

import contextlib
import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest
from rich.text import Text
from scipy.stats import mannwhitneyu

from metaopt.assessment.replay import replay_candidate, run_source
from metaopt.comparison.experiment import (
    Experiment,
    experiment_from_flags,
    load_experiment,
    restrict,
)
from metaopt.comparison.runner import run_experiment
from metaopt.comparison.summary import ProblemTraits, compare
from metaopt.comparison.transfer import replay_on_other_engines, transfer_table
from metaopt.errors import ConfigError
from metaopt.executors.base import SerialExecutor
from metaopt.plugins import registry
from metaopt.problem import Sense
from metaopt.reporting.result_table import ResultTable
from metaopt.running import RunInterrupted, RunSettings
from metaopt.storage.experiment_store import ExperimentStore
from metaopt.storage.run_store import EvaluationCounts
from tests.conftest import ROOT, metaopt_cli

SPHERE_FLAGS = ("-o", "hs", "-o", "random", "-p", "sphere", "--seeds", "5", "--budget", "300",
                "--set", "dim=5")  # fmt: skip


def _quiet(label: str) -> contextlib.AbstractContextManager[None]:
    return contextlib.nullcontext()


def _run(experiment: Experiment, store: ExperimentStore, watch=_quiet):
    return run_experiment(experiment, store, registry(), SerialExecutor, watch)


def _flags_experiment(**overrides) -> Experiment:
    given = {"optimizers": ["hs"], "problem": "sphere", "seeds": 2, "budget": 200,
             "settings": ["dim=3"], "target": None, "name": None, **overrides}  # fmt: skip
    return experiment_from_flags(**given, plugins=registry())


def _best_fitnesses(store: ExperimentStore, experiment: Experiment) -> dict[str, list[float]]:
    """Each cell's best fitness per seed, straight from the store."""
    found = {}
    for cell in experiment.cells():
        runs = [store.member(experiment.name, cell.key, seed) for seed in experiment.seeds]
        found[cell.optimizer.label] = [store.best_evaluation(run).fitness for run in runs]
    return found


def _csv_rows(text: str) -> list[dict[str, object]]:
    def value(text: str) -> object:
        if text == "":
            return None
        for kind in (int, float):
            with contextlib.suppress(ValueError):
                return kind(text)
        return text

    return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(io.StringIO(text))]


def test_flags_form_table_equals_the_store_and_reruns_nothing(tmp_path: Path) -> None:
    done = metaopt_cli("compare", *SPHERE_FLAGS, "--csv", "out.csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "10 run(s) ran, 0 resumed, 0 already finished" in done.stdout
    rows = {row["optimizer"]: row for row in _csv_rows((tmp_path / "out.csv").read_text())}
    experiment = _flags_experiment(
        optimizers=["hs", "random"], seeds=5, budget=300, settings=["dim=5"]
    )
    with ExperimentStore(tmp_path / "metaopt.db") as store:
        fitnesses = _best_fitnesses(store, experiment)
        assert len(store.runs()) == 10
    for label, values in fitnesses.items():
        q25, q50, q75 = np.percentile(values, [25, 50, 75])
        assert rows[label]["fitness_median"] == pytest.approx(q50, rel=1e-15)
        assert rows[label]["fitness_iqr"] == pytest.approx(q75 - q25, rel=1e-15)
        assert (rows[label]["finished"], rows[label]["planned"]) == (5, 5)
    # hs clearly beats random on the sphere: hs is the best cell, random's p-value is scipy's
    assert rows["hs"]["p_value"] is None
    expected = mannwhitneyu(fitnesses["hs"], fitnesses["random"], alternative="two-sided")
    assert rows["random"]["p_value"] == pytest.approx(expected.pvalue, rel=1e-12)
    assert rows["random"]["p_value"] < 0.01

    again = metaopt_cli("compare", *SPHERE_FLAGS, "--csv", "again.csv", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert "0 run(s) ran, 0 resumed, 10 already finished" in again.stdout
    assert (tmp_path / "again.csv").read_text() == (tmp_path / "out.csv").read_text()
    with ExperimentStore(tmp_path / "metaopt.db") as store:
        assert len(store.runs()) == 10


def test_the_csv_holds_the_values_the_terminal_table_shows(tmp_path: Path) -> None:
    experiment = _flags_experiment(optimizers=["hs", "random"], seeds=3, target=2.0)
    with ExperimentStore(tmp_path / "c.db") as store:
        _run(experiment, store)
        table = compare(experiment, store, registry())
    handle = io.StringIO()
    table.write_csv(handle)
    rows = _csv_rows(handle.getvalue())
    assert [list(row) for row in rows] == [table.fields] * 2
    rich = table.to_rich()
    shown = [column for column in table.columns if column.in_terminal]
    assert [str(c.header) for c in rich.columns] == [c.header for c in shown]
    for rich_column, column in zip(rich.columns, shown):  # each cell a Text, shown as typed
        assert all(isinstance(cell, Text) for cell in [rich_column.header, *rich_column._cells])
        assert list(map(str, rich_column._cells)) == [column.render(row) for row in rows]
    assert {"success_rate", "evaluations_to_target", "wall_time_median"} <= set(table.fields)


def test_markdown_shows_the_terminal_cells(tmp_path: Path) -> None:
    experiment = _flags_experiment(optimizers=["hs", "random"], seeds=3)
    with ExperimentStore(tmp_path / "c.db") as store:
        _run(experiment, store)
        table = compare(experiment, store, registry())
    lines = table.to_markdown().splitlines()
    shown = [column for column in table.columns if column.in_terminal]
    assert lines[0] == f"**{table.title}**"
    assert lines[2] == "| " + " | ".join(c.header.replace("\n", " ") for c in shown) + " |"
    body = [line.strip("|").split(" | ") for line in lines[4:]]
    assert [[cell.strip() for cell in row] for row in body] == [
        [column.render(row) for column in shown] for row in table.rows
    ]


def test_no_run_shows_what_is_stored_and_runs_nothing(tmp_path: Path) -> None:
    """Seed 1 of 2 is stored; --no-run shows it as 1/2 and leaves the store as it was."""
    with ExperimentStore(tmp_path / "c.db") as store:
        _run(_flags_experiment(seeds=1, name="half"), store)
    flags = ("-o", "hs", "-p", "sphere", "--seeds", "2", "--budget", "200", "--set", "dim=3",
             "--name", "half", "--db", "c.db", "--no-run")  # fmt: skip
    done = metaopt_cli("compare", *flags, "--format", "csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    (row,) = _csv_rows(done.stdout)
    assert (row["finished"], row["planned"]) == (1, 2)
    with ExperimentStore(tmp_path / "c.db") as store:
        assert len(store.runs()) == 1
    missing = metaopt_cli("compare", *flags[:-3], "--db", "none.db", "--no-run", cwd=tmp_path)
    assert missing.returncode == 2 and not (tmp_path / "none.db").exists()


def test_jobs_run_side_by_side_and_end_as_one_after_another(tmp_path: Path) -> None:
    """--jobs 2: every run in its own process gives the very runs a serial compare gives (same
    evaluations, same best), a second call skips them all, and --jobs with --workers is refused."""
    experiment = _flags_experiment(optimizers=["hs", "ga"], seeds=3, budget=150, name="jobs")
    with ExperimentStore(tmp_path / "serial.db") as store:
        _run(experiment, store)
        serial = _best_fitnesses(store, experiment)
    flags = ("-o", "hs", "-o", "ga", "-p", "sphere", "--seeds", "3", "--budget", "150",
             "--set", "dim=3", "--name", "jobs", "--db", "jobs.db", "--jobs", "2")  # fmt: skip
    done = metaopt_cli("compare", *flags, "--format", "csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert sum(line.endswith(" ran") for line in done.stderr.splitlines()) == 6
    with ExperimentStore(tmp_path / "jobs.db") as store:
        assert _best_fitnesses(store, experiment) == serial
        counts = {store.evaluation_counts(r.id) for r in store.runs()}
    assert counts == {EvaluationCounts(150, 0, 0)}
    again = metaopt_cli("compare", *flags, "--format", "csv", cwd=tmp_path)
    skipped = sum(line.endswith(" skipped") for line in again.stderr.splitlines())
    assert again.returncode == 0 and skipped == 6, again.stderr
    both = metaopt_cli("compare", *flags, "--workers", "2", cwd=tmp_path)
    assert both.returncode == 2 and "use one or the other" in both.stderr


def test_at_compares_cells_of_different_budgets_at_an_equal_one(tmp_path: Path) -> None:
    (tmp_path / "at.toml").write_text(
        'problem = "sphere"\nseeds = 3\n[problem_settings]\ndim = 3\n'
        '[[optimizers]]\nname = "hs"\nbudget = 100\n'
        '[[optimizers]]\nname = "random"\nbudget = 300\n'
        '[[optimizers]]\nlabel = "resampled"\nname = "random"\nbudget = 300\n'
        "settings = { resample = 3 }\n"
    )
    experiment = load_experiment(tmp_path / "at.toml", registry())
    with ExperimentStore(tmp_path / "c.db") as store:
        _run(experiment, store)
        table = compare(experiment, store, registry(), at=100)
        firsts = {
            cell.optimizer.label: [
                min(e.fitness for e in store.evaluations(run.id) if e.index < 100)
                for run in (store.member(experiment.name, cell.key, s) for s in experiment.seeds)
            ]
            for cell in experiment.cells()
        }
    hs, plain, resampled = table.rows
    assert hs["best_at_median"] == pytest.approx(np.median(firsts["hs"]))
    assert plain["best_at_median"] == pytest.approx(np.median(firsts["random"]))
    assert plain["fitness_median"] < plain["best_at_median"]  # its 200 evaluations more count
    assert resampled["best_at_median"] is None  # a single sample is not what was judged
    worse = plain if hs["best_at_median"] < plain["best_at_median"] else hs
    expected = mannwhitneyu(firsts["hs"], firsts["random"], alternative="two-sided").pvalue
    assert worse["p_at"] == pytest.approx(expected)


def test_success_rate_and_evaluations_to_target_on_a_constructed_case(tmp_path: Path) -> None:
    """Minimized, target 1: seed 1 reaches it at its 3rd evaluation, seed 2 at its 2nd, seed 3
    never; so success 2/3 and a median of 2.5 evaluations over the successful seeds."""
    fitnesses = {1: [5.0, 3.0, 0.5, 0.1], 2: [2.0, 0.9, 4.0, 7.0], 3: [4.0, 3.0, 2.0, 1.5]}
    experiment = _flags_experiment(optimizers=["random"], seeds=3, budget=4, target=1.0)
    (cell,) = experiment.cells()
    with ExperimentStore(tmp_path / "made.db") as store:
        for seed, values in fitnesses.items():
            with store.joining(experiment.name, cell.key, seed):
                run_id = store.create_run(
                    optimizer="random", optimizer_params={}, problem="sphere",
                    problem_params={"dim": 3}, seed=seed, budget=4, sense="minimize",
                    space=[], settings=vars(RunSettings()), versions={},
                )  # fmt: skip
            for index, fitness in enumerate(values):
                store.add_evaluation(run_id, index, index, np.zeros(3), fitness, {}, None, 0, 0.0)
            store.finish_run(run_id, "finished", wall_time=float(seed))
        (row,) = compare(experiment, store, registry()).rows
        assert [d.action for d in _run(experiment, store)] == ["skipped"] * 3
    assert row["success_rate"] == pytest.approx(2 / 3)
    assert row["evaluations_to_target"] == 2.5
    assert row["fitness_median"] == 0.9
    assert row["wall_time_median"] == 2.0


def test_evaluations_to_target_of_a_resampled_run_counts_whole_candidates(
    tmp_path: Path,
) -> None:
    """Resampled twice, target 1: a lucky first sample (0.5 at evaluation 1) does not reach it
    for a candidate whose mean is 2.75; the third candidate's mean 0.85 does, after 6."""
    samples = [[0.5, 5.0], [3.0, 3.0], [0.8, 0.9], [0.1, 0.2]]
    experiment = _flags_experiment(optimizers=["random"], seeds=1, budget=8, target=1.0)
    (cell,) = experiment.cells()
    with ExperimentStore(tmp_path / "made.db") as store:
        with store.joining(experiment.name, cell.key, 1):
            run_id = store.create_run(
                optimizer="random", optimizer_params={}, problem="sphere",
                problem_params={"dim": 3}, seed=1, budget=8, sense="minimize", space=[],
                settings=vars(RunSettings(resample=2)), versions={},
            )  # fmt: skip
        for number, values in enumerate(samples):
            for sample, fitness in enumerate(values):
                index = 2 * number + sample
                store.add_evaluation(run_id, index, number, np.zeros(3), fitness, {}, None, 0, 0.0)
        store.finish_run(run_id, "finished", wall_time=1.0)
        (row,) = compare(experiment, store, registry()).rows
    assert row["success_rate"] == 1.0
    assert row["evaluations_to_target"] == 6
    assert row["fitness_median"] == pytest.approx(0.15)


def test_metric_rates_and_medians_follow_the_recent_figures_rule() -> None:
    """One rule for a flag and a metric's figure: compare's tables use reporting.recent's."""
    from metaopt.comparison import summary, transfer
    from metaopt.reporting import recent

    assert summary.is_flag is recent.is_flag and transfer.is_flag is recent.is_flag
    assert summary.metric_value is recent.metric_value
    assert summary.center([0.0, 1.0, 1.0, 1.0], True) == 0.75
    assert summary.center([3.0, 1.0, 2.0, 10.0], False) == 2.5
    assert summary.center([], False) is None


def test_reaching_the_target_follows_the_sense() -> None:
    assert ProblemTraits(Sense.MINIMIZE, ()).reaches(0.5, 1.0)
    assert not ProblemTraits(Sense.MINIMIZE, ()).reaches(1.5, 1.0)
    assert ProblemTraits(Sense.MAXIMIZE, ()).reaches(1.0, 1.0)
    assert not ProblemTraits(Sense.MAXIMIZE, ()).reaches(0.5, 1.0)


def test_an_interrupted_cell_is_resumed_and_ends_like_an_uninterrupted_one(
    tmp_path: Path,
) -> None:
    experiment = _flags_experiment(seeds=2, budget=200)

    class StopSecondRun:
        def __init__(self) -> None:
            self.runs = 0

        def start(self, total: int, done: int) -> None:
            self.runs += 1

        def update(self, done: int, best: float | None) -> None:
            if self.runs == 2 and done == 120:
                raise KeyboardInterrupt

    stopper = StopSecondRun()
    with ExperimentStore(tmp_path / "cut.db") as store:
        with pytest.raises(RunInterrupted):
            _run(experiment, store, lambda label: contextlib.nullcontext(stopper))
        assert [r.status for r in store.runs()] == ["finished", "interrupted"]
        actions = [(d.action, d.run_id) for d in _run(experiment, store)]
        assert actions == [("skipped", 1), ("resumed", 2)]
        assert [r.status for r in store.runs()] == ["finished", "finished"]
        resumed = [(e.x.tobytes(), e.fitness) for e in store.evaluations(2)]
    with ExperimentStore(tmp_path / "whole.db") as store:
        _run(experiment, store)
        assert [(e.x.tobytes(), e.fitness) for e in store.evaluations(2)] == resumed


def test_an_edited_experiment_under_the_same_name_is_refused(tmp_path: Path) -> None:
    with ExperimentStore(tmp_path / "e.db") as store:
        _run(_flags_experiment(seeds=1, budget=50, name="same"), store)
        with pytest.raises(ConfigError, match="budget 50 -> 60"):
            _run(_flags_experiment(seeds=1, budget=60, name="same"), store)


def test_a_warm_started_experiment_run_again_reuses_its_runs(tmp_path: Path) -> None:
    """A warm start without start_points is stored with the optimizer's initial population
    filled in: the next compare skips those runs, and still refuses other start points."""
    text = (
        'name = "warm"\nproblem = "sphere"\nseeds = 2\n[problem_settings]\ndim = 2\n'
        '[[optimizers]]\nname = "random"\nbudget = 30\nsettings = { start = [0.1, 0.2]%s }\n'
    )
    (tmp_path / "warm.toml").write_text(text % "")
    experiment = load_experiment(tmp_path / "warm.toml", registry())
    with ExperimentStore(tmp_path / "w.db") as store:
        assert [d.action for d in _run(experiment, store)] == ["ran"] * 2
        assert {r.settings["start_points"] for r in store.runs()} == {100}  # random's batch
        assert [d.action for d in _run(experiment, store)] == ["skipped"] * 2
        (tmp_path / "warm.toml").write_text(text % ", start_points = 5")
        edited = load_experiment(tmp_path / "warm.toml", registry())
        with pytest.raises(ConfigError, match=r"'start_points': 100, .* -> .*'start_points': 5,"):
            _run(edited, store)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('problem = "sphere"\nseeds = 2\n[[optimizers]]\nname = "hss"\nbudget = 10\n',
         "optimizer entry 1 ('hss'): unknown optimizer 'hss'. Did you mean 'hs'?"),
        ('problem = "sphere"\nseeds = 2\n[[optimizers]]\nname = "hs"\n',
         "optimizer entry 1 ('hs') has no 'budget'"),
        ('problem = "sphere"\nseeds = [1, 2\n', "not valid TOML"),
        ('problem = "nao-walk"\nseeds = 1\n[[optimizers]]\nname = "hs"\nbudget = 4\n'
         'settings = { start_from = "goal_wlk" }\n',
         "start_from 'goal_wlk' is not a stored candidate"),
        ('problem = "nao-walk"\nseeds = 1\n[[optimizers]]\nname = "hs"\nbudget = 4\n'
         'settings = { start_from = "goal_walk" }\n',  # a steered gait, the paper's controller
         "'goal_walk' has the variables"),
        ('problem = "nao-walk"\nseeds = 1\n[problem_settings]\n'
         'controller = ["steered", "balanced"]\n[[optimizers]]\nname = "hs"\nbudget = 4\n'
         'settings = { start_from = "goal_walk" }\n',  # fits both, with 15 and 17 values
         "start_from 'goal_walk' gives different start points in different cells"),
        ('problem = "nao-walk"\nseeds = 1\n[problem_settings]\nengine_score = "worst"\n'
         'backend = ["mujoco+pybullet+ode", "mujoco"]\n[[optimizers]]\nname = "cmaes"\n'
         'budget = 24\nsettings = { screen = true }\n',  # one engine: no cheaper bound
         "cell 'cmaes' [backend=mujoco]: problem 'nao-walk' with these settings has no cheaper "
         "bound to screen with"),
        ('problem = "nao-walk"\nseeds = 1\n[problem_settings]\nengine_score = "worst"\n'
         'backend = "mujoco+pybullet+ode"\n[[optimizers]]\nname = "cmaes"\nbudget = 24\n'
         'settings = { screen = true }\n[[optimizers]]\nname = "hs"\nbudget = 24\n'
         'settings = { screen = true }\n',  # refused before the cmaes cell runs
         "cell 'hs': optimizer 'hs' reads every candidate's fitness"),
    ],
    ids=["unknown optimizer", "missing budget", "bad TOML", "unknown start", "other variables",
         "start per cell", "screen without a bound", "screen with hs"],
)  # fmt: skip
def test_a_bad_experiment_file_is_one_clear_error(tmp_path: Path, text: str, message: str) -> None:
    (tmp_path / "bad.toml").write_text(text)
    done = metaopt_cli("compare", "bad.toml", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert "bad.toml: " in done.stderr and message in " ".join(done.stderr.split())
    assert not (tmp_path / "metaopt.db").exists()


def test_an_experiment_file_starts_its_runs_from_stored_candidates(tmp_path: Path) -> None:
    """settings.start_from names stored candidates: every run's first candidates are their
    points, in the order given (a warm start, as run --start-from), on every cell."""
    (tmp_path / "warm.toml").write_text(
        'problem = "nao-walk"\nseeds = [1]\n'
        '[problem_settings]\ncontroller = "steered"\nduration = 2.0\nlock = 1.0\n'
        'backend = ["mujoco", "ode"]\n'
        '[[optimizers]]\nname = "hs"\nbudget = 4\n'
        'settings = { start_from = ["goal_walk", "steered_walk"], start_points = 3 }\n'
    )
    done = metaopt_cli("compare", "warm.toml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    stored = registry().problem("nao-walk").stored_candidates()
    with ExperimentStore(tmp_path / "metaopt.db") as store:
        runs = store.runs()
        assert len(runs) == 2
        for run in runs:
            assert run.settings["start_from"] == "goal_walk, steered_walk"
            first = [e.x for e in store.evaluations(run.id)][:2]
            np.testing.assert_array_equal(first[0], stored["goal_walk"].x)
            np.testing.assert_array_equal(first[1], stored["steered_walk"].x)


def test_the_documented_warm_start_experiment_loads_its_gaits(tmp_path: Path) -> None:
    """docs/comparing.md's example of settings.start_from, as written there."""
    text = (ROOT / "docs" / "comparing.md").read_text(encoding="utf-8")
    example = text.split("### Starting from a stored gait")[1].split("```toml")[1]
    (tmp_path / "refine.toml").write_text(example.split("```")[0])
    experiment = load_experiment(tmp_path / "refine.toml", registry())
    stored = registry().problem("nao-walk").stored_candidates()
    starts = {entry.label: entry.settings.start for entry in experiment.optimizers}
    assert starts == {
        "hs": [list(stored["goal_walk"].x)],
        "ga": [list(stored["goal_walk"].x), list(stored["capped_walk"].x)],
    }


def test_an_experiment_file_defines_the_grid(tmp_path: Path) -> None:
    path = tmp_path / "grid.toml"
    path.write_text(
        'name = "grid"\nproblem = "rastrigin"\nseeds = [7, 8]\ntarget = 50\n'
        "[problem_settings]\ndim = [2, 4]\n"
        '[[optimizers]]\nlabel = "hs-classic"\nname = "hs"\nbudget = 40\n'
        "params = { hmcr = 0.9 }\nsettings = { batch = 4 }\n"
        '[[optimizers]]\nname = "ga"\nbudget = 60\nparams = { population = 10 }\n'
    )
    experiment = load_experiment(path, registry())
    cells = experiment.cells()
    assert [(c.optimizer.label, c.setting) for c in cells] == [
        ("hs-classic", "dim=2"), ("ga", "dim=2"), ("hs-classic", "dim=4"), ("ga", "dim=4"),
    ]  # fmt: skip
    with ExperimentStore(tmp_path / "grid.db") as store:
        _run(experiment, store)
        runs = store.runs()
        table = compare(experiment, store, registry())
    assert len(runs) == 8 and {r.seed for r in runs} == {7, 8}
    assert {(r.optimizer, r.budget, r.settings["batch"]) for r in runs} == {
        ("hs", 40, 4), ("ga", 60, 0),
    }  # fmt: skip
    assert [row["setting"] for row in table.rows] == ["dim=2", "dim=2", "dim=4", "dim=4"]
    assert sum(row.get("p_value") is None for row in table.rows) == 2  # one best per setting


def test_only_runs_part_of_the_grid_as_members_of_the_whole(tmp_path: Path) -> None:
    """--only optimizer=ga --only dim=4 runs and shows that one cell; its runs are the whole
    experiment's (the full compare skips them and its other cells are as if run together), and
    a selection the grid does not have is one line naming it."""
    path = tmp_path / "grid.toml"
    path.write_text(
        'name = "part"\nproblem = "rastrigin"\nseeds = 2\n[problem_settings]\ndim = [2, 4]\n'
        '[[optimizers]]\nname = "hs"\nbudget = 40\n'
        '[[optimizers]]\nname = "ga"\nbudget = 60\nparams = { population = 10 }\n'
    )
    experiment = load_experiment(path, registry())
    part = restrict(experiment, ["optimizer=ga", "dim=4.0"], registry())
    assert [(c.optimizer.label, c.setting) for c in part.cells()] == [("ga", "dim=4")]
    done = metaopt_cli("compare", "grid.toml", "--only", "optimizer=ga", "--only", "dim=4",
                       "--format", "csv", "--db", "part.db", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert [(r["optimizer"], r["setting"], r["finished"]) for r in _csv_rows(done.stdout)] == [
        ("ga", "dim=4", 2)
    ]
    whole = metaopt_cli("compare", "grid.toml", "--db", "part.db", "--format", "csv", cwd=tmp_path)
    assert whole.returncode == 0, whole.stderr
    assert "6 run(s) ran, 0 resumed, 2 already finished" in whole.stderr
    with ExperimentStore(tmp_path / "part.db") as store:
        assert _best_fitnesses(store, part) == {"ga": [
            store.best_evaluation(r).fitness for r in store.runs() if r.problem_params["dim"] == 4
            and r.optimizer == "ga"
        ]}  # fmt: skip
    with ExperimentStore(tmp_path / "together.db") as store:
        _run(experiment, store)
        together = _best_fitnesses(store, restrict(experiment, ["dim=2"], registry()))
    with ExperimentStore(tmp_path / "part.db") as store:
        assert _best_fitnesses(store, restrict(experiment, ["dim=2"], registry())) == together
    for bad, named in [("optimizer=cma", "hs, ga"), ("dim=3", "2, 4"), ("seed=1", "optimizer, dim"),
                       ("dim", "NAME=VALUE")]:  # fmt: skip
        refused = metaopt_cli("compare", "grid.toml", "--only", bad, "--db", "x.db", cwd=tmp_path)
        lines = refused.stderr.strip().splitlines()
        assert refused.returncode == 2 and len(lines) == 1 and named in lines[0], refused.stderr
        assert "--only" in lines[0] and not (tmp_path / "x.db").exists()


def _walk_experiment(tmp_path: Path) -> Experiment:
    path = tmp_path / "walk.toml"
    path.write_text(
        'name = "walk"\nproblem = "nao-walk"\nseeds = [1, 2]\n'
        '[problem_settings]\nbackend = "mujoco"\nduration = 3.0\nlock = 1.0\n'
        '[[optimizers]]\nname = "hs"\nbudget = 8\nparams = { hms = 4 }\n'
    )
    return load_experiment(path, registry())


def test_transfer_table_values_equal_replays_on_the_other_engine(tmp_path: Path) -> None:
    experiment = _walk_experiment(tmp_path)
    with ExperimentStore(tmp_path / "walk.db") as store:
        _run(experiment, store)
        transfers = replay_on_other_engines(experiment, store, registry())
        table: ResultTable = transfer_table(experiment, transfers, registry())
        replays = [replay_candidate(run_source(store, run.id), registry(), {"backend": "pybullet"})
                   for run in store.runs()]  # fmt: skip
    others = [e for e, info in registry().physics_backends.items()
              if e != "mujoco" and not info.unavailable]  # fmt: skip
    assert [row["replayed_on"] for row in table.rows] == others  # ode, where installed
    row, transfer = table.rows[-1], transfers[-1]
    assert (row["found_on"], row["replayed_on"], row["runs"]) == ("mujoco", "pybullet", 2)
    assert [r.replayed.fitness for r in transfer.replays] == [r.replayed.fitness for r in replays]
    assert row["fitness_replayed"] == np.median([r.replayed.fitness for r in replays])
    assert row["fitness_found"] == np.median([r.source.fitness for r in replays])
    assert row["distance_replayed"] == np.median([r.replayed.metrics["distance"] for r in replays])
    assert row["fell_replayed"] == np.mean([r.replayed.metrics["fell"] for r in replays])
    gaps = [r.source.fitness - r.replayed.fitness for r in replays]
    assert row["fitness_gap"] == pytest.approx(np.median(gaps), rel=1e-12)


def test_transfer_needs_a_problem_with_engines(tmp_path: Path) -> None:
    experiment = _flags_experiment(seeds=1, budget=10)
    with ExperimentStore(tmp_path / "t.db") as store, pytest.raises(ConfigError, match="backend"):
        replay_on_other_engines(experiment, store, registry())


@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
def test_ctrl_c_stops_every_job_and_keeps_what_finished(tmp_path: Path, stop: str) -> None:
    """SIGINT (Ctrl-C) or SIGTERM to a --jobs 2 compare: exit 130 with the resume hint, the two
    runs under way marked interrupted with their evaluations stored, the members not started
    never begun."""
    import signal
    import sqlite3
    import subprocess
    import sys
    import time

    command = [sys.executable, "-m", "metaopt", "compare", "-o", "hs", "-o", "random", "-p",
               "sphere", "--seeds", "2", "--budget", "2000000", "--db", "c.db",
               "--jobs", "2"]  # fmt: skip
    # A shell without job control starts background jobs with SIGINT ignored, and the ignoring
    # is inherited (a CI step run with '&' would never see the Ctrl-C): start the compare as a
    # terminal does, with SIGINT at its default.
    process = subprocess.Popen(
        command, cwd=tmp_path, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip

    def stored() -> int:
        try:
            with sqlite3.connect(tmp_path / "c.db") as db:
                return db.execute("SELECT COUNT(DISTINCT run_id) FROM evaluations").fetchone()[0]
        except sqlite3.OperationalError:
            return 0

    deadline = time.monotonic() + 60
    while stored() < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    process.send_signal(getattr(signal, stop))
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "Run the same `metaopt compare` again" in stderr and "Traceback" not in stderr
    with ExperimentStore(tmp_path / "c.db") as store:
        runs = store.runs()
        assert len(runs) == 2 and {run.status for run in runs} == {"interrupted"}
        assert all(store.evaluation_counts(run.id).stored > 0 for run in runs)


def test_brackets_in_names_labels_settings_and_paths_are_shown_as_typed(tmp_path: Path) -> None:
    """A name, an optimizer label, a setting and a store path in brackets are data, not rich
    markup: the compare runs and shows them, `runs` lists the experiment, export names its file."""
    path = tmp_path / "brackets.toml"
    path.write_text(
        'name = "a[/b]"\nproblem = "sphere"\nseeds = 1\n[problem_settings]\ndim = [2, 3]\n'
        '[[optimizers]]\nlabel = "r[/x]"\nname = "random"\nbudget = 5\n'
    )
    done = metaopt_cli("compare", "brackets.toml", "--db", "n[x].db", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "experiment 'a[/b]': 2 run(s) ran" in done.stdout and "(in n[x].db)" in done.stdout
    assert "r[/x] [dim=2] seed 1" in done.stdout  # the progress bar's label
    assert "experiment a[/b]" in done.stdout and "r[/x]" in done.stdout
    flags = metaopt_cli("compare", "-o", "random", "-p", "sphere", "--budget", "5", "--seeds",
                        "1", "--set", "dim=2", "--set", "dim=3", "--name", "flags",
                        "--db", "n[x].db", cwd=tmp_path)  # fmt: skip
    assert flags.returncode == 0, flags.stderr
    assert "random [dim=2] seed 1" in flags.stdout and "random [dim=3] seed 1" in flags.stdout
    listed = metaopt_cli("runs", "--db", "n[x].db", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    assert listed.stdout.count("a[/b]") == 2
    single = metaopt_cli("run", "-o", "random", "-p", "sphere", "--budget", "5",
                         "--db", "q[a].db", cwd=tmp_path)  # fmt: skip
    assert single.returncode == 0, single.stderr
    assert "(in q[a].db)" in single.stdout
    wrote = metaopt_cli("export", "1", "--db", "q[a].db", "--output", "x[final].csv", cwd=tmp_path)
    assert wrote.returncode == 0 and "wrote 5 evaluations to x[final].csv" in wrote.stderr


def test_transfer_as_json_is_one_document_and_as_csv_is_refused(tmp_path: Path) -> None:
    """--transfer --format json: one object holding both tables; --format csv, which would write
    two tables with different headers, is refused in one line before anything runs."""
    (tmp_path / "walk.toml").write_text(
        'name = "walk"\nproblem = "nao-walk"\nseeds = [1]\n'
        '[problem_settings]\nbackend = "mujoco"\nduration = 3.0\nlock = 1.0\n'
        '[[optimizers]]\nname = "hs"\nbudget = 8\nparams = { hms = 4 }\n'
    )
    refused = metaopt_cli("compare", "walk.toml", "--transfer", "--format", "csv",
                          "--db", "walk.db", cwd=tmp_path)  # fmt: skip
    lines = refused.stderr.strip().splitlines()
    assert refused.returncode == 2 and len(lines) == 1, refused.stderr
    assert "--format json" in lines[0] and "--transfer-csv" in lines[0]
    assert refused.stdout == "" and not (tmp_path / "walk.db").exists()
    done = metaopt_cli("compare", "walk.toml", "--transfer", "--format", "json", "--transfer-csv",
                       "transfer.csv", "--db", "walk.db", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    document = json.loads(done.stdout)
    assert list(document) == ["comparison", "transfer"]
    assert [row["optimizer"] for row in document["comparison"]] == ["hs"]
    assert document["transfer"] and {r["found_on"] for r in document["transfer"]} == {"mujoco"}
    from_file = _csv_rows((tmp_path / "transfer.csv").read_text())
    assert [r["replayed_on"] for r in from_file] == [r["replayed_on"] for r in document["transfer"]]
    plain = metaopt_cli("compare", "walk.toml", "--no-run", "--format", "json", "--db", "walk.db",
                        cwd=tmp_path)  # fmt: skip
    assert isinstance(json.loads(plain.stdout), list)  # without --transfer: the table's rows
