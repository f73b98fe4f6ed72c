"""`metaopt report`: valid small PNGs whose plotted data is the stored (or re-simulated) data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from matplotlib.image import imread

from metaopt.cli.report import report
from metaopt.plugins import registry
from metaopt.reporting.convergence import Band, convergence, group_runs
from metaopt.reporting.plots import bands_figure, convergence_figure
from metaopt.reporting.report import comparison_figures, run_figures, write_figures
from metaopt.running import RunSpec, run
from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait
from tests.walk_runs import store_walk_run


@pytest.fixture(scope="module")
def walk_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    db = tmp_path_factory.mktemp("walk") / "runs.db"
    assert store_walk_run(db) == 1
    return db


def _sphere_runs(db: Path, setups: list[tuple[str, dict]], seeds: range) -> list[int]:
    plugins = registry()
    ids = []
    with RunStore(db) as store:
        for optimizer, params in setups:
            for seed in seeds:
                spec = RunSpec(optimizer, "sphere", 120, seed, optimizer_params=params)
                result = run(spec, plugins.optimizer(optimizer), plugins.problem("sphere"), store)
                ids.append(result.run_id)
    return ids


def _lines(figure, axes: int = 0) -> dict[str, np.ndarray]:
    """Each labelled line's y data of one axes."""
    return {line.get_label(): line.get_ydata() for line in figure.axes[axes].get_lines()}


def test_best_so_far_and_trailing_mean_leave_failed_evaluations_out():
    curves = convergence(np.array([3.0, np.nan, 1.0, 2.0, np.nan, np.nan]), False, window=2)
    np.testing.assert_array_equal(curves.best, [3, 3, 1, 1, 1, 1])
    np.testing.assert_array_equal(curves.mean, [3, 3, 1, 1.5, 2, np.nan])
    assert curves.failed == 3
    rising = convergence(np.array([np.nan, 1.0, 0.5, 4.0]), True)
    np.testing.assert_array_equal(rising.best, [np.nan, 1, 1, 4])
    assert rising.window == 1  # 5 % of 4 evaluations, at least 1


def test_run_report_plots_the_stored_evaluations(walk_db):
    with RunStore(walk_db) as store:
        stored = [e.fitness for e in store.evaluations(1)]
        figures = run_figures(store, 1, registry())
    assert figures.note is None
    assert list(figures.figures) == ["convergence", "joint_angles", "drift", "torso_height"]
    lines = _lines(figures.figures["convergence"])
    ok = [f for f in stored if f is not None]
    assert stored[2] is None and len(ok) == 2
    np.testing.assert_array_equal(lines["best so far"], [ok[0], max(ok), max(ok)])
    # the window is 5 % of 3 evaluations, at least 1: the last one only, NaN where it failed
    mean = lines["mean of the last 1 evaluations (failed excluded)"]
    np.testing.assert_array_equal(mean, [ok[0], ok[1], np.nan])
    assert "1 of 3 evaluations failed" in figures.figures["convergence"].axes[0].get_title()
    zoomed = figures.figures["convergence"].axes[1]
    np.testing.assert_array_equal(zoomed.get_lines()[0].get_ydata(), lines["best so far"])
    low, high = zoomed.get_ylim()
    assert low < min(ok) and max(ok) < high and high - low < 1.2 * (max(ok) - min(ok))


def test_walk_figures_are_the_resimulated_best_in_the_papers_convention(walk_db):
    with RunStore(walk_db) as store:
        figures = run_figures(store, 1, registry()).figures
    problem = registry().problem("nao-walk").factory(duration=3.0, lock=1.0)
    walk = problem.runner.run(problem.gait(gait_vector(load_gait())), record=True).trajectory
    problem.close()
    assert len(walk["time"]) == 100  # 2 s of walking at 50 Hz, no fall
    np.testing.assert_array_equal(_lines(figures["drift"])["_child0"], walk["y"])
    np.testing.assert_array_equal(_lines(figures["torso_height"])["_child0"], walk["z"])
    angles = figures["joint_angles"]
    for axes, (joint, sign) in enumerate((("lj3", -1), ("lj4", 1), ("lj5", -1))):
        lines = _lines(angles, axes)
        for side in ("left", "right"):
            server = walk[f"{side[0]}{joint}_target"]
            np.testing.assert_allclose(lines[f"{side} target (CPG)"], sign * np.degrees(server))
            measured = walk[f"{side[0]}{joint}_angle"]
            np.testing.assert_allclose(lines[f"{side} measured"], sign * np.degrees(measured))
        assert angles.axes[axes].get_ylabel().endswith("(deg)")
    assert angles.axes[-1].get_xlabel() == "time since walking began (s)"


def test_report_command_writes_small_valid_pngs(walk_db, tmp_path):
    out = tmp_path / "figures"
    done = CliRunner().invoke(report, ["1", "--db", str(walk_db), "--out", str(out)])
    assert done.exit_code == 0, done.output
    sizes = {path.name: imread(path).shape[:2] for path in sorted(out.iterdir())}
    assert sizes == {
        "convergence.png": (640, 640),
        "drift.png": (360, 640),
        "joint_angles.png": (720, 640),
        "torso_height.png": (360, 640),
    }
    assert all(path.stat().st_size < 150_000 for path in out.iterdir())
    assert f"wrote {out / 'joint_angles.png'}" in done.output


def test_a_problem_without_figures_gets_its_convergence_and_one_note(tmp_path):
    db = tmp_path / "runs.db"
    _sphere_runs(db, [("random", {})], range(1, 2))
    done = CliRunner().invoke(report, ["1", "--db", str(db), "--out", str(tmp_path / "out")])
    assert done.exit_code == 0, done.output
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["convergence.png"]
    note = "Note: problem 'sphere': draws no figures of its own; only the convergence figure"
    assert note in done.output
    assert "Traceback" not in done.output


def test_comparison_bands_are_median_and_quartiles_per_setup(tmp_path):
    db = tmp_path / "runs.db"
    ids = _sphere_runs(db, [("hs", {"hmcr": 0.9}), ("hs", {"hmcr": 0.5}), ("random", {})],
                       range(1, 4))  # fmt: skip
    with RunStore(db) as store:
        figures = comparison_figures(store, [str(i) for i in ids], "setup")
        best = {i: np.minimum.accumulate([e.fitness for e in store.evaluations(i)]) for i in ids}
        by_name = group_runs([store.run(i) for i in ids], "optimizer")
    lines = _lines(figures.figures["convergence_comparison"])
    assert list(lines) == ["hs hmcr=0.9 (3 runs)", "hs hmcr=0.5 (3 runs)", "random (3 runs)"]
    for label, members in zip(lines, (ids[:3], ids[3:6], ids[6:])):
        np.testing.assert_allclose(lines[label], np.median([best[i] for i in members], axis=0))
    bands = figures.figures["convergence_comparison"].axes[0].collections
    assert len(bands) == 3
    assert {k: len(v) for k, v in by_name.items()} == {"hs": 6, "random": 3}
    paths = write_figures(figures, tmp_path / "out")
    assert imread(paths[0]).shape[:2] == (420, 640)


@pytest.mark.parametrize("maximize", [True, False])
def test_band_axes_follow_the_medians_and_the_better_quartile(maximize):
    """A worse quartile still at the first random candidates' level (robots that all fall, -10)
    runs off the axis; the medians and the better quartile stay in view from 5 % on."""
    sign = 1.0 if maximize else -1.0
    evaluations = np.arange(1, 101)
    median = sign * np.linspace(0.1, 0.4, 100)
    better = median + sign * 0.05
    worse = np.where(evaluations < 30, -10.0 * sign, median - sign * 0.02)
    lower, upper = (worse, better) if maximize else (better, worse)
    figure = bands_figure({"hs": Band(evaluations, lower, median, upper, 5)}, maximize, "t")
    low, high = figure.axes[0].get_ylim()
    shown = np.concatenate([median[5:], better[5:]])
    assert low <= shown.min() and shown.max() <= high
    assert high - low < 1.2 * (shown.max() - shown.min())  # the -10 quartile is not in range


def test_runs_of_different_problems_do_not_compare(tmp_path):
    db = tmp_path / "mixed.db"
    store_walk_run(db)
    _sphere_runs(db, [("random", {})], range(1, 2))
    done = CliRunner().invoke(report, ["1", "2", "--db", str(db)])
    assert done.exit_code != 0
    assert "runs compare only on one problem; these are on nao-walk, sphere" in str(done.exception)


def test_a_minimized_fitness_spanning_decades_is_drawn_on_log_axes(tmp_path):
    plugins = registry()
    with RunStore(tmp_path / "runs.db") as store:
        spec = RunSpec("hs", "sphere", 2000, 1)  # from about 100 down to about 1e-3
        run(spec, plugins.optimizer("hs"), plugins.problem("sphere"), store)
        figure = run_figures(store, 1, plugins).figures["convergence"]
        best = np.minimum.accumulate([e.fitness for e in store.evaluations(1)])
    top, gap = figure.axes
    assert top.get_yscale() == "log" and gap.get_yscale() == "log"
    assert "best so far − optimum (0)" in gap.get_ylabel()  # sphere declares its optimum, 0
    np.testing.assert_array_equal(gap.get_lines()[0].get_ydata(), best)
    # Fitness that stays within two decades, or is maximized, keeps linear axes.
    flat = convergence_figure(convergence(np.linspace(5.0, 1.0, 50), False), "flat")
    rising = convergence_figure(convergence(np.logspace(-3, 3, 50), True), "rising", 0.0)
    assert {ax.get_yscale() for ax in (*flat.axes, *rising.axes)} == {"linear"}


EXPERIMENT = """name = "tiny"
problem = "sphere"
seeds = 3
[problem_settings]
dim = [2, 3]
[[optimizers]]
name = "hs"
budget = 60
[[optimizers]]
name = "random"
budget = 60
"""


def test_experiment_report_draws_each_setting_from_the_stored_runs(tmp_path):
    from metaopt.comparison.experiment import load_experiment
    from metaopt.storage.experiment_store import ExperimentStore
    from tests.conftest import metaopt_cli

    (tmp_path / "tiny.toml").write_text(EXPERIMENT)
    assert metaopt_cli("compare", "tiny.toml", "--db", "e.db", cwd=tmp_path).returncode == 0
    done = metaopt_cli("report", "--experiment", "tiny.toml", "--db", "e.db", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    out = tmp_path / "report-tiny"
    for folder in ("dim-2", "dim-3"):
        stems = {p.stem for p in (out / folder).glob("*.png")}
        assert stems == {"convergence", "mean_fitness", "best_convergence"}
    index = (out / "index.md").read_text()
    assert "## dim=2" in index and "(dim-3/mean_fitness.png)" in index

    experiment = load_experiment(tmp_path / "tiny.toml", registry())
    with ExperimentStore(tmp_path / "e.db") as store:
        from metaopt.reporting.report import experiment_figures

        (first, second) = experiment_figures(store, experiment, registry())
        cell = experiment.cells()[0]  # hs on dim=2
        runs = [store.member("tiny", cell.key, seed) for seed in experiment.seeds]
        curves = [convergence([e.fitness for e in store.evaluations(r.id)], False) for r in runs]
        best_run = min(
            (store.member("tiny", c.key, s) for c in experiment.cells()[:2] for s in (1, 2, 3)),
            key=lambda r: store.best_evaluation(r).fitness,
        )
    best_lines = _lines(first.figures.figures["convergence"])
    np.testing.assert_allclose(best_lines["hs (3 runs)"], np.median([c.best for c in curves], 0))
    mean_lines = _lines(first.figures.figures["mean_fitness"])
    np.testing.assert_allclose(mean_lines["hs (3 runs)"], np.median([c.mean for c in curves], 0))
    assert (first.setting, second.setting) == ("dim=2", "dim=3")
    assert first.best_run.id == best_run.id


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["1", "--experiment", "tiny.toml"], "not both"),
        ([], "not both"),
        (["--experiment", "tiny.toml"], "no finished run"),
    ],
)
def test_experiment_report_bad_input_is_one_line(tmp_path, args, message):
    from metaopt.storage.experiment_store import ExperimentStore
    from tests.conftest import metaopt_cli

    (tmp_path / "tiny.toml").write_text(EXPERIMENT)
    ExperimentStore(tmp_path / "e.db").close()
    done = metaopt_cli("report", *args, "--db", "e.db", cwd=tmp_path)
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "report-tiny").exists()


@pytest.mark.parametrize("maximize", [False, True])
def test_convergence_of_no_fitness_is_empty_curves(maximize: bool) -> None:
    curves = convergence(np.array([]), maximize)
    assert curves.fitness.size == curves.best.size == curves.mean.size == 0
    assert curves.evaluations.size == 0 and curves.failed == 0 and curves.window == 1
