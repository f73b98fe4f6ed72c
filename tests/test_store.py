import contextlib
import os
import sqlite3
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from metaopt import ConfigError, StoreError
from metaopt.cli.common import check_store_path
from metaopt.storage import run_store as store_module
from metaopt.storage.experiment_store import ExperimentStore
from metaopt.storage.run_store import FLUSH_INTERVAL, EvaluationCounts, RunStore


def _new_run(store: RunStore, settings: dict | None = None) -> int:
    return store.create_run(
        optimizer="hs",
        optimizer_params={"hmcr": 0.9},
        problem="sphere",
        problem_params={"dim": 2},
        seed=7,
        budget=10,
        sense="minimize",
        space=[{"name": "x0", "lower": -1, "upper": 1, "description": ""}],
        settings=settings or {"mode": "sync"},
        versions={"python": "3"},
    )


def test_evaluations_round_trip_exactly(tmp_path):
    x = np.array([0.1, -1 / 3, np.pi])
    with RunStore(tmp_path / "a.db") as store:
        run_id = _new_run(store)
        store.add_evaluation(run_id, 0, 0, x, 1.25, {"distance": 2.5}, None, 99, 0.01)
        store.add_evaluation(run_id, 1, 1, x * 2, None, None, "ValueError: boom", 100, 0.02)
    with RunStore(tmp_path / "a.db") as store:
        first, second = store.evaluations(run_id)
        assert first.x.tobytes() == x.tobytes()  # bit for bit
        assert (first.fitness, first.metrics, first.status, first.seed) == (
            1.25, {"distance": 2.5}, "ok", 99,
        )  # fmt: skip
        assert (second.fitness, second.status, second.error) == (None, "failed", "ValueError: boom")
        assert store.evaluation_counts(run_id) == EvaluationCounts(2, 1, 0)
        assert store.run(run_id).optimizer_params == {"hmcr": 0.9}


def test_queued_evaluations_are_committed_within_the_flush_interval(tmp_path):
    """A finished evaluation never waits long uncommitted, even when no more follow."""
    store = RunStore(tmp_path / "b.db")
    run_id = _new_run(store)
    store.add_evaluation(run_id, 0, 0, np.zeros(1), 1.0, None, None, 1, 0.0)
    reader = sqlite3.connect(tmp_path / "b.db")
    deadline = time.monotonic() + 4 * FLUSH_INTERVAL
    count = 0
    while time.monotonic() < deadline and count == 0:
        count = reader.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0]
        time.sleep(0.05)
    assert count == 1
    store.close()


def test_foreign_files_are_refused_and_left_untouched(tmp_path):
    text = tmp_path / "notes.db"
    text.write_text("my notes")
    with pytest.raises(StoreError, match="not a SQLite database"):
        RunStore(text)
    assert text.read_text() == "my notes"
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as connection:
        connection.execute("CREATE TABLE customers (name TEXT)")
    with pytest.raises(StoreError, match="database of something else"):
        RunStore(other)
    with pytest.raises(StoreError, match="is a directory"):
        RunStore(tmp_path)


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="reads /proc/self/fd")
def test_a_refused_store_leaves_no_file_open(tmp_path):
    """Refused after the connection opened (another program's database): it is closed, so no
    descriptor of this process points at the file."""
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as connection:
        connection.execute("CREATE TABLE customers (name TEXT)")
    connection.close()
    for _ in range(5):
        with pytest.raises(StoreError, match="database of something else"):
            RunStore(other)
    pointing = []
    for descriptor in Path("/proc/self/fd").iterdir():
        with contextlib.suppress(OSError):  # one closed meanwhile (another thread's)
            if os.readlink(descriptor).startswith(str(other)):  # the file, its -wal, -shm
                pointing.append(descriptor.name)
    assert pointing == []


def test_unknown_run_names_the_known_ones(tmp_path):
    with RunStore(tmp_path / "c.db") as store:
        _new_run(store)
        with pytest.raises(StoreError, match=r"no run 5 .* runs there: 1"):
            store.run(5)
        with pytest.raises(StoreError, match="must be a number"):
            store.run("abc")


def test_an_unknown_run_in_a_long_store_names_the_newest_and_the_count(tmp_path):
    """Eleven runs: the message names the last ten and says there are eleven, not just ten."""
    with RunStore(tmp_path / "c.db") as store:
        for _ in range(11):
            _new_run(store)
        with pytest.raises(StoreError) as refused:
            store.run(20)
    message = str(refused.value)
    assert "runs there: 11 runs, the last ten 2, 3, 4, 5, 6, 7, 8, 9, 10, 11" in message


def test_two_writers_on_one_file_keep_all_their_data(tmp_path):
    path = tmp_path / "shared.db"
    first, second = RunStore(path), RunStore(path)
    run_a, run_b = _new_run(first), _new_run(second)
    for i in range(200):
        first.add_evaluation(run_a, i, i, np.zeros(1), float(i), None, None, i, 0.0)
        second.add_evaluation(run_b, i, i, np.ones(1), float(-i), None, None, i, 0.0)
    first.close()
    second.close()
    with RunStore(path) as store:
        assert store.evaluation_counts(run_a) == EvaluationCounts(200, 0, 0)
        assert store.evaluation_counts(run_b) == EvaluationCounts(200, 0, 0)


def test_an_owners_heartbeat_is_renewed_and_a_silent_remote_claim_taken_over(tmp_path, monkeypatch):
    """The flusher renews a claim's heartbeat; another host's claim is refused while its
    heartbeat is fresh and taken over once it is older than OWNER_TIMEOUT."""
    monkeypatch.setattr(store_module, "HEARTBEAT_INTERVAL", 0.1)
    with RunStore(tmp_path / "h.db") as store:
        run_id = _new_run(store)
        store.claim(run_id)
        (first,) = store.read("SELECT heartbeat FROM run_owners")[0]
        deadline = time.monotonic() + 20 * FLUSH_INTERVAL
        renewed = first
        while time.monotonic() < deadline and renewed == first:
            time.sleep(0.05)
            (renewed,) = store.read("SELECT heartbeat FROM run_owners")[0]
        assert renewed > first
        store.finish_run(run_id, "finished", 0.0)
        assert store.read("SELECT * FROM run_owners") == []  # released

        remote = "UPDATE run_owners SET pid = 1, host = 'elsewhere', heartbeat = ?"
        store.claim(run_id)
        with store._write_lock:
            store._owned.clear()  # this process's flusher no longer renews it
        store._connection.execute(remote, (time.time(),))
        with pytest.raises(StoreError, match="on host elsewhere"):
            store.claim(run_id)
        store._connection.execute(remote, (time.time() - store_module.OWNER_TIMEOUT - 1,))
        store.claim(run_id)  # a silent remote owner is taken as dead
        assert store.read("SELECT host FROM run_owners") == [(store_module.HOST,)]


def test_latest_candidates_none_of_which_succeeded_are_refused_by_name(tmp_path):
    """--last N over a run whose N latest candidates all failed: nothing to take, and the
    message names the window rather than saying the run never succeeded."""
    from metaopt.assessment.candidates import find_candidates
    from metaopt.plugins import registry

    with RunStore(tmp_path / "a.db") as store:
        empty = _new_run(store)
        run_id = _new_run(store)
        store.add_evaluation(run_id, 0, 0, np.zeros(1), 1.0, {}, None, 0, 0.0)
        store.add_evaluation(run_id, 1, 1, np.ones(1), None, {}, "ValueError: boom", 1, 0.0)
    with RunStore(tmp_path / "a.db") as store:
        run = store.run(run_id)
        assert store.best_candidates(run, 3, last=1) == []
        assert store.best_candidates(store.run(empty), 3, last=1) == []  # no latest at all
        assert [r.number for r in store.best_candidates(run, 3, last=2)] == [0]
    with pytest.raises(StoreError, match=f"run {run_id} has no successful evaluation among its 1"):
        find_candidates(str(run_id), registry().problems, str(tmp_path / "a.db"), 3, last=1)


def test_a_runs_best_candidates_are_distinct_ranked_by_their_aggregate(tmp_path):
    """best_candidates: the K best by the mean of each candidate's samples (a candidate with a
    failed sample does not count), one per decision vector, among the run's N latest when
    asked; candidate(run, N) reads one back; best_candidate is the first of them."""
    a, b, c, d = (np.full(1, v) for v in (0.1, 0.2, 0.3, 0.4))
    with RunStore(tmp_path / "a.db") as store:
        run_id = _new_run(store, {"mode": "sync", "resample": 2, "aggregate": "mean"})
        samples = [  # (candidate, x, fitness): minimized
            (0, a, 1.0),
            (0, a, 5.0),  # mean 3
            (1, b, 0.5),
            (1, b, 0.7),  # mean 0.6: the best
            (2, a, 2.0),
            (2, a, 2.0),  # mean 2: the best with vector a
            (3, c, 0.1),
            (3, c, None),  # a failed sample: left out
            (4, d, 1.5),
            (4, d, 1.5),
        ]
        for index, (number, x, fitness) in enumerate(samples):
            error = None if fitness is not None else "ValueError: boom"
            store.add_evaluation(run_id, index, number, x, fitness, {"f": fitness or 0.0},
                                 error, index, 0.0)  # fmt: skip
    with RunStore(tmp_path / "a.db") as store:
        run = store.run(run_id)
        best = store.best_candidates(run, 3)
        assert [(r.number, r.fitness) for r in best] == [(1, 0.6), (4, 1.5), (2, 2.0)]
        assert [r.number for r in store.best_candidates(run, 10)] == [1, 4, 2]
        assert store.best_candidate(run).number == 1
        # among the latest: counted back from candidate 4, the failed candidate 3 included
        assert [r.number for r in store.best_candidates(run, 3, last=3)] == [4, 2]
        assert [r.number for r in store.best_candidates(run, 3, last=2)] == [4]
        assert [r.number for r in store.best_candidates(run, 3, last=4)] == [1, 4, 2]
        assert store.candidate(run, 0).fitness == 3.0
        assert store.candidate(run, 0).metrics == {"f": 3.0}
        with pytest.raises(StoreError, match="no candidate 3 with all its samples successful"):
            store.candidate(run, 3)


def test_the_store_path_is_refused_where_no_store_can_be_and_nothing_is_left_behind(tmp_path):
    """`metaopt run` checks where its store goes before anything else and creates it only once
    every setting has passed: the check itself creates nothing."""
    check_store_path(str(tmp_path / "new.db"))
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "notes.txt").write_text("not a store")
    with pytest.raises(StoreError, match=r"notes\.txt is not a SQLite database"):
        check_store_path(str(tmp_path / "notes.txt"))
    with pytest.raises(StoreError, match="is a directory"):
        check_store_path(str(tmp_path))
    with pytest.raises(ConfigError, match=r"folder .*missing does not exist"):
        check_store_path(str(tmp_path / "missing" / "x.db"))
    with RunStore(tmp_path / "kept.db") as store:
        _new_run(store)
    check_store_path(str(tmp_path / "kept.db"))  # an existing store passes, as it was
    with RunStore(tmp_path / "kept.db") as store:
        assert len(store.runs()) == 1


def _stored_count(path) -> int:
    """Evaluations committed in the store at path, read on a connection of its own."""
    with sqlite3.connect(path) as reader:
        return reader.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0]


def _write_lock(path) -> sqlite3.Connection:
    """A second connection holding the store's write lock until it commits (another process
    writing, for the run store: BEGIN IMMEDIATE as the store's own writes take it)."""
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    return holder


def _queue_evaluations(store: RunStore, run_id: int, indices: range) -> None:
    """Queue one evaluation per index, its fitness and seed the index."""
    for i in indices:
        store.add_evaluation(run_id, i, i, np.full(1, i), float(i), None, None, i, 0.0)


def test_a_flush_that_fails_keeps_its_evaluations_for_the_next_one(tmp_path):
    """A write refused (the store locked past the busy timeout) raises and loses nothing:
    once the lock is gone the next flush stores every evaluation, in order."""
    path = tmp_path / "locked.db"
    store = RunStore(path, busy_timeout=0.1)
    run_id = _new_run(store)
    holder = _write_lock(path)
    _queue_evaluations(store, run_id, range(20))
    with pytest.raises(sqlite3.OperationalError, match="locked"):
        store.flush()
    _queue_evaluations(store, run_id, range(20, 30))  # queued behind the kept ones
    holder.commit()
    holder.close()
    store.flush()
    assert _stored_count(path) == 30
    store.close()
    with RunStore(path) as reopened:
        assert [e.index for e in reopened.evaluations(run_id)] == list(range(30))


def test_the_flusher_outlives_a_locked_store_and_stores_everything_after(tmp_path):
    """The background flusher's failed writes keep their rows and it goes on: once the lock
    is released they are committed with no explicit flush; close() raises a failure that
    lasts, and closes the store all the same."""
    path = tmp_path / "flusher.db"
    store = RunStore(path, busy_timeout=0.05)
    run_id = _new_run(store)
    holder = _write_lock(path)
    for i in range(10):
        store.add_evaluation(run_id, i, i, np.zeros(1), float(i), None, None, i, 0.0)
    time.sleep(4 * FLUSH_INTERVAL)  # several of the flusher's ticks fail meanwhile
    assert _stored_count(path) == 0
    holder.commit()
    deadline = time.monotonic() + 20 * FLUSH_INTERVAL
    while time.monotonic() < deadline and _stored_count(path) < 10:
        time.sleep(0.05)
    assert _stored_count(path) == 10

    holder.execute("BEGIN IMMEDIATE")  # locked again, for good this time
    store.add_evaluation(run_id, 10, 10, np.zeros(1), 10.0, None, None, 10, 0.0)
    with pytest.raises(sqlite3.OperationalError, match="locked"):
        store.close()
    with pytest.raises(sqlite3.ProgrammingError):  # closed all the same
        store.read("SELECT 1")
    holder.rollback()
    holder.close()


def test_queuing_an_evaluation_never_waits_on_a_write_to_a_locked_store(tmp_path):
    """While a flush waits on another connection's write lock (and then fails), queuing goes on
    at once; the refused rows stay ahead of those queued meanwhile, and once the lock is
    released a flush stores every evaluation once, in the order it was queued."""
    path = tmp_path / "busy.db"
    store = RunStore(path, busy_timeout=1.5)
    run_id = _new_run(store)
    holder = _write_lock(path)
    _queue_evaluations(store, run_id, range(10))
    errors: list[BaseException] = []

    def flush_in_background() -> None:
        try:
            store.flush()
        except sqlite3.OperationalError as error:
            errors.append(error)

    writer = threading.Thread(target=flush_in_background)
    writer.start()
    deadline = time.monotonic() + 1.0
    while not store._write_lock.locked() and time.monotonic() < deadline:
        time.sleep(0.005)
    assert store._write_lock.locked()  # the flush holds the write lock
    started = time.monotonic()
    _queue_evaluations(store, run_id, range(10, 20))
    assert time.monotonic() - started < 0.5  # not the busy timeout
    writer.join()
    assert len(errors) == 1 and "locked" in str(errors[0])
    holder.commit()
    holder.close()
    store.flush()
    assert store.read("SELECT idx FROM evaluations ORDER BY rowid") == [(i,) for i in range(20)]
    store.close()


def test_a_member_run_and_its_membership_are_stored_together_or_not_at_all(tmp_path):
    """An experiment's run joins its cell in the transaction that creates it: when recording
    the membership fails (here its table is gone), the run is not left behind either."""
    db = tmp_path / "e.db"
    with ExperimentStore(db) as store:
        with store.joining("study", "cell", 1):
            _new_run(store)
        assert store.member("study", "cell", 1) is not None
        with sqlite3.connect(db) as other:
            other.execute("DROP TABLE experiment_runs")
        other.close()
        with store.joining("study", "cell", 2), pytest.raises(sqlite3.OperationalError):
            _new_run(store)
        assert [row[0] for row in store.read("SELECT id FROM runs")] == [1]
