"""The bbob problem: the right COCO function, precision fitness, checks, clean cwd, COCO output."""

from __future__ import annotations

import pickle

import cocoex
import numpy as np
import pytest

from metaopt import ConfigError
from metaopt.params import resolve
from metaopt.testing import check_problem
from metaopt_problems.bbob import DIMENSIONS, PARAMS, BBOBProblem
from tests.conftest import metaopt_cli


def coco_reference(function: int, dim: int, instance: int):
    """The same problem straight from COCO's full bbob suite (kept with its suite, which must
    outlive it), and COCO's optimum value."""
    suite = cocoex.Suite("bbob", "", "")
    problem = suite.get_problem_by_function_dimension_instance(function, dim, instance)
    return suite, problem, cocoex.BareProblem("bbob", function, dim, instance).best_value()


def test_dimensions_are_those_of_cocos_suite():
    assert tuple(cocoex.Suite("bbob", "", "").dimensions) == DIMENSIONS


@pytest.mark.parametrize(
    "function, dim, instance", [(1, 2, 1), (7, 5, 3), (15, 10, 2), (24, 40, 75)]
)
def test_function_dim_instance_select_the_same_problem_as_cocoex(function, dim, instance):
    problem = BBOBProblem(function, dim, instance)
    _suite, reference, f_opt = coco_reference(function, dim, instance)
    assert problem.space.dim == dim
    assert np.all(problem.space.lower == -5.0) and np.all(problem.space.upper == 5.0)
    for x in np.random.default_rng(function).uniform(-5.0, 5.0, (3, dim)):
        expected = reference(x)
        evaluation = problem.evaluate(x, seed=0)
        assert evaluation.metrics["f"] == expected
        assert evaluation.fitness == expected - f_opt
        assert problem.evaluate(x, seed=99).fitness == evaluation.fitness  # pure in (x, seed)
    problem.close()


@pytest.mark.parametrize("function", range(1, 25))
def test_fitness_is_zero_at_cocos_optimum(function):
    problem = BBOBProblem(function, 3, 2)
    assert problem.evaluate(problem.argmin, seed=0).fitness == problem.optimum == 0.0
    off = problem.space.repair(problem.argmin + 0.1)
    assert problem.evaluate(off, seed=0).fitness > 0.0


def test_a_rebuilt_problem_evaluates_the_same():
    problem = BBOBProblem(21, 5, 4)
    x = np.linspace(-4.0, 4.0, 5)
    copy = pickle.loads(pickle.dumps(problem))
    assert copy.evaluate(x, seed=1).fitness == problem.evaluate(x, seed=1).fitness
    problem.close()
    problem.close()  # twice is harmless
    assert problem.evaluate(x, seed=1).fitness == copy.evaluate(x, seed=1).fitness


@pytest.mark.parametrize(
    "given, message",
    [
        ({"function": 25}, "'function' = 25 is invalid; expected an int in [1, 24]"),
        ({"function": 0}, "'function' = 0 is invalid"),
        ({"instance": 0}, "'instance' = 0 is invalid"),
        ({"dim": 4}, "'dim' = 4 is invalid; COCO's bbob suite has dimensions 2, 3, 5, 10, 20, 40"),
        ({"dim": 41}, "'dim' = 41 is invalid"),
        ({"observe": "a b"}, "COCO cannot write to a path with spaces"),
    ],
)
def test_bad_values_are_rejected_before_cocoex_sees_them(given, message):
    # cocoex ends the whole process on an unknown problem, so this must never reach it.
    with pytest.raises(ConfigError) as error:
        BBOBProblem(**resolve(PARAMS, given, "bbob"))
    assert message in str(error.value)


def test_the_working_directory_stays_empty(tmp_path, monkeypatch):
    cwd, elsewhere = tmp_path / "cwd", tmp_path / "elsewhere"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    plain = BBOBProblem(3, 5, 1)
    observed = BBOBProblem(3, 5, 1, observe=str(elsewhere / "run"))
    for x in np.zeros((3, 5)):
        plain.evaluate(x, seed=0)
        observed.evaluate(x, seed=0)
    assert observed.result_folder == str(elsewhere / "run")
    plain.close()
    observed.close()
    assert list(cwd.iterdir()) == []  # COCO's default ./exdata never appears
    assert (elsewhere / "run" / "bbobexp_f3.info").exists()


def test_observe_writes_coco_output_of_a_cli_run(tmp_path):
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    db, folder = tmp_path / "runs.db", tmp_path / "coco" / "random-f1"
    done = metaopt_cli(
        "run", "-o", "random", "-p", "bbob", "--budget", "200", "--db", str(db),
        "--set", "dim=5", "--set", f"observe={folder}", cwd=cwd,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert list(cwd.iterdir()) == []
    info = (folder / "bbobexp_f1.info").read_text()
    assert "funcId = 1, DIM = 5" in info and "algId = 'random-f1'" in info
    assert "1:200|" in info  # instance 1, 200 evaluations
    data = folder / "data_f1" / "bbobexp_f1_DIM5.dat"
    assert data.exists() and data.stat().st_size > 0


def test_a_relative_observe_folder_is_the_only_thing_written_to_cwd(tmp_path):
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    done = metaopt_cli(
        "run", "-o", "random", "-p", "bbob", "--budget", "20", "--db", str(tmp_path / "runs.db"),
        "--set", "observe=coco-out", "--set", "dim=2", cwd=cwd,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert [p.name for p in cwd.iterdir()] == ["coco-out"]
    assert (cwd / "coco-out" / "bbobexp_f1.info").exists()


def test_the_cli_reports_a_bad_dimension_in_one_line(tmp_path):
    done = metaopt_cli(
        "run", "-o", "random", "-p", "bbob", "--set", "dim=4", "--db", str(tmp_path / "runs.db"),
        cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2
    assert "COCO's bbob suite has dimensions 2, 3, 5, 10, 20, 40" in done.stderr


@pytest.mark.parametrize("observe", [False, True])
def test_bbob_passes_the_conformance_kit(tmp_path, monkeypatch, observe):
    monkeypatch.chdir(tmp_path)
    params = {"function": 15, "dim": 3, "observe": str(tmp_path / "coco") if observe else ""}
    check_problem("bbob", params=params)
    written = {p.name.split("-")[0] for p in tmp_path.iterdir()}  # each build: coco, coco-0001...
    assert written == ({"coco"} if observe else set())
