"""The run loop: seeding, storage, sense translation, failures and interruption."""

import json
import math
import time
from concurrent.futures import BrokenExecutor

import numpy as np
import pytest

from metaopt import ConfigError, Evaluation, Problem, ProblemInfo, Sense, Space
from metaopt.errors import RunFailed
from metaopt.plugins import registry
from metaopt.running import RunInterrupted, RunSettings, RunSpec, resume, run
from metaopt.seeding import EvaluationSeeds
from metaopt.storage.run_store import EvaluationCounts, RunStore
from tests.fixtures.breaking_executor import BreakingExecutor


def _stored(store: RunStore, run_id: int) -> list[tuple]:
    return [(e.index, e.x.tobytes(), e.fitness, e.seed) for e in store.evaluations(run_id)]


def _run(store, optimizer="hs", problem="sphere", budget=300, seed=1, **params):
    plugins = registry()
    spec = RunSpec(optimizer, problem, budget, seed, optimizer_params=params)
    return run(spec, plugins.optimizer(optimizer), plugins.problem(problem), store)


@pytest.mark.parametrize("optimizer", ["hs", "ga", "random"])
def test_same_seed_same_run_bit_for_bit_and_other_seeds_differ(tmp_path, optimizer):
    with RunStore(tmp_path / "runs.db") as store:
        first = _run(store, optimizer, seed=11)
        second = _run(store, optimizer, seed=11)
        third = _run(store, optimizer, seed=12)
        assert _stored(store, first.run_id) == _stored(store, second.run_id)
        assert len(_stored(store, first.run_id)) == 300
        assert _stored(store, first.run_id) != _stored(store, third.run_id)
        assert first.best_fitness == second.best_fitness


def test_every_evaluation_is_stored_with_the_run_record(tmp_path):
    with RunStore(tmp_path / "runs.db") as store:
        result = _run(store, budget=123, hmcr=0.8)
        record = store.run(result.run_id)
        assert record.status == "finished"
        assert record.optimizer_params["hmcr"] == 0.8
        assert record.optimizer_params["budget"] == 123  # schedules follow the run's budget
        assert record.problem_params == {"dim": 10}
        assert {"python", "numpy", "metaopt"} <= set(record.versions)
        assert record.ended_at is not None and record.wall_time > 0
        assert store.evaluation_counts(result.run_id) == EvaluationCounts(123, 0, 0)
        assert record.checkpoint["told_below"] == 123 and record.checkpoint["state"]
        assert record.settings["mode"] == "sync"
        fitnesses = [e.fitness for e in store.evaluations(result.run_id)]
        assert min(fitnesses) == result.best_fitness
        assert len({e.seed for e in store.evaluations(result.run_id)}) == 123


class Peak(Problem):
    """Maximize -(x - 0.7)^2; NaN for x < -0.5, an exception for x > 0.9, interrupt at x=stop."""

    sense = Sense.MAXIMIZE

    def __init__(self, interrupt_after: int = -1) -> None:
        self.space = Space.from_bounds([-1.0], [1.0])
        self.calls = 0
        self.interrupt_after = interrupt_after

    def evaluate(self, x, seed):
        self.calls += 1
        if self.calls == self.interrupt_after:
            raise KeyboardInterrupt
        if x[0] < -0.5:
            return Evaluation(float("nan"))
        if x[0] > 0.9:
            raise RuntimeError("simulation exploded")
        return Evaluation(-((x[0] - 0.7) ** 2), {"x": float(x[0])})


def _peak_info(**kwargs):
    return ProblemInfo("peak", "test peak", factory=lambda: Peak(**kwargs))


def test_maximize_failures_and_summary(tmp_path):
    with RunStore(tmp_path / "runs.db") as store:
        spec = RunSpec("hs", "peak", 400, 3)
        result = run(spec, registry().optimizer("hs"), _peak_info(), store)
        evaluations = list(store.evaluations(result.run_id))
        failed = [e for e in evaluations if e.status == "failed"]
        assert result.failed == len(failed) > 0
        assert {e.error for e in failed} >= {"fitness is nan", "RuntimeError: simulation exploded"}
        ok = [e.fitness for e in evaluations if e.status == "ok"]
        assert result.best_fitness == max(ok)  # maximized, not minimized
        # Minimizing would head for x = -0.5 (fitness -1.44); IHS's low early PAR wastes some
        # of 400 evaluations on one variable, so the peak is approached, not pinned.
        assert result.best_fitness > -1e-2 and abs(result.best_x[0] - 0.7) < 0.1


def test_interrupt_keeps_every_finished_evaluation(tmp_path):
    with RunStore(tmp_path / "runs.db") as store:
        spec = RunSpec("hs", "peak", 1000, 3)
        with pytest.raises(KeyboardInterrupt):
            run(spec, registry().optimizer("hs"), _peak_info(interrupt_after=251), store)
        record = store.runs()[-1]
        assert record.status == "interrupted"
        assert store.evaluation_counts(record.id).stored == 250


class SlowSphere(Problem):
    """The 2-D sphere at 2 ms an evaluation: a max time of tenths of a second stops it early."""

    def __init__(self) -> None:
        self.space = Space.from_bounds([-1.0, -1.0], [1.0, 1.0])

    def evaluate(self, x, seed):
        time.sleep(0.002)
        return Evaluation(float(np.sum(x**2)))


def test_a_run_stopped_at_its_max_time_resumes_with_more_time_to_the_unstopped_runs_end(tmp_path):
    """Stopped at its max time, a sync run's checkpoint is its last tell: resumed (with the
    stored max time, then with a new one, which is stored) it ends as the run never stopped."""
    info, ga = ProblemInfo("slow", "slow sphere", factory=SlowSphere), registry().optimizer("ga")
    with RunStore(tmp_path / "runs.db") as store:
        whole = run(RunSpec("ga", "slow", 400, 7), ga, info, store)
        limited = RunSpec("ga", "slow", 400, 7, settings=RunSettings(max_time=0.2))
        stopped = run(limited, ga, info, store)
        assert 0 < stopped.evaluations < 400
        assert store.run(stopped.run_id).message.startswith("stopped at its max time")
        first_session = store.run(stopped.run_id).wall_time
        assert first_session == pytest.approx(stopped.wall_time, abs=0.05)
        again = resume(stopped.run_id, store, ga, info)  # another 0.2 s
        assert stopped.evaluations < again.evaluations < 400
        done = resume(stopped.run_id, store, ga, info, max_time=60.0)
        record = store.run(stopped.run_id)
        # the stored wall time is the sum of the three sessions', each result its own session's
        total = first_session + again.wall_time + done.wall_time
        assert record.wall_time == pytest.approx(total, abs=0.05)
        assert (done.evaluations, record.status, record.message) == (400, "finished", None)
        assert record.settings["max_time"] == 60.0
        assert done.best_fitness == whole.best_fitness
        assert _stored(store, stopped.run_id) == _stored(store, whole.run_id)
        with pytest.raises(ConfigError, match="already finished; nothing to resume"):
            resume(stopped.run_id, store, ga, info, max_time=60.0)
        other = run(limited, ga, info, store)
        with pytest.raises(ConfigError, match="max time must be positive"):
            resume(other.run_id, store, ga, info, max_time=-1.0)
        assert store.run(other.run_id).settings["max_time"] == 0.2


def test_a_run_that_spent_its_budget_resumes_with_a_larger_one_to_the_larger_runs_end(tmp_path):
    """CMA-ES has no schedule over its budget: a run of 40 evaluations (five generations of 7
    and a short one of 5), resumed with a budget of 80, stores row for row what a run given 80
    at once does: the short batch's generation is completed before the next is asked."""
    plugins = registry()
    cmaes, sphere = plugins.optimizer("cmaes"), plugins.problem("sphere")
    with RunStore(tmp_path / "runs.db") as store:
        whole = run(RunSpec("cmaes", "sphere", 80, 5, problem_params={"dim": 3}), cmaes, sphere,
                    store)  # fmt: skip
        spent = run(RunSpec("cmaes", "sphere", 40, 5, problem_params={"dim": 3}), cmaes, sphere,
                    store)  # fmt: skip
        with pytest.raises(ConfigError, match="already finished; nothing to resume"):
            resume(spent.run_id, store, cmaes, sphere)
        with pytest.raises(ConfigError, match="more than the 40 evaluations run 2 has made"):
            resume(spent.run_id, store, cmaes, sphere, budget=40)
        assert store.run(spent.run_id).budget == 40  # a refused budget is not stored
        more = resume(spent.run_id, store, cmaes, sphere, budget=80)
        record = store.run(spent.run_id)
        assert (more.evaluations, record.budget, record.status) == (80, 80, "finished")
        assert _stored(store, spent.run_id) == _stored(store, whole.run_id)
        assert more.best_fitness == whole.best_fitness


def test_a_run_stored_before_a_parameter_existed_resumes_with_its_default(tmp_path):
    """The GA's eta_m_end and fine_share came after runs were stored: an interrupted run whose
    stored parameters lack them resumes with their defaults and ends as the run that never
    stopped (the factory demands every declared parameter)."""
    spec = RunSpec("ga", "sphere", 600, 4, optimizer_params={"mutation": "polynomial"},
                   problem_params={"dim": 3})  # fmt: skip
    plugins = registry()
    with RunStore(tmp_path / "runs.db") as store:
        whole = run(spec, plugins.optimizer("ga"), plugins.problem("sphere"), store)
        with pytest.raises(KeyboardInterrupt):
            run(spec, plugins.optimizer("ga"), _stopping_sphere(after=250), store)
        stopped = store.runs()[-1]
        params = {k: v for k, v in stopped.optimizer_params.items()
                  if k not in ("eta_m_end", "fine_share")}  # fmt: skip
        store._connection.execute(
            "UPDATE runs SET optimizer_params = ? WHERE id = ?", (json.dumps(params), stopped.id)
        )
        store._connection.commit()
        resumed = resume(stopped.id, store, plugins.optimizer("ga"), plugins.problem("sphere"))
        fitnesses = [[e.fitness for e in store.evaluations(r)] for r in (whole.run_id, stopped.id)]
    assert resumed.best_fitness == whole.best_fitness
    assert fitnesses[0] == fitnesses[1]


def _stopping_sphere(after: int) -> ProblemInfo:
    """The sphere plugin (dim 3) whose evaluation number ``after`` is a Ctrl-C."""
    sphere = registry().problem("sphere")

    def factory(**params):
        problem = sphere.factory(**params)
        evaluate, calls = problem.evaluate, [0]

        def stopping(x, seed):
            calls[0] += 1
            if calls[0] == after:
                raise KeyboardInterrupt
            return evaluate(x, seed)

        problem.evaluate = stopping
        return problem

    return ProblemInfo(sphere.name, sphere.description, factory=factory, params=sphere.params)


def test_a_stopped_run_resumes_with_a_budget_below_its_own_to_that_many_evaluations(tmp_path):
    """A run stopped early (here by Ctrl-C at evaluation 30 of 80) is given N more by a budget
    of its count plus N, below its stored budget: it ends there, row for row the first rows of
    the run that never stopped; a budget not above its count is refused and not stored."""
    spec = RunSpec("cmaes", "sphere", 80, 5, problem_params={"dim": 3})
    plugins = registry()
    cmaes = plugins.optimizer("cmaes")
    with RunStore(tmp_path / "runs.db") as store:
        whole = run(spec, cmaes, plugins.problem("sphere"), store)
        with pytest.raises(KeyboardInterrupt):
            run(spec, cmaes, _stopping_sphere(after=30), store)
        stopped = store.runs()[-1]
        made = store.evaluation_counts(stopped.id).stored
        assert 0 < made < 50
        with pytest.raises(ConfigError, match=f"more than the {made} evaluations run 2 has"):
            resume(stopped.id, store, cmaes, plugins.problem("sphere"), budget=made)
        assert store.run(stopped.id).budget == 80
        more = resume(stopped.id, store, cmaes, plugins.problem("sphere"), budget=50)
        record = store.run(stopped.id)
        assert (more.evaluations, record.budget, record.status) == (50, 50, "finished")
        assert _stored(store, stopped.id) == _stored(store, whole.run_id)[:50]


def test_bad_budget_and_parameters_are_config_errors(tmp_path):
    with RunStore(tmp_path / "runs.db") as store:
        with pytest.raises(ConfigError, match="budget must be a positive"):
            _run(store, budget=0)
        with pytest.raises(ConfigError, match=r"'hmcr' = 1\.5 is invalid"):
            _run(store, hmcr=1.5)
        assert store.runs() == []


def test_hs_finds_the_sphere_far_better_than_random(tmp_path):
    with RunStore(tmp_path / "runs.db") as store:
        hs = _run(store, "hs", budget=20_000, seed=5)
        ga = _run(store, "ga", budget=20_000, seed=5)
        rnd = _run(store, "random", budget=20_000, seed=5)
    assert hs.best_fitness < 1e-2 and ga.best_fitness < 1e-2
    assert rnd.best_fitness > 100 * max(hs.best_fitness, ga.best_fitness)
    assert np.all(np.abs(hs.best_x) < 0.1)


class EveryThirdFails(Problem):
    """Sphere in 1-D whose every third call fails: with --resample 3 no candidate is whole."""

    def __init__(self) -> None:
        self.space = Space.from_bounds([-1.0], [1.0])
        self.calls = 0

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        self.calls += 1
        if self.calls % 3 == 0:
            raise ValueError("every third call fails")
        return Evaluation(float(x[0] ** 2))


def test_a_run_without_one_whole_candidate_fails_and_says_why(tmp_path):
    plugins = registry()
    info = ProblemInfo("third", "fails every third call", factory=EveryThirdFails)
    spec = RunSpec("random", "third", 9, 1, settings=RunSettings(resample=3))
    with RunStore(tmp_path / "runs.db") as store:
        with pytest.raises(RunFailed, match="3 of 9 evaluations failed and in no candidate"):
            run(spec, plugins.optimizer("random"), info, store)
        record = store.runs()[0]
        assert record.status == "failed" and "every third call fails" in record.message


@pytest.mark.parametrize(
    ("fault", "raised", "says", "status", "message"),
    [
        (BrokenExecutor, BrokenExecutor, "broke at task {breaks_at} ", "failed",
         "BrokenExecutor: "),
        (KeyboardInterrupt, RunInterrupted, "interrupted with {stored} evaluations stored",
         "interrupted", "stopped by the user (Ctrl-C or SIGTERM)"),
    ],
    ids=["broken", "ctrl-c"],
)  # fmt: skip
@pytest.mark.parametrize(
    ("mode", "together", "breaks_at", "told"),
    [
        ("sync", 4, 6, 4),  # 4, 5 and 7 of the second batch finish, then 6 breaks the executor
        ("sync", 1, 5, 4),  # 4 finishes, 5 breaks, the submit of 6 raises
        ("async", 1, 6, 4),  # 0 to 3 are told, 4 and 5 finish, 6 breaks, the submit of 7 raises
        ("async", 3, 1, 0),  # 0 and 2 finish, 1 breaks, the submit of 3 raises
    ],
)
def test_a_broken_or_interrupted_run_loses_no_evaluation_that_finished(
    tmp_path, monkeypatch, fault, raised, says, status, message, mode, together, breaks_at, told
):
    """Every evaluation that finished before the executor broke for good or Ctrl-C stopped the
    run (from a future or from a later submit) is stored, not told: the last checkpoint (one
    after every tell) tells none of them; the resume evaluates none of them again and ends with
    the whole budget, a sync run's row for row as the run never stopped."""
    monkeypatch.setattr("metaopt.running.session.CHECKPOINT_INTERVAL", 0.0)
    plugins = registry()
    random, sphere = plugins.optimizer("random"), plugins.problem("sphere")
    spec = RunSpec("random", "sphere", 16, 3, optimizer_params={"batch_size": 4},
                   problem_params={"dim": 2}, settings=RunSettings(mode=mode))  # fmt: skip
    with RunStore(tmp_path / "runs.db") as store:
        whole = run(spec, random, sphere, store)
        breaking = BreakingExecutor(4, breaks_at, together, fault)
        with pytest.raises(raised) as stop:
            run(spec, random, sphere, store, executor=breaking)
        stopped = store.runs()[-1]
        assert stopped.status == status and stopped.message.startswith(message)
        finished = sorted(task.index for task in breaking.evaluated)
        assert breaks_at not in finished and len(finished) >= 1
        assert sorted(e.index for e in store.evaluations(stopped.id)) == finished
        assert says.format(breaks_at=breaks_at, stored=len(finished)) in str(stop.value)
        checkpoint = stopped.checkpoint or {"told_below": 0, "told_extra": []}
        assert (checkpoint["told_below"], checkpoint["told_extra"]) == (told, [])
        again = BreakingExecutor(4)
        resumed = resume(stopped.id, store, random, sphere, executor=again)
        assert not {task.index for task in again.evaluated} & set(finished)
        assert resumed.evaluations == len(finished) + len(again.evaluated) == 16
        assert store.run(stopped.id).status == "finished"
        if mode == "sync":
            assert _stored(store, stopped.id) == _stored(store, whole.run_id)


def test_a_second_ctrl_c_while_the_finished_are_stored_loses_the_rest_never_the_store(
    tmp_path, monkeypatch
):
    """Ctrl-C again while the evaluations that finished (0 and 2) are being stored, 0 stored
    already, loses 2 but not the store: the run is marked interrupted with 0 committed, and its
    resume evaluates every other one, to the whole budget; the message counts the one."""
    plugins = registry()
    random, sphere = plugins.optimizer("random"), plugins.problem("sphere")
    spec = RunSpec("random", "sphere", 16, 3, problem_params={"dim": 2},
                   settings=RunSettings(mode="async"))  # fmt: skip
    with RunStore(tmp_path / "runs.db") as store:
        add_evaluation = store.add_evaluation

        def second_ctrl_c(run_id: int, index: int, *rest: object) -> None:
            if index == 2:
                raise KeyboardInterrupt
            add_evaluation(run_id, index, *rest)

        monkeypatch.setattr(store, "add_evaluation", second_ctrl_c)
        stopping = BreakingExecutor(4, 1, 3, KeyboardInterrupt)  # 0 and 2 finish, 1 stops it
        with pytest.raises(RunInterrupted) as stop:
            run(spec, random, sphere, store, executor=stopping)
        monkeypatch.undo()
        (stopped,) = store.runs()
        assert stopped.status == "interrupted"
        assert [e.index for e in store.evaluations(stopped.id)] == [0]
        assert str(stop.value) == f"run {stopped.id} interrupted with 1 evaluations stored"
        again = BreakingExecutor(4)
        resumed = resume(stopped.id, store, random, sphere, executor=again)
        assert resumed.evaluations == 16
        assert sorted(task.index for task in again.evaluated) == list(range(1, 16))


class ShutdownInterrupted(BreakingExecutor):
    """Ctrl-C again as the executor shuts down (a pool may wait seconds for idle workers)."""

    def shutdown(self) -> None:
        raise KeyboardInterrupt


def test_a_second_ctrl_c_while_the_executor_shuts_down_still_marks_and_commits_the_run(
    tmp_path, monkeypatch
):
    """Ctrl-C (the second batch's 6) then Ctrl-C again in the executor's shutdown: the run is
    still marked interrupted, every evaluation that finished is committed (by the run's own
    flush: the store's flusher is put off here), and the run still ends in RunInterrupted (the
    CLI's resume line), not the second bare KeyboardInterrupt."""
    monkeypatch.setattr("metaopt.storage.run_store.FLUSH_INTERVAL", 3600.0)
    plugins = registry()
    spec = RunSpec("random", "sphere", 16, 3, optimizer_params={"batch_size": 4},
                   problem_params={"dim": 2})  # fmt: skip
    stopping = ShutdownInterrupted(4, 6, 4, KeyboardInterrupt)  # 4, 5 and 7 finish, 6 stops it
    with RunStore(tmp_path / "runs.db") as store:
        # Caught as KeyboardInterrupt so that a bare one fails here, not the whole pytest run.
        with pytest.raises(KeyboardInterrupt) as stop:
            run(spec, plugins.optimizer("random"), plugins.problem("sphere"), store,
                executor=stopping)  # fmt: skip
        (stopped,) = store.runs()
        assert stopped.status == "interrupted"
        assert [e.index for e in store.evaluations(stopped.id)] == [0, 1, 2, 3, 4, 5, 7]
        assert stop.type is RunInterrupted
        assert (stop.value.run_id, stop.value.stored) == (stopped.id, 7)


class Fails(Problem):
    """A 1-D problem whose every evaluation fails."""

    def __init__(self) -> None:
        self.space = Space.from_bounds([-1.0], [1.0])

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        raise ValueError("never evaluates")


def test_a_broken_executor_keeps_every_failure_that_finished_and_fails_as_broken(tmp_path):
    """Failures kept after the break pass the all-failed stop (ten) without stopping there: all
    eleven that finished are stored, and the run fails with the break, not as 'all failed'."""
    info = ProblemInfo("fails", "never evaluates", factory=Fails)
    spec = RunSpec("random", "fails", 24, 1, optimizer_params={"batch_size": 12})
    breaking = BreakingExecutor(12, breaks_at=3, together=12)
    with RunStore(tmp_path / "runs.db") as store:
        with pytest.raises(BrokenExecutor, match="broke at task 3 "):
            run(spec, registry().optimizer("random"), info, store, executor=breaking)
        (record,) = store.runs()
        assert record.status == "failed" and record.message.startswith("BrokenExecutor: ")
        assert store.evaluation_counts(record.id) == EvaluationCounts(11, 11, 0)


class SucceedsOn(Problem):
    """A 1-D problem whose evaluations all fail but those given one of ``seeds`` (chosen
    evaluations: a seed is the run seed's and the index's alone)."""

    def __init__(self, seeds: set[int]) -> None:
        self.space = Space.from_bounds([-1.0], [1.0])
        self.seeds = seeds

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        if seed not in self.seeds:
            raise ValueError("not a chosen evaluation")
        return Evaluation(float(x[0] ** 2))


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_the_all_failed_stop_keeps_the_other_evaluations_that_finished(tmp_path, mode):
    """The first ten evaluations fail and the two after them, finished with them, succeed: the
    run stops as all failed at the tenth yet stores all twelve, and its resume evaluates
    neither success again."""
    seeds = EvaluationSeeds(1)
    info = ProblemInfo("chosen", "succeeds on 10 and 11",
                       factory=lambda: SucceedsOn({seeds(10), seeds(11)}))  # fmt: skip
    spec = RunSpec("random", "chosen", 24, 1, optimizer_params={"batch_size": 12},
                   settings=RunSettings(mode=mode))  # fmt: skip
    random = registry().optimizer("random")
    with RunStore(tmp_path / "runs.db") as store:
        with pytest.raises(RunFailed, match=r"all 10 evaluations failed.*stopped early"):
            run(spec, random, info, store, executor=BreakingExecutor(12, together=12))
        (record,) = store.runs()
        assert record.status == "failed"
        assert store.evaluation_counts(record.id) == EvaluationCounts(12, 10, 0)
        again = BreakingExecutor(12, together=12)
        resumed = resume(record.id, store, random, info, executor=again)
        assert sorted(task.index for task in again.evaluated) == list(range(12, 24))
        assert (resumed.evaluations, resumed.failed) == (24, 22)


@pytest.mark.parametrize("checkpoints", [math.inf, 0.0], ids=["no-checkpoint", "every-tell"])
@pytest.mark.parametrize(
    ("resample", "workers", "together", "breaks_at", "start_points"),
    [
        (1, 4, 3, 1, 0),  # 0 and 2 finish, 1 breaks, the submit of 3 raises
        (1, 4, 3, 1, 4),  # the same, candidates 0 to 3 a warm start's points
        (2, 6, 6, (2, 3), 0),  # candidates 0 and 2 finish, both samples of 1 break
    ],
)
def test_a_resumed_async_run_asks_again_every_candidate_lost_in_flight(
    tmp_path, monkeypatch, checkpoints, resample, workers, together, breaks_at, start_points
):
    """A candidate in flight when the executor broke, below one that finished, is asked again
    on resume under its own number (its seeds, its warm start point): the run ends finished
    with its whole budget, every index once, all told, whether the last checkpoint came after
    the last tell or never; the same seed gives the same broken and resumed run."""
    monkeypatch.setattr("metaopt.running.session.CHECKPOINT_INTERVAL", checkpoints)
    plugins = registry()
    random, sphere = plugins.optimizer("random"), plugins.problem("sphere")
    start = [[0.5, 0.5]] if start_points else None
    settings = RunSettings(mode="async", resample=resample, start=start, start_points=start_points)
    spec = RunSpec("random", "sphere", 16, 3, problem_params={"dim": 2}, settings=settings)
    with RunStore(tmp_path / "runs.db") as store:
        whole = {e.index: e for e in store.evaluations(run(spec, random, sphere, store).run_id)}
        runs = []
        for _ in range(2):
            breaking = BreakingExecutor(workers, breaks_at, together)
            with pytest.raises(BrokenExecutor, match="broke at task "):
                run(spec, random, sphere, store, executor=breaking)
            broken = store.runs()[-1]
            finished = {task.index for task in breaking.evaluated}
            assert {i // resample for i in finished} == {0, 2}  # candidate 1 a gap
            again = BreakingExecutor(workers)
            resumed = resume(broken.id, store, random, sphere, executor=again)
            record = store.run(broken.id)
            assert (resumed.evaluations, record.status) == (16, "finished")
            asked = sorted(task.index for task in again.evaluated)
            assert asked == sorted(set(range(16)) - finished)
            assert (record.checkpoint["told_below"], record.checkpoint["told_extra"]) == (16, [])
            evaluations = list(store.evaluations(broken.id))
            assert [e.index for e in evaluations] == list(range(16))
            assert all(e.seed == whole[e.index].seed for e in evaluations)
            assert all(task.seed == whole[task.index].seed for task in again.evaluated)
            starts = [e for e in evaluations if e.candidate < start_points]
            assert all(np.array_equal(e.x, whole[e.index].x) for e in starts)  # the lost one's too
            runs.append(_stored(store, broken.id))
        assert runs[0] == runs[1]
