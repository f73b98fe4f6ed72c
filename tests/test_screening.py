"""metaopt run --screen: a cheap bound first, the full evaluation only where a rank needs it."""

import json
from concurrent.futures import BrokenExecutor

import numpy as np
import pytest
from click.testing import CliRunner

from metaopt import ConfigError, Evaluation, Problem, ProblemInfo, Space
from metaopt.cli import main
from metaopt.errors import RunFailed
from metaopt.executors.base import Executor
from metaopt.plugins import registry
from metaopt.reporting.convergence import run_convergence
from metaopt.reporting.report import run_figures
from metaopt.running import RunSettings, RunSpec, resume, run
from metaopt.storage.run_store import EvaluationCounts, RunStore
from tests.fixtures.breaking_executor import BreakingExecutor

POPULATION = 24


class TwoPartSphere(Problem):
    """Minimize the worse of two spheres; the screen computes the first one alone (the full
    fitness, their max, is never lower). Counts the complete phases it ran."""

    screens = True

    def __init__(self, interrupt_at: int = -1) -> None:
        self.space = Space.from_bounds([-1.0] * 4, [1.0] * 4)
        self.completed = 0
        self.interrupt_at = interrupt_at

    def _first(self, x: np.ndarray) -> float:
        return float(np.sum((x - 0.3) ** 2))

    def _second(self, x: np.ndarray) -> float:
        return float(np.sum((x + 0.1) ** 2)) * 0.8

    def evaluate(self, x, seed):
        return Evaluation(max(self._first(x), self._second(x)), {"part": 0.0})

    def screen(self, x, seed):
        return Evaluation(self._first(x), {"part": 1.0})

    def complete(self, x, seed, screened):
        self.completed += 1
        if self.completed == self.interrupt_at:
            raise KeyboardInterrupt
        return Evaluation(max(screened.fitness, self._second(x)), {"part": 0.0})


def _info(problem: TwoPartSphere) -> ProblemInfo:
    return ProblemInfo("two-part-sphere", "test", factory=lambda: problem)


def _run(
    store, problem, screen, budget=POPULATION * 12, optimizer="cmaes",
    executor: Executor | None = None, **settings,
):  # fmt: skip
    params = {"population": POPULATION, "sigma0": 0.3} if optimizer == "cmaes" else {}
    spec = RunSpec(optimizer, "two-part-sphere", budget, 5, optimizer_params=params,
                   settings=RunSettings(screen=screen, **settings))  # fmt: skip
    return run(spec, registry().optimizer(optimizer), _info(problem), store, executor=executor)


def test_screening_changes_no_step_of_cmaes_and_skips_most_full_evaluations(tmp_path):
    """CMA-ES's update reads its better half by rank: telling the others a bound leaves every
    step as it was, so the screened run ends where the plain one does, with fewer complete
    evaluations; each candidate it completed scored what the plain run's did."""
    with RunStore(tmp_path / "runs.db") as store:
        plain_problem, screened_problem = TwoPartSphere(), TwoPartSphere()
        plain = _run(store, plain_problem, screen=False)
        screened = _run(store, screened_problem, screen=True)
        assert screened.best_fitness == plain.best_fitness
        assert np.array_equal(screened.best_x, plain.best_x)
        state = store.run(screened.run_id).checkpoint["state"]
        assert state == store.run(plain.run_id).checkpoint["state"]
        rows = list(store.evaluations(screened.run_id))
        plain_rows = {e.index: e for e in store.evaluations(plain.run_id)}
        statuses = [e.status for e in rows]
        assert statuses.count("screened") == POPULATION * 12 - screened_problem.completed
        assert POPULATION * 12 // 2 <= screened_problem.completed < POPULATION * 12 * 0.8
        for e in rows:
            if e.status == "ok":
                assert e.fitness == plain_rows[e.index].fitness
            else:
                assert e.status == "screened" and e.fitness is None
                assert e.metrics["screen_bound"] <= plain_rows[e.index].fitness
        left = POPULATION * 12 - screened_problem.completed
        assert (plain.screened, screened.screened) == (0, left)
        counts = store.evaluation_counts(screened.run_id)
        assert counts == EvaluationCounts(POPULATION * 12, 0, left)


def test_a_screened_candidate_ranks_below_the_selected_ones_of_its_batch(tmp_path):
    """Every bound cut lies below the batch's selected scores, and on one worker no candidate
    is completed that the ones before it (best bound first) had already ranked out."""
    problem = TwoPartSphere()
    with RunStore(tmp_path / "runs.db") as store:
        result = _run(store, problem, screen=True)
        rows = list(store.evaluations(result.run_id))
        selected = POPULATION // 2
        for first in range(0, len(rows), POPULATION):
            batch = rows[first : first + POPULATION]
            full = sorted(e.fitness for e in batch if e.status == "ok")
            bounds = [e.metrics["screen_bound"] for e in batch if e.status == "screened"]
            assert len(full) >= selected
            assert all(bound > full[selected - 1] for bound in bounds)
            completed = sorted((problem._first(e.x), e.fitness) for e in batch if e.status == "ok")
            for position, (bound, _) in enumerate(completed):
                assert sum(score < bound for _, score in completed[:position]) < selected


def test_same_seed_same_screened_run(tmp_path):
    with RunStore(tmp_path / "runs.db") as store:
        first = _run(store, TwoPartSphere(), screen=True)
        second = _run(store, TwoPartSphere(), screen=True)
        as_stored = [[(e.index, e.status, e.fitness, e.metrics) for e in store.evaluations(r)]
                     for r in (first.run_id, second.run_id)]  # fmt: skip
        assert as_stored[0] == as_stored[1]


def test_an_interrupted_screened_run_resumes_to_the_same_end(tmp_path):
    with RunStore(tmp_path / "runs.db") as store:
        whole = _run(store, TwoPartSphere(), screen=True)
        with pytest.raises(KeyboardInterrupt):
            _run(store, TwoPartSphere(interrupt_at=100), screen=True)
        stopped = store.runs()[-1]
        assert stopped.status == "interrupted"
        kept = [e.status for e in store.evaluations(stopped.id)]
        assert kept.count("ok") == 99  # every completed evaluation was stored as it finished
        resumed = resume(stopped.id, store, registry().optimizer("cmaes"), _info(TwoPartSphere()))
        assert resumed.best_fitness == whole.best_fitness
        assert (resumed.evaluations, resumed.screened) == (whole.evaluations, whole.screened)
        statuses = [[e.status for e in store.evaluations(r)] for r in (stopped.id, whole.run_id)]
        assert statuses[0] == statuses[1]  # the same candidates completed, none extra
        assert (store.run(stopped.id).checkpoint["state"]
                == store.run(whole.run_id).checkpoint["state"])  # fmt: skip


@pytest.mark.parametrize(
    ("fault", "status"), [(BrokenExecutor, "failed"), (KeyboardInterrupt, "interrupted")]
)
@pytest.mark.parametrize(
    ("together", "breaks_at", "completes", "stored_whole"),
    [
        # the first complete finishes, the second breaks, the third's submit raises
        (1, POPULATION + 1, 1, False),
        # the first and third finish, the second breaks, the fourth's submit raises
        (3, POPULATION + 1, 2, False),
        # all 16 of the first batch finish (two started ahead of its cut), the first screen of
        # the next breaks: the first batch is stored whole, not told
        (1, POPULATION + 16, 16, True),
    ],
)
def test_a_broken_or_interrupted_run_loses_no_complete_evaluation_that_finished(
    tmp_path, fault, status, together, breaks_at, completes, stored_whole
):
    """The complete evaluations that finished before the executor broke for good or Ctrl-C
    stopped the run are stored; its resume screens the batch again (the order needs every
    bound) but completes none of them again, keeps every row stored (one completed ahead of
    the cut too), and ends where the run never stopped does. Which ranked-out candidates were
    started ahead of the cut may differ (reused ones take no worker), unless the batch was
    stored whole: then every row is the unstopped run's."""
    with RunStore(tmp_path / "runs.db") as store:
        whole = _run(store, TwoPartSphere(), screen=True, executor=BreakingExecutor(4))
        breaking = BreakingExecutor(4, breaks_at, together, fault)
        with pytest.raises(fault):
            _run(store, TwoPartSphere(), screen=True, executor=breaking)
        stopped = store.runs()[-1]
        assert stopped.status == status
        completed = sorted(t.index for t in breaking.evaluated if t.phase == "complete")
        assert len(completed) == completes
        kept = {e.index: (e.status, e.fitness) for e in store.evaluations(stopped.id)}
        assert sorted(i for i, (state, _) in kept.items() if state != "screened") == completed
        again = BreakingExecutor(4)
        cmaes = registry().optimizer("cmaes")
        resumed = resume(stopped.id, store, cmaes, _info(TwoPartSphere()), executor=again)
        assert not {t.index for t in again.evaluated if t.phase == "complete"} & set(completed)
        rows = {e.index: (e.status, e.fitness) for e in store.evaluations(stopped.id)}
        assert {index: rows[index] for index in kept} == kept
        assert resumed.evaluations == whole.evaluations
        assert resumed.best_fitness == whole.best_fitness
        assert (store.run(stopped.id).checkpoint["state"]
                == store.run(whole.run_id).checkpoint["state"])  # fmt: skip
        if stored_whole:
            assert rows == {e.index: (e.status, e.fitness) for e in store.evaluations(whole.run_id)}
            assert resumed.screened == whole.screened


class FailsScreens(TwoPartSphere):
    """The screen fails for candidates far out in the first coordinate (a few of each
    batch); resumed with a plain TwoPartSphere, the failures were flaky: screened well."""

    def screen(self, x, seed):
        if x[0] > 0.5:
            raise ValueError("a screen that fails (a fault injected by a test)")
        return super().screen(x, seed)


@pytest.mark.parametrize("flaky", [False, True])
def test_a_resumed_batch_counts_a_failed_screen_once_and_never_completes_with_it(tmp_path, flaky):
    """A failed screen stored before Ctrl-C stopped the batch is screened again on resume:
    it is counted failed once (as in the run never stopped), and where the screen now
    succeeds, the stored failure is no complete result of the candidate."""
    with RunStore(tmp_path / "runs.db") as store:
        whole = _run(store, FailsScreens(), screen=True, executor=BreakingExecutor(4))
        breaking = BreakingExecutor(4, POPULATION + 1, 1, KeyboardInterrupt)
        with pytest.raises(KeyboardInterrupt):
            _run(store, FailsScreens(), screen=True, executor=breaking)
        stopped = store.runs()[-1]
        failed = [e.index for e in store.evaluations(stopped.id) if e.status == "failed"]
        assert failed and max(failed) < POPULATION  # failed screens of the stopped batch
        again = BreakingExecutor(4)
        problem = TwoPartSphere() if flaky else FailsScreens()
        cmaes = registry().optimizer("cmaes")
        resumed = resume(stopped.id, store, cmaes, _info(problem), executor=again)
        rows = {e.index: e for e in store.evaluations(stopped.id)}
        assert resumed.failed == sum(e.status == "failed" for e in rows.values())
        assert resumed.evaluations == whole.evaluations == len(rows)
        if flaky:  # every screen succeeds now: each candidate completed or told its bound
            assert resumed.failed == 0
            assert all(rows[i].status in ("ok", "screened") for i in failed)
        else:
            assert resumed.failed == whole.failed > 0
            assert resumed.best_fitness == whole.best_fitness


class BeatsItsScreen(TwoPartSphere):
    """A full fitness better than the screen's: the screen is no bound."""

    def complete(self, x, seed, screened):
        return Evaluation(screened.fitness - 1.0, {"part": 0.0})


def test_a_complete_kept_as_ctrl_c_stopped_the_run_is_checked_against_its_bound_on_resume(
    tmp_path,
):
    """Ctrl-C stores the completes that finished unchecked (the run stops at once); the resume
    (its problem's later completes sound) fails on reusing one that beats its screen, as the
    run would have on reading it."""
    with RunStore(tmp_path / "runs.db") as store:
        breaking = BreakingExecutor(4, POPULATION + 1, 3, KeyboardInterrupt)
        with pytest.raises(KeyboardInterrupt):
            _run(store, BeatsItsScreen(), screen=True, executor=breaking)
        stopped = store.runs()[-1]
        assert stopped.status == "interrupted"
        assert [e.status for e in store.evaluations(stopped.id)] == ["ok", "ok"]
        cmaes = registry().optimizer("cmaes")
        with pytest.raises(RunFailed, match=r"is better than its screen's .* no bound"):
            resume(stopped.id, store, cmaes, _info(TwoPartSphere()), executor=BreakingExecutor(4))
        assert store.run(stopped.id).status == "failed"


@pytest.mark.parametrize(
    ("optimizer", "settings", "says"),
    [
        ("hs", {}, "reads every candidate's fitness"),
        ("cmaes", {"batch": 5}, "leave --batch out or give 24"),
        ("cmaes", {"resample": 2}, "one evaluation per candidate"),
        ("cmaes", {"mode": "async"}, "in sync mode"),
    ],
)
def test_screening_refuses_what_it_cannot_rank(tmp_path, optimizer, settings, says):
    with RunStore(tmp_path / "runs.db") as store:
        with pytest.raises(ConfigError, match=says):
            _run(store, TwoPartSphere(), screen=True, optimizer=optimizer, **settings)
        assert not store.runs()


def test_the_cli_refuses_screening_a_problem_without_a_bound_in_one_line(tmp_path):
    db = str(tmp_path / "runs.db")
    for problem, setting in (("sphere", ()), ("nao-walk", ("--set", "backend=mujoco+ode"))):
        result = CliRunner().invoke(
            main, ["run", "-o", "cmaes", "-p", problem, "--screen", "--budget", "50", *setting,
                   "--db", db],
        )  # fmt: skip
        assert result.exit_code == 2, result.output
        assert "no cheaper bound to screen with" in result.output
        assert "Traceback" not in result.output and len(result.output.strip().splitlines()) == 1


WALK = {"backend": "mujoco+pybullet+ode", "controller": "balanced", "engine_score": "worst",
        "engine_cap": 6.0, "noise": 0.1, "fitness": "progress", "flight_penalty": 50.0,
        "worlds": "pushes", "duration": 10.0}  # fmt: skip


def test_nao_walk_screens_on_the_faster_engines_and_completes_to_its_full_evaluation():
    """The screen walks MuJoCo and ODE (not PyBullet); completing it gives evaluate's very
    Evaluation, and its fitness is never better than the screen's."""
    info = registry().problem("nao-walk")
    problem = info.factory(**info.checked_params(WALK))
    walking = info.stored_candidates()["balanced_walk"].x  # a gait that walks on all three
    falling = problem.space.sample(np.random.default_rng(3), 1)[0]
    try:
        assert problem.screens and problem.screen_engines == ("mujoco", "ode")
        for seed, x in enumerate((walking, falling)):
            full = problem.evaluate(x, seed)
            screened = problem.screen(x, seed)
            assert not any(name.endswith("@pybullet") for name in screened.metrics)
            assert screened.fitness >= full.fitness
            assert screened.fitness == min(screened.metrics["fitness@mujoco"],
                                           screened.metrics["fitness@ode"])  # fmt: skip
            completed = problem.complete(x, seed, screened)
            assert completed == full
    finally:
        problem.close()


@pytest.mark.parametrize(
    ("setting", "says"),
    [("screen_engines=mujoco+pybullet+ode", "not all of them"),
     ("screen_engines=bullet", "some of the backend's engines")],
)  # fmt: skip
def test_nao_walk_refuses_screen_engines_that_are_not_a_part_of_the_backend(setting, says):
    info = registry().problem("nao-walk")
    name, value = setting.split("=")
    with pytest.raises(ConfigError, match=says):
        info.checked_params({**WALK, name: value})


def test_a_screened_nao_walk_run_is_the_same_on_one_worker_and_two(tmp_path):
    """Where the cut falls depends on the scores alone: two workers (which complete a
    candidate ahead while the other is decided) tell CMA-ES what one worker does, and so does
    `metaopt compare` with the setting in an experiment file."""
    db = str(tmp_path / "runs.db")
    given = [arg for name, value in WALK.items() for arg in ("--set", f"{name}={value}")]
    for workers in ("1", "2"):
        result = CliRunner().invoke(
            main, ["run", "-o", "cmaes", "-p", "nao-walk", "--screen", "--budget", "24",
                   "--seed", "4", "--set", "population=8", *given, "--workers", workers,
                   "--db", db],
        )  # fmt: skip
        assert result.exit_code == 0, result.output
    # An experiment file's `settings = { screen = true }` is the same run (compare: serial).
    (tmp_path / "screened.toml").write_text(
        'problem = "nao-walk"\nseeds = [4]\n[problem_settings]\n'
        + "".join(f"{name} = {json.dumps(value)}\n" for name, value in WALK.items())
        + '[[optimizers]]\nname = "cmaes"\nbudget = 24\nparams = { population = 8 }\n'
        "settings = { screen = true }\n"
    )
    compared = CliRunner().invoke(main, ["compare", str(tmp_path / "screened.toml"), "--db", db])
    assert compared.exit_code == 0, compared.output
    with RunStore(db) as store:
        one, two, member = store.runs()
        assert one.checkpoint["state"] == two.checkpoint["state"] == member.checkpoint["state"]
        assert one.settings["screen"] and two.settings["screen"] and member.settings["screen"]
        rows = [{e.index: (e.status, e.fitness) for e in store.evaluations(run.id)}
                for run in (one, two, member)]  # fmt: skip
    assert rows[2] == rows[0]
    _assert_same_but_completed_ahead(serial=rows[0], parallel=rows[1])
    statuses = [status for status, _ in rows[0].values()]
    assert statuses.count("screened") > 0 and statuses.count("ok") >= 3 * 4


def _assert_same_but_completed_ahead(serial: dict, parallel: dict) -> None:
    """Rows of a serial and a parallel screened run, by index: the same candidates, the same
    fitness wherever both completed one; the parallel run may have completed some the serial
    one screened (a worker started them ahead of the cut), never the other way round."""
    assert serial.keys() == parallel.keys()
    assert {status for status, _ in serial.values()} <= {"ok", "screened"}
    for index, (status, fitness) in parallel.items():
        if status == "screened":
            assert serial[index][0] == "screened"
        elif serial[index][0] == "ok":
            assert fitness == serial[index][1]
        else:
            assert status == "ok"  # completed ahead of the cut


def test_show_and_history_count_screened_evaluations_apart_from_failed_ones(tmp_path):
    """A screened evaluation has no fitness but did not fail: the figures are the completed
    ones', and the screened are counted on their own."""
    db = tmp_path / "runs.db"
    with RunStore(db) as store:
        result = _run(store, TwoPartSphere(), screen=True, budget=POPULATION * 4)
        statuses = [e.status for e in store.evaluations(result.run_id)]
    screened, window = statuses.count("screened"), statuses[-POPULATION:].count("screened")
    assert 0 < window < POPULATION
    shown = CliRunner().invoke(main, ["show", str(result.run_id), "--recent", str(POPULATION),
                                      "--db", str(db)])  # fmt: skip
    assert shown.exit_code == 0, shown.output
    assert f"{window} screened, the figures are the other {POPULATION - window}" in shown.output
    assert "failed" not in shown.output.split("last")[-1]
    budget = POPULATION * 4
    assert f"{budget} of {budget} (0 failed, {screened} screened)" in shown.output
    for command in (["show", str(result.run_id)], ["runs"]):
        listed = CliRunner().invoke(main, [*command, "--format", "json", "--db", str(db)])
        assert listed.exit_code == 0, listed.output
        document = json.loads(listed.output)
        record = document[0] if isinstance(document, list) else document
        counts = (record["evaluations"], record["failed"], record["screened"])
        assert counts == (budget, 0, screened)
    table = CliRunner().invoke(main, ["runs", "--db", str(db)]).output.splitlines()
    header = next(line for line in table if line.split()[:2] == ["id", "optimizer"])
    (row,) = [line for line in table if line.split()[:1] == [str(result.run_id)]]
    assert header.split()[7:10] == ["evals", "failed", "screened"]
    assert row.split()[-7:-4] == [f"{budget}/{budget}", "0", str(screened)]
    history = CliRunner().invoke(main, ["history", str(result.run_id), "--window", "96",
                                        "--format", "json", "--db", str(db)])  # fmt: skip
    assert history.exit_code == 0, history.output
    (row,) = json.loads(history.output)
    assert (row["failed"], row["screened"]) == (0, screened)


def test_the_convergence_figure_counts_screened_evaluations_apart_from_failed_ones(tmp_path):
    with RunStore(tmp_path / "runs.db") as store:
        result = _run(store, TwoPartSphere(), screen=True, budget=POPULATION * 2)
        curves = run_convergence(store, store.run(result.run_id))
        figures = run_figures(store, result.run_id, registry())
    assert (curves.failed, curves.screened) == (0, result.screened) and result.screened > 0
    title = figures.figures["convergence"].axes[0].get_title()
    assert f"{result.screened} of {POPULATION * 2} evaluations screened" in title
    assert "failed" not in title


@pytest.mark.parametrize("executor", ["process", "dask"])
def test_a_screened_run_tells_the_same_on_worker_processes_and_dask(tmp_path, executor):
    """Screens and completes of one candidate are two tasks (on Dask two keys): on 2 local
    processes and a 2-worker LocalCluster the run tells CMA-ES what a serial one does."""
    plugins = registry()
    spec = RunSpec("cmaes", "nao-walk", 24, 9, optimizer_params={"population": 8},
                   problem_params={"duration": 3.0, "lock": 1.0, "backend": "mujoco+pybullet"},
                   settings=RunSettings(screen=True))  # fmt: skip
    states = []
    for pool in (None, plugins.executor(executor).factory(2, None)):
        with RunStore(tmp_path / f"{executor}-{pool is None}.db") as store:
            result = run(spec, plugins.optimizer("cmaes"), plugins.problem("nao-walk"), store,
                         None, pool)  # fmt: skip
            rows = {e.index: (e.status, e.fitness) for e in store.evaluations(result.run_id)}
            states.append((store.run(result.run_id).checkpoint["state"], rows))
    (serial_state, serial_rows), (state, rows) = states
    assert state == serial_state
    assert "screened" in {status for status, _ in serial_rows.values()}
    _assert_same_but_completed_ahead(serial_rows, rows)
