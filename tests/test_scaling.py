"""Executors, scheduling modes, resampling, resume and faults, on real processes and Dask."""

from __future__ import annotations

import builtins
import concurrent.futures
import contextlib
import errno
import gc
import os
import resource
import signal
import sqlite3
import subprocess
import sys
import threading
import time
import urllib.request
import warnings
from collections.abc import Iterator
from multiprocessing import resource_tracker
from pathlib import Path

import numpy as np
import pytest

from metaopt import Evaluation, Problem, Space
from metaopt.executors.base import EvaluationTask
from metaopt.executors.dask_cluster import PREFETCH
from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt.running import RunSettings, RunSpec, run
from metaopt.storage.run_store import RunStore
from tests.conftest import metaopt_cli

ALL = {"METAOPT_LOAD_PLUGINS": None}
#: How the process pool names the exit of a worker killed by SIGKILL (never "exit code None").
KILLED = f"(exit code {-signal.SIGKILL})"
#: A short nao-walk episode: real physics, a few milliseconds an evaluation.
SHORT_WALK = {"duration": 3.0, "lock": 1.0}


def _stored(db: Path, run_id: int = 1) -> list[tuple]:
    with RunStore(db) as store:
        return [
            (e.index, e.candidate, e.x.tobytes(), e.fitness, e.seed, e.status)
            for e in store.evaluations(run_id)
        ]


def _walk_run(db: Path, executor_name: str | None, settings: RunSettings, budget: int = 24):
    plugins = registry()
    spec = RunSpec("hs", "nao-walk", budget, 9, problem_params=SHORT_WALK, settings=settings)
    executor = None if executor_name is None else plugins.executor(executor_name).factory(2, None)
    with RunStore(db) as store:
        return run(
            spec, plugins.optimizer("hs"), plugins.problem("nao-walk"), store, None, executor
        )


def test_sync_runs_are_identical_on_every_executor(tmp_path):
    """Serially, on 2 local processes and on a 2-worker Dask LocalCluster: same evaluations."""
    settings = RunSettings(mode="sync", batch=4)
    results = {}
    for name in (None, "process", "dask"):
        db = tmp_path / f"{name}.db"
        results[name] = (_walk_run(db, name, settings), _stored(db))
    serial_result, serial_rows = results[None]
    assert len(serial_rows) == 24 and serial_result.status == "finished"
    for name in ("process", "dask"):
        result, rows = results[name]
        assert rows == serial_rows, f"{name} differs from the serial run"
        assert result.best_fitness == serial_result.best_fitness


def test_two_local_dask_clusters_at_once_each_serve_on_their_own_loopback_port():
    """Two runs on the dask executor at once (parallel tests, two users' runs): each local
    cluster's scheduler serves its pages on a free port of 127.0.0.1, not both on 8787 with
    a "Port 8787 is already in use" warning."""
    factory = registry().executor("dask").factory
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first, second = factory(1, None), factory(1, None)
        try:
            links = [executor.dashboard for executor in (first, second)]
            for link in links:  # each served while its cluster runs
                health = link.replace("/status", "/health")
                with urllib.request.urlopen(health, timeout=10) as answer:
                    assert answer.read() == b"ok"
        finally:
            first.shutdown()
            second.shutdown()
    assert not [w for w in caught if "already in use" in str(w.message)]
    assert all(link.startswith("http://127.0.0.1:") for link in links)
    assert links[0] != links[1]


def test_a_run_on_a_local_dask_cluster_says_where_its_dashboard_is(tmp_path):
    """The dashboard's port is a free one, different each run: the run names it on stderr,
    once, on loopback; a run on worker processes (no dashboard) says nothing of one."""
    common = ("run", "-o", "hs", "-p", "sphere", "--budget", "8", "--workers", "1")
    on_dask = metaopt_cli(*common, "--executor", "dask", "--db", "d.db", cwd=tmp_path, env=ALL)
    assert on_dask.returncode == 0, on_dask.stderr
    lines = [line for line in on_dask.stderr.splitlines() if "dashboard" in line]
    assert len(lines) == 1, on_dask.stderr
    assert lines[0].startswith("The dask executor's dashboard: http://127.0.0.1:")
    port = lines[0].split("127.0.0.1:")[1].split("/")[0]
    assert port.isdigit() and port != "8787"
    on_processes = metaopt_cli(*common, "--executor", "process", "--db", "p.db", cwd=tmp_path)
    assert on_processes.returncode == 0 and "dashboard" not in on_processes.stderr


def test_async_mode_keeps_workers_busy_and_spends_the_budget(tmp_path):
    result = _walk_run(tmp_path / "a.db", "process", RunSettings(mode="async"), budget=30)
    rows = _stored(tmp_path / "a.db")
    assert result.status == "finished" and len(rows) == 30
    assert sorted(r[0] for r in rows) == list(range(30))


def test_async_refuses_a_generational_optimizer(tmp_path):
    done = metaopt_cli("run", "-o", "ga", "-p", "sphere", "--mode", "async", "--workers", "2",
                       cwd=tmp_path)  # fmt: skip
    assert done.returncode == 2 and "cannot run in async mode" in done.stderr


def test_resampling_stores_every_sample_with_its_own_seed(tmp_path):
    done = metaopt_cli(
        "run", "-o", "random", "-p", "nao-walk", "--budget", "12", "--resample", "3",
        "--aggregate", "median", "--seed", "4", "--set", "duration=3", "--set", "lock=1",
        "--set", "noise=1", cwd=tmp_path,
    ) if "noise" in {p.name for p in registry().problem("nao-walk").params} else None  # fmt: skip
    if done is None:
        pytest.skip("nao-walk has no noise option yet")
    assert done.returncode == 0, done.stderr
    rows = _stored(tmp_path / "metaopt.db")
    assert len(rows) == 12
    by_candidate: dict[int, list[tuple]] = {}
    for row in rows:
        by_candidate.setdefault(row[1], []).append(row)
    assert sorted(by_candidate) == [0, 1, 2, 3]
    for samples in by_candidate.values():
        assert len({s[2] for s in samples}) == 1  # one candidate
        assert len({s[4] for s in samples}) == 3  # three seeds
    assert len({s[3] for s in by_candidate[0]}) > 1  # noise made the samples differ


def _count(db: Path) -> int:
    try:
        with sqlite3.connect(db, timeout=5) as connection:
            return connection.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0]
    except sqlite3.OperationalError:
        return 0


def _start_run(db: Path, cwd: Path, *extra: str) -> subprocess.Popen:
    command = [
        sys.executable, "-m", "metaopt", "run", "-o", "hs", "-p", "nao-walk", "--budget", "150",
        "--seed", "3", "--batch", "3", "--set", "duration=3", "--set", "lock=1", "--db", str(db),
        *extra,
    ]  # fmt: skip
    return subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _kill_when(process: subprocess.Popen, db: Path, stored: int, sig: int) -> None:
    deadline = time.monotonic() + 120
    while _count(db) < stored and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    process.send_signal(sig)
    process.wait(timeout=60)


def test_sigkill_at_any_point_then_resume_ends_like_an_uninterrupted_run(tmp_path):
    reference = tmp_path / "reference.db"
    assert _start_run(reference, tmp_path).wait(timeout=300) == 0
    expected = _stored(reference)
    assert len(expected) == 150
    interrupted_mid_run = 0
    for kill_at in (5, 60, 110):
        db = tmp_path / f"killed-{kill_at}.db"
        _kill_when(_start_run(db, tmp_path), db, kill_at, signal.SIGKILL)
        stored_before = _count(db)
        if stored_before < 150:  # the kill landed inside the run (a fast machine may finish)
            interrupted_mid_run += 1
            resumed = metaopt_cli("resume", "1", "--db", str(db), cwd=tmp_path)
            assert resumed.returncode == 0, resumed.stderr
        assert _stored(db) == expected, f"killed at {stored_before} stored evaluations"
    assert interrupted_mid_run >= 2


def test_sigterm_stops_cleanly_and_says_how_to_resume(tmp_path):
    db = tmp_path / "term.db"
    process = _start_run(db, tmp_path)
    _kill_when(process, db, 30, signal.SIGTERM)
    stderr = process.stderr.read().decode()
    assert process.returncode == 130, stderr
    assert f"Resume with: metaopt resume 1 --db {db}" in stderr
    assert "Traceback" not in stderr
    with RunStore(db) as store:
        assert store.run(1).status == "interrupted"
        stored = store.evaluation_counts(1).stored
    assert 30 <= stored < 150
    assert metaopt_cli("resume", "1", "--db", str(db), cwd=tmp_path).returncode == 0
    with RunStore(db) as store:
        assert store.run(1).status == "finished" and store.evaluation_counts(1).stored == 150


@pytest.mark.parametrize("executor", ["process", "dask"])
def test_a_worker_that_dies_is_replaced_and_its_candidate_failed(
    tmp_path, outside_plugin_path, executor
):
    """The bowl kills its own process for x0 < -2: retried once, then stored as failed."""
    done = metaopt_cli(
        "run", "-o", "random", "-p", "bowl", "--budget", "40", "--seed", "1",
        "--executor", executor, "--workers", "2", "--set", "die_below=2",
        cwd=tmp_path, extra_path=outside_plugin_path, env=ALL,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    rows = _stored(tmp_path / "metaopt.db")
    assert len(rows) == 40
    with RunStore(tmp_path / "metaopt.db") as store:
        evaluations = list(store.evaluations(1))
    deadly = [e for e in evaluations if e.x[0] < -2]
    assert deadly and all(e.status == "failed" for e in deadly)
    assert all(e.status == "ok" for e in evaluations if e.x[0] >= -2)
    marker = (
        f"died twice on this candidate {KILLED}" if executor == "process" else "Dask task failed"
    )
    assert all(marker in e.error for e in deadly)


@pytest.mark.parametrize("executor", [None, "process"])
def test_an_evaluation_past_its_time_limit_is_stopped_and_failed(
    tmp_path, outside_plugin_path, executor
):
    choice = [] if executor is None else ["--executor", executor, "--workers", "2"]
    start = time.monotonic()
    done = metaopt_cli(
        "run", "-o", "random", "-p", "bowl", "--budget", "20", "--seed", "1",
        "--set", "batch_size=4", "--set", "stall_below=2.5", "--time-limit", "0.5", *choice,
        cwd=tmp_path, extra_path=outside_plugin_path, env=ALL,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert time.monotonic() - start < 25  # nobody waited out a 30 s stall
    with RunStore(tmp_path / "metaopt.db") as store:
        evaluations = list(store.evaluations(1))
    stalled = [e for e in evaluations if e.x[0] < -2.5]
    assert stalled and all("time limit" in e.error for e in stalled)


def test_two_runs_writing_one_database_at_once_both_complete(tmp_path):
    db = tmp_path / "shared.db"
    processes = [_start_run(db, tmp_path, "--seed", str(seed)) for seed in (1, 2)]
    assert [p.wait(timeout=300) for p in processes] == [0, 0]
    with RunStore(db) as store:
        assert [r.status for r in store.runs()] == ["finished", "finished"]
        assert [store.evaluation_counts(r.id).stored for r in store.runs()] == [150, 150]


def test_unknown_executor_and_misplaced_scheduler(tmp_path):
    done = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--executor", "ray", cwd=tmp_path)
    assert done.returncode == 2 and "unknown executor 'ray'" in done.stderr
    done = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--executor", "process",
                       "--scheduler", "tcp://127.0.0.1:1", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 2 and "--scheduler is for the dask executor" in done.stderr
    assert not os.path.exists(tmp_path / "metaopt.db") or _count(tmp_path / "metaopt.db") == 0


def _free_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_joining_an_existing_dask_cluster_on_loopback(tmp_path):
    """`dask scheduler` and `dask worker` started by hand; --scheduler joins them."""
    address = f"tcp://127.0.0.1:{_free_port()}"
    port = address.rsplit(":", 1)[1]
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen(
        [*dask, "--host", "127.0.0.1", "--port", port, "--dashboard-address", ":0"], **quiet
    )
    worker = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2",
         "--nthreads", "1", "--no-dashboard"], **quiet,
    )  # fmt: skip
    try:
        common = [
            "run",
            "-o",
            "hs",
            "-p",
            "sphere",
            "--budget",
            "40",
            "--seed",
            "6",
            "--batch",
            "4",
        ]
        joined = metaopt_cli(*common, "--scheduler", address, "--db", "dask.db", cwd=tmp_path)
        assert joined.returncode == 0, joined.stderr
        serial = metaopt_cli(*common, "--db", "serial.db", cwd=tmp_path)
        assert serial.returncode == 0, serial.stderr
        assert _stored(tmp_path / "dask.db") == _stored(tmp_path / "serial.db")
    finally:
        for process in (worker, scheduler):
            process.terminate()
            process.wait(timeout=30)


def test_an_unreachable_scheduler_is_one_clear_error(tmp_path):
    address = f"tcp://127.0.0.1:{_free_port()}"
    done = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--scheduler", address, cwd=tmp_path)
    assert done.returncode == 2
    assert f"cannot reach the Dask scheduler at {address}" in done.stderr
    assert "Traceback" not in done.stderr


def _sphere_tasks(count: int, time_limit: float | None) -> list[EvaluationTask]:
    """count evaluations of the 2-D sphere (microseconds each), with this time limit."""
    info = registry().problem("sphere")
    params = resolve(info.params, {}, "sphere")
    return [
        EvaluationTask(i, np.full(2, i / count), i, info.factory, params, time_limit=time_limit)
        for i in range(count)
    ]


def _timer_threads() -> int:
    return sum(isinstance(thread, threading.Timer) for thread in threading.enumerate())


def test_dask_time_limits_leave_no_timer_behind_a_settled_evaluation():
    """Each evaluation's time-limit timer goes when it settles: fast evaluations under a long
    limit do not pile up a sleeping thread each until the run ends."""
    executor = registry().executor("dask").factory(2, None)
    try:
        before = _timer_threads()
        futures = [executor.submit(task) for task in _sphere_tasks(200, time_limit=60.0)]
        outcomes = [future.result(timeout=120) for future in futures]
        assert all(outcome.error is None for outcome in outcomes)
        deadline = time.monotonic() + 10  # a cancelled timer's thread ends at once
        while time.monotonic() < deadline and _timer_threads() > before:
            time.sleep(0.05)
        assert _timer_threads() <= before  # none left by this run (another's may end)
    finally:
        executor.shutdown()
    executor.shutdown()  # the run's, then its caller's: the second does nothing


def test_process_workers_shut_down_leave_no_pipe_open():
    """Shutting the worker processes down closes every pipe to them (and the manager's wake
    pipe), not only those of workers it had to kill; a second shutdown does nothing."""
    executor = registry().executor("process").factory(2, None)
    futures = [executor.submit(task) for task in _sphere_tasks(4, time_limit=None)]
    assert all(future.result(timeout=120).error is None for future in futures)
    pipes = [executor._wake_reader, executor._wake_writer]
    pipes += [worker.connection for worker in executor._pool]
    executor.shutdown()
    executor.shutdown()
    assert len(pipes) == 4 and all(pipe.closed for pipe in pipes)


def _kill_own_process() -> None:
    """A problem factory whose set-up kills the worker process that runs it."""
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_worker_process_replaced_mid_run_is_closed():
    """A worker that dies under its task is replaced, and the Process object of the dead one
    is closed (its resources released), not left for the garbage collector."""
    executor = registry().executor("process").factory(1, None)
    try:
        (first,) = [worker.process for worker in executor._pool]
        task = EvaluationTask(0, np.zeros(2), 0, _kill_own_process, {})
        outcome = executor.submit(task).result(timeout=120)
        assert f"died twice on this candidate {KILLED}" in outcome.error
        with pytest.raises(ValueError, match="closed"):
            first.is_alive()
        assert executor._pool[0].process.is_alive()  # its replacement
    finally:
        executor.shutdown()


def _note_then_kill_own_process(path: str) -> None:
    """A problem factory that notes one try in the file at path, then kills its worker."""
    with open(path, "a") as tries:
        tries.write("try\n")
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_worker_that_died_idle_is_replaced_when_given_a_task(tmp_path):
    """A worker killed while idle (kill -9, the OOM killer) is replaced when it is given a
    task, which goes to a live worker with its attempt unspent (a task that kills its worker
    still gets its two tries), and the pool serves on: nothing waits for ever."""
    executor = registry().executor("process").factory(1, None)
    try:
        (warm_up,) = _sphere_tasks(1, time_limit=None)
        assert executor.submit(warm_up).result(timeout=120).error is None
        (idle,) = [worker.process for worker in executor._pool]
        os.kill(idle.pid, signal.SIGKILL)
        os.waitid(os.P_PID, idle.pid, os.WEXITED | os.WNOWAIT)  # gone, not yet reaped
        tries = tmp_path / "tries"
        deadly = EvaluationTask(
            9, np.zeros(2), 0, _note_then_kill_own_process, {"path": str(tries)}
        )
        tasks = [deadly, *_sphere_tasks(3, time_limit=None)]
        futures = [executor.submit(task) for task in tasks]
        outcomes = [future.result(timeout=60) for future in futures]
        assert f"died twice on this candidate {KILLED}" in outcomes[0].error
        assert tries.read_text().count("try") == 2
        assert [outcome.error for outcome in outcomes[1:]] == [None, None, None]
        with pytest.raises(ValueError, match="closed"):
            idle.is_alive()  # the dead worker was replaced, its Process closed
    finally:
        executor.shutdown()


def test_workers_that_die_as_they_start_fail_the_task_instead_of_starting_for_ever(monkeypatch):
    """A worker found dead before it ever answered (it died as it started) costs the task an
    attempt: two such deaths fail it, 'died twice', and the pool starts no third worker."""
    from metaopt.executors import process_pool

    send = process_pool._Worker.start
    killed: list[int] = []

    def die_before_answering(worker, job) -> None:
        if not worker.answered:  # the real process, really killed, before the task reaches it
            worker.process.kill()
            os.waitid(os.P_PID, worker.process.pid, os.WEXITED | os.WNOWAIT)
            killed.append(worker.process.pid)
        send(worker, job)

    monkeypatch.setattr(process_pool._Worker, "start", die_before_answering)
    executor = registry().executor("process").factory(1, None)
    try:
        (task,) = _sphere_tasks(1, time_limit=None)
        outcome = executor.submit(task).result(timeout=60)
        assert f"died twice on this candidate {KILLED}" in outcome.error
        assert len(killed) == 2
    finally:
        executor.shutdown()


class _Marks(Problem):
    """A 2-D problem whose evaluation leaves a file named by its seed in folder, after
    sleeping seconds: which tasks ran can be read back from the folder."""

    def __init__(self, folder: str, seconds: float = 0.0) -> None:
        self.space = Space.from_bounds([-1.0, -1.0], [1.0, 1.0])
        self.folder, self.seconds = Path(folder), seconds

    def evaluate(self, x, seed):
        time.sleep(self.seconds)
        (self.folder / str(seed)).touch()
        return Evaluation(float(np.sum(x**2)))


def test_a_future_its_caller_cancelled_is_passed_over_and_the_pool_serves_on(tmp_path):
    """Cancelling a waiting task leaves the pool serving: the task never runs, and the next
    tasks complete."""
    executor = registry().executor("process").factory(1, None)
    try:
        params = {"folder": str(tmp_path)}
        first = EvaluationTask(0, np.zeros(2), 0, _Marks, {**params, "seconds": 0.5})
        tasks = [EvaluationTask(i, np.zeros(2), i, _Marks, params) for i in (1, 2, 3)]
        first, cancelled, *later = (executor.submit(task) for task in [first, *tasks])
        assert cancelled.cancel()  # waiting: the one worker is busy with the first
        assert first.result(timeout=60).error is None
        assert [future.result(timeout=60).error for future in later] == [None, None]
        (after,) = _sphere_tasks(1, time_limit=None)
        assert executor.submit(after).result(timeout=60).error is None
        assert sorted(path.name for path in tmp_path.iterdir()) == ["0", "2", "3"]
    finally:
        executor.shutdown()


class _RefusesPickling:
    """A problem parameter that cannot be sent to a worker process."""

    def __reduce__(self) -> tuple:
        raise TypeError("a _RefusesPickling refuses to be pickled")


def test_a_task_that_does_not_pickle_fails_alone_and_the_pool_serves_on():
    """A task that cannot be sent to a worker (a lambda in it, an object refusing to pickle)
    fails at once with the reason, and the same worker, its pipe intact, serves the rest."""
    executor = registry().executor("process").factory(1, None)
    try:
        (worker,) = [worker.process for worker in executor._pool]
        sphere = registry().problem("sphere").factory
        local = EvaluationTask(7, np.zeros(2), 0, lambda **params: sphere(**params), {})
        refusing = EvaluationTask(8, np.zeros(2), 0, sphere, {"dim": _RefusesPickling()})
        tasks = [local, refusing, *_sphere_tasks(3, time_limit=None)]
        outcomes = [executor.submit(task).result(timeout=60) for task in tasks]
        assert "cannot be sent to a worker process" in outcomes[0].error
        assert "local object" in outcomes[0].error and "<lambda>" in outcomes[0].error
        assert "refuses to be pickled" in outcomes[1].error
        assert [outcome.error for outcome in outcomes[2:]] == [None, None, None]
        assert executor._pool[0].process is worker and worker.is_alive()  # never replaced
    finally:
        executor.shutdown()


@contextlib.contextmanager
def _no_descriptor_left_open() -> Iterator[None]:
    """Asserts that the block leaves open no file descriptor of this process that was not open
    before it (a pool's pipes, its workers' Process sentinels)."""
    resource_tracker.ensure_running()  # the first spawned process starts it, open for good
    gc.collect()  # an earlier test's garbage closing its descriptors meanwhile would mislead
    descriptors = set(os.listdir("/dev/fd"))
    yield
    gc.collect()
    assert set(os.listdir("/dev/fd")) <= descriptors  # none opened and left open


def test_a_replacement_worker_that_cannot_start_fails_every_task_instead_of_hanging():
    """No file descriptor left when a dead worker is replaced: every task waiting or running
    fails at once with BrokenExecutor naming the error, and so do later submits (the error
    ended the manager thread and left them waiting for ever); shutdown still stops every
    worker, and no descriptor is left open, nor the pipe of the worker that could not start."""
    with _no_descriptor_left_open():
        executor = registry().executor("process").factory(2, None)
        processes = [worker.process for worker in executor._pool]
        try:
            warm_up = _sphere_tasks(2, time_limit=None)
            assert all(executor.submit(t).result(timeout=120).error is None for t in warm_up)
            deadly = EvaluationTask(9, np.zeros(2), 0, _kill_own_process, {})
            soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
            lowest_free = os.open(os.devnull, os.O_RDONLY)
            os.close(lowest_free)
            resource.setrlimit(resource.RLIMIT_NOFILE, (lowest_free, hard))  # no new descriptor
            try:
                futures = [executor.submit(t) for t in [deadly, *_sphere_tasks(3, time_limit=None)]]
                _, waiting = concurrent.futures.wait(futures, timeout=30)
            finally:
                resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
            assert not waiting
            broken = "the process pool stopped: its manager thread failed with OSError"
            with pytest.raises(concurrent.futures.BrokenExecutor, match=broken):
                futures[0].result()
            for future in futures[1:]:  # finished before the failure, or failed by it
                assert future.exception() is None or broken in str(future.exception())
            with pytest.raises(concurrent.futures.BrokenExecutor, match=broken):
                executor.submit(warm_up[0])
        finally:
            executor.shutdown()
    for process in processes:
        with pytest.raises(ValueError, match="closed"):
            process.is_alive()  # stopped, and its Process closed


def test_a_pool_whose_worker_cannot_start_stops_the_workers_started_before_it(monkeypatch):
    """A worker that cannot start (no file descriptor left) fails the pool's construction with
    its error, and the workers started before it are stopped, joined and closed first, their
    pipes too: no process is left running, no descriptor open."""
    from metaopt.executors import process_pool

    start = process_pool._Worker.__init__
    started: list[process_pool._Worker] = []

    def third_cannot_start(worker, context) -> None:
        if len(started) == 2:
            raise OSError(errno.EMFILE, "Too many open files")
        start(worker, context)
        started.append(worker)

    monkeypatch.setattr(process_pool._Worker, "__init__", third_cannot_start)
    with _no_descriptor_left_open(), pytest.raises(OSError, match="Too many open files"):
        registry().executor("process").factory(3, None)
    assert len(started) == 2 and all(worker.connection.closed for worker in started)
    for worker in started:
        with pytest.raises(ValueError, match="closed"):
            worker.process.is_alive()  # stopped, joined, and its Process closed


class _Sleeps(Problem):
    """A 2-D problem whose evaluation sleeps this long: its worker stays busy until stopped."""

    def __init__(self, seconds: float) -> None:
        self.space = Space.from_bounds([-1.0, -1.0], [1.0, 1.0])
        self.seconds = seconds

    def evaluate(self, x, seed):
        time.sleep(self.seconds)
        return Evaluation(float(np.sum(x**2)))


def _sleeping_tasks(count: int) -> list[EvaluationTask]:
    """count evaluations that each sleep a minute (far longer than any test waits)."""
    return [EvaluationTask(i, np.zeros(2), i, _Sleeps, {"seconds": 60.0}) for i in range(count)]


def _wait_until_all_busy(executor) -> None:
    """Wait until every worker has reported that its task's evaluation began."""
    deadline = time.monotonic() + 60
    while not all(worker.started is not None for worker in executor._pool):
        assert time.monotonic() < deadline, "the workers never started their tasks"
        time.sleep(0.05)


def _waiting_thread(future: concurrent.futures.Future, returned: list) -> threading.Thread:
    """A thread blocked in concurrent.futures.wait() on the future, which appends what wait()
    returns to returned once woken: started, and blocked, when this returns."""
    waiter = threading.Thread(
        target=lambda: returned.append(concurrent.futures.wait([future])), daemon=True
    )
    waiter.start()
    deadline = time.monotonic() + 30
    while not future._waiters:  # blocked in wait(), not about to begin
        assert time.monotonic() < deadline, "the caller never began to wait"
        time.sleep(0.01)
    return waiter


def test_shutdown_cancels_unsettled_tasks_and_a_later_submit_raises():
    """Shutting down cancels every unsettled task, the one waiting and the one running (its
    worker is stopped, its outcome will never come), so no caller waits for ever; a submit
    after shutdown raises RuntimeError, as concurrent.futures does, instead of queuing a task
    that never runs."""
    executor = registry().executor("process").factory(1, None)
    try:
        running, waiting = (executor.submit(task) for task in _sleeping_tasks(2))
        _wait_until_all_busy(executor)
    finally:
        executor.shutdown()
    assert running.cancelled() and waiting.cancelled()
    with pytest.raises(concurrent.futures.CancelledError):
        running.result(timeout=5)
    (later,) = _sphere_tasks(1, time_limit=None)
    with pytest.raises(RuntimeError, match="cannot submit after shutdown"):
        executor.submit(later)


def test_shutdown_stops_busy_workers_at_once_not_one_wait_each():
    """Busy workers are terminated at shutdown, not each waited for in turn: two workers deep
    in long evaluations are stopped well within a second and a half, every Process closed."""
    executor = registry().executor("process").factory(2, None)
    processes = [worker.process for worker in executor._pool]
    try:
        futures = [executor.submit(task) for task in _sleeping_tasks(2)]
        _wait_until_all_busy(executor)
    finally:
        start = time.monotonic()
        executor.shutdown()
        took = time.monotonic() - start
    assert took < 1.5, f"shutdown took {took:.1f} s"
    assert all(future.cancelled() for future in futures)
    for process in processes:
        with pytest.raises(ValueError, match="closed"):
            process.is_alive()


def test_shutdown_wakes_a_caller_blocked_in_wait_on_a_task_it_cancels():
    """A caller blocked in concurrent.futures.wait() on a running task returns once shutdown
    cancels it, the task done and cancelled: a bare cancel() left the future CANCELLED, never
    notified, and wait() blocked for ever."""
    executor = registry().executor("process").factory(1, None)
    returned: list[tuple[set, set]] = []
    try:
        running, _ = (executor.submit(task) for task in _sleeping_tasks(2))
        _wait_until_all_busy(executor)
        waiter = _waiting_thread(running, returned)  # blocked before shutdown cancels the task
    finally:
        executor.shutdown()
    waiter.join(timeout=30)
    assert not waiter.is_alive(), "wait() was never woken"
    assert returned == [({running}, set())] and running.cancelled()


@pytest.mark.parametrize("executor_name", ["process", "dask"])
def test_a_caller_blocked_in_wait_on_a_task_its_caller_cancels_is_woken_at_once(executor_name):
    """A thread blocked in concurrent.futures.wait() on a task its caller then cancels, one
    waiting in line or one running (handed to Dask), returns at once, with no shutdown: the
    executor passed a cancelled task over (or dropped its outcome) without notifying it, so
    wait() blocked for ever, here behind a worker busy for a minute."""
    executor = registry().executor(executor_name).factory(1, None)
    try:
        if executor_name == "process":
            running, queued = (executor.submit(task) for task in _sleeping_tasks(2))
            _wait_until_all_busy(executor)
        else:  # the first PREFETCH are handed to Dask, the last waits here
            futures = [executor.submit(task) for task in _sleeping_tasks(PREFETCH + 1)]
            deadline = time.monotonic() + 60
            while executor._running < PREFETCH:
                assert time.monotonic() < deadline, "the tasks were never handed to Dask"
                time.sleep(0.05)
            running, queued = futures[0], futures[-1]
        returned: dict[concurrent.futures.Future, list] = {running: [], queued: []}
        waiters = [_waiting_thread(future, returned[future]) for future in returned]
        assert queued.cancel() and running.cancel()
        deadline = time.monotonic() + 30  # generous: a loaded 2-core machine
        for waiter in waiters:
            waiter.join(timeout=max(0.0, deadline - time.monotonic()))
        assert not any(waiter.is_alive() for waiter in waiters), "wait() was not woken"
        assert returned == {running: [({running}, set())], queued: [({queued}, set())]}
    finally:
        executor.shutdown()


def test_an_interrupt_mid_shutdown_still_stops_every_worker_and_cancels_every_task():
    """A second Ctrl-C as shutdown waits for the first worker to end still leaves every worker
    killed, every pipe and Process closed, no descriptor open and every task cancelled (it cut
    the teardown short: the other workers ran on, their callers waiting for ever)."""
    with _no_descriptor_left_open():
        executor = registry().executor("process").factory(2, None)
        workers = list(executor._pool)
        pipes = [executor._wake_reader, executor._wake_writer]
        pipes += [worker.connection for worker in workers]
        futures = [executor.submit(task) for task in _sleeping_tasks(3)]
        _wait_until_all_busy(executor)
        first, join = workers[0].process, workers[0].process.join
        joins: list[float | None] = []

        def interrupted_once(timeout: float | None = None) -> None:
            joins.append(timeout)
            if len(joins) == 1:
                raise KeyboardInterrupt
            join(timeout)

        first.join = interrupted_once
        with pytest.raises(KeyboardInterrupt):
            executor.shutdown()
        assert len(joins) == 2  # interrupted, then joined again as it was killed
        assert all(future.cancelled() for future in futures)
        assert len(pipes) == 4 and all(pipe.closed for pipe in pipes)
        for worker in workers:
            with pytest.raises(ValueError, match="closed"):
                worker.process.is_alive()  # killed, joined, and its Process closed


def test_dask_shutdown_cancels_every_unsettled_task_and_wakes_its_waiters():
    """Shutting the Dask executor down cancels every unsettled task, one waiting here and one
    handed to Dask alike, and a caller blocked in concurrent.futures.wait() on either returns:
    a bare cancel() left the waiting one CANCELLED, never notified, so wait() blocked for ever,
    and one handed to Dask was not cancelled at all (the client's close cut its attempt short,
    which queued it again, for a dispatcher that had stopped). A later submit raises
    RuntimeError, as the Executor contract says, instead of queuing a task no dispatcher hands
    over, its future never settling."""
    executor = registry().executor("dask").factory(1, None)
    try:
        futures = [executor.submit(task) for task in _sleeping_tasks(PREFETCH + 1)]
        deadline = time.monotonic() + 60
        while executor._running < PREFETCH:  # the first ones handed over, the last waits here
            assert time.monotonic() < deadline, "the tasks were never handed to Dask"
            time.sleep(0.05)
        handed, waiting = futures[0], futures[-1]
        returned: dict[concurrent.futures.Future, list] = {handed: [], waiting: []}
        waiters = [_waiting_thread(future, returned[future]) for future in returned]
    finally:
        executor.shutdown()
    deadline = time.monotonic() + 30
    for waiter in waiters:
        waiter.join(timeout=max(0.0, deadline - time.monotonic()))
    assert not any(waiter.is_alive() for waiter in waiters), "wait() was never woken"
    assert returned == {handed: [({handed}, set())], waiting: [({waiting}, set())]}
    assert all(future.cancelled() for future in futures)
    (later,) = _sphere_tasks(1, time_limit=None)  # no dispatcher would hand it over
    with pytest.raises(RuntimeError, match="cannot submit after shutdown"):
        executor.submit(later)


class _UnpicklableMetric(Problem):
    """A 2-D problem whose evaluation returns a metric that refuses to be pickled."""

    def __init__(self) -> None:
        self.space = Space.from_bounds([-1.0, -1.0], [1.0, 1.0])

    def evaluate(self, x, seed):
        return Evaluation(0.0, {"odd": _RefusesPickling()})


def test_an_outcome_that_does_not_pickle_fails_alone_and_the_worker_serves_on():
    """An evaluation whose outcome cannot be sent back fails its task at once, saying why in
    one line, instead of crashing its worker twice; the same worker serves the rest."""
    executor = registry().executor("process").factory(1, None)
    try:
        (worker,) = [worker.process for worker in executor._pool]
        odd = EvaluationTask(5, np.zeros(2), 0, _UnpicklableMetric, {})
        tasks = [odd, *_sphere_tasks(2, time_limit=None)]
        outcomes = [executor.submit(task).result(timeout=60) for task in tasks]
        assert outcomes[0].index == 5 and outcomes[0].fitness is None
        refused = "TypeError: a _RefusesPickling refuses to be pickled"
        assert outcomes[0].error == f"the outcome could not be sent back: {refused}"
        assert [outcome.error for outcome in outcomes[1:]] == [None, None]
        assert executor._pool[0].process is worker and worker.is_alive()  # never replaced
    finally:
        executor.shutdown()


def _refuse_unpickling(error: str) -> None:
    """What a _RefusesUnpickling's pickle calls when loaded: it raises the built-in error."""
    raise getattr(builtins, error)("a _RefusesUnpickling refuses to be unpickled")


class _RefusesUnpickling:
    """A metric value that pickles in the worker but raises when the parent unpickles it."""

    def __init__(self, error: str) -> None:
        self.error = error

    def __reduce__(self) -> tuple:
        return _refuse_unpickling, (self.error,)


class _UnreadableMetric(Problem):
    """A 2-D problem whose evaluation returns a metric that pickles but cannot be unpickled."""

    def __init__(self, error: str) -> None:
        self.space = Space.from_bounds([-1.0, -1.0], [1.0, 1.0])
        self.error = error

    def evaluate(self, x, seed):
        return Evaluation(0.0, {"odd": _RefusesUnpickling(self.error)})


@pytest.mark.parametrize("error", ["ValueError", "SystemExit"])
def test_an_outcome_that_does_not_unpickle_fails_alone_and_the_worker_serves_on(error):
    """An outcome that the worker sends but the parent cannot unpickle fails its task alone,
    saying why in one line, with its index and wall time, instead of breaking the pool (the
    load raised in the manager thread: every task failed with BrokenExecutor), nor, where the
    load raised SystemExit, ending the manager thread silently (every caller waited for ever);
    the same worker, alive and idle, serves the rest."""
    executor = registry().executor("process").factory(1, None)
    try:
        (worker,) = [worker.process for worker in executor._pool]
        odd = EvaluationTask(5, np.zeros(2), 0, _UnreadableMetric, {"error": error})
        tasks = [odd, *_sphere_tasks(2, time_limit=None)]
        outcomes = [executor.submit(task).result(timeout=60) for task in tasks]
        assert outcomes[0].index == 5 and outcomes[0].fitness is None
        refused = f"{error}: a _RefusesUnpickling refuses to be unpickled"
        assert outcomes[0].error == f"the outcome could not be read back: {refused}"
        assert outcomes[0].wall_time > 0  # from the start of its timed evaluation
        assert [outcome.error for outcome in outcomes[1:]] == [None, None]
        assert executor._broken is None
        assert executor._pool[0].process is worker and worker.is_alive()  # never replaced
    finally:
        executor.shutdown()


def test_a_manager_thread_ended_by_system_exit_breaks_the_pool(monkeypatch):
    """A BaseException that is no Exception (SystemExit) ending the manager thread breaks the
    pool as any error does, so a submit raises BrokenExecutor naming it (the thread ended
    silently, and every task submitted waited for ever)."""
    from metaopt.executors import process_pool

    def exits(executor: process_pool.ProcessExecutor) -> None:
        raise SystemExit("told to exit")

    monkeypatch.setattr(process_pool.ProcessExecutor, "_serve", exits)
    executor = registry().executor("process").factory(1, None)
    try:
        executor._manager.join(timeout=30)
        (task,) = _sphere_tasks(1, time_limit=None)
        broken = "its manager thread failed with SystemExit: told to exit"
        with pytest.raises(concurrent.futures.BrokenExecutor, match=broken):
            executor.submit(task)
    finally:
        executor.shutdown()
