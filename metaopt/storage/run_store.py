"""The run store: every run and every evaluation in an embedded SQLite database.

Evaluations are queued by the run loop and committed in small transactions by a background
flusher, so cheap evaluations cost microseconds while none waits uncommitted for more than
``FLUSH_INTERVAL`` seconds. WAL mode lets other processes read (and write) while a run goes on.
"""

from __future__ import annotations

import json
import os
import socket
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import AbstractContextManager
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from metaopt.errors import StoreError
from metaopt.resampling import aggregate_fitness, aggregate_metrics
from metaopt.storage.limits import MAX_STORED_INT

FORMAT_NAME = "metaopt-run-store"
SCHEMA_VERSION = 1
FLUSH_INTERVAL = 0.5
#: Seconds a write waits for another connection's write lock before it fails.
BUSY_TIMEOUT = 30.0
DEFAULT_DB = "metaopt.db"
#: A store that lives in memory, for runs that are not kept (SQLite's own name for one).
IN_MEMORY = ":memory:"
#: A running run's owner renews its claim this often (seconds) ...
HEARTBEAT_INTERVAL = 5.0
#: ... and a claim from another host not renewed for this long is taken as dead.
OWNER_TIMEOUT = 30.0
HOST = socket.gethostname()

#: Which process runs which run (a table of its own, created when first needed, so stores of
#: earlier versions open unchanged): a second process is refused while the owner lives.
_OWNER_SCHEMA = """
CREATE TABLE IF NOT EXISTS run_owners (
    run_id INTEGER PRIMARY KEY REFERENCES runs(id),
    pid INTEGER NOT NULL,
    host TEXT NOT NULL,
    heartbeat REAL NOT NULL
);
"""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    optimizer TEXT NOT NULL,
    optimizer_params TEXT NOT NULL,
    problem TEXT NOT NULL,
    problem_params TEXT NOT NULL,
    seed INTEGER NOT NULL,
    budget INTEGER NOT NULL,
    sense TEXT NOT NULL,
    space TEXT NOT NULL,
    settings TEXT NOT NULL,
    versions TEXT NOT NULL,
    started_at TEXT NOT NULL,
    ended_at TEXT,
    status TEXT NOT NULL,
    message TEXT,
    wall_time REAL,
    checkpoint TEXT
);
CREATE TABLE IF NOT EXISTS evaluations (
    run_id INTEGER NOT NULL REFERENCES runs(id),
    idx INTEGER NOT NULL,
    candidate INTEGER NOT NULL,
    x BLOB NOT NULL,
    fitness REAL,
    metrics TEXT,
    status TEXT NOT NULL,
    error TEXT,
    seed INTEGER NOT NULL,
    wall_time REAL NOT NULL,
    finished_at REAL NOT NULL,
    PRIMARY KEY (run_id, idx)
);
"""

RUN_STATUSES = ("running", "finished", "interrupted", "failed")


@dataclass
class RunRecord:
    """One row of the runs table, JSON columns decoded."""

    id: int
    optimizer: str
    optimizer_params: dict[str, Any]
    problem: str
    problem_params: dict[str, Any]
    seed: int
    budget: int
    sense: str
    space: list[dict]
    settings: dict[str, Any]
    versions: dict[str, str]
    started_at: str
    ended_at: str | None
    status: str
    message: str | None
    wall_time: float | None
    #: {"state": optimizer state, "told_below": n, "told_extra": [candidate, ...]}: the
    #: optimizer has been told every candidate whose evaluations all lie below index n, and
    #: the candidates listed.
    checkpoint: dict | None


@dataclass
class EvaluationRecord:
    """One stored evaluation. ``fitness`` is None when it failed (status 'failed') or when
    only its screen ran (status 'screened', metrics hold the bound: metaopt run --screen)."""

    index: int
    candidate: int
    x: np.ndarray
    fitness: float | None
    metrics: dict[str, float]
    status: str
    error: str | None
    seed: int
    wall_time: float
    finished_at: float


@dataclass(frozen=True)
class EvaluationCounts:
    """How many evaluations of a run are stored, and of those how many failed and how many
    were screened (only their screen ran: metaopt run --screen)."""

    stored: int
    failed: int
    screened: int


@dataclass
class CandidateRecord:
    """A candidate with its stored samples and their aggregate (the run's resample and
    aggregate settings; one sample: that evaluation as it is). ``index`` and ``seed`` are its
    first sample's, the one a figure or video of the candidate shows."""

    number: int
    x: np.ndarray
    fitness: float
    metrics: dict[str, float]
    samples: list[EvaluationRecord]
    aggregate: str = "mean"

    @property
    def index(self) -> int:
        return self.samples[0].index

    @property
    def seed(self) -> int:
        return self.samples[0].seed

    def describe(self) -> str:
        """'evaluation 7' or 'candidate 3, mean of evaluations 9-11'."""
        if len(self.samples) == 1:
            return f"evaluation {self.index}"
        last = self.samples[-1].index
        return f"candidate {self.number}, {self.aggregate} of evaluations {self.index}-{last}"


def _owner_alive(pid: int, host: str, heartbeat: float) -> bool:
    """Whether a run's owner still runs: on this host, whether its process exists; elsewhere,
    whether its heartbeat is recent."""
    if host != HOST:
        return time.time() - heartbeat < OWNER_TIMEOUT
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _database_uri(path: Path) -> str:
    """The SQLite URI of the file at ``path``, every character of it quoted (IN_MEMORY as it
    is): SQLite builds that read URIs by default take a plain name starting with 'file:' as one
    (its '?' and '#' as parts of it) and would open another file."""
    if str(path) == IN_MEMORY:
        return IN_MEMORY
    return path.absolute().as_uri()


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


class RunStore:
    """A SQLite run store at ``path`` (created if missing; refused if it is not a metaopt store)."""

    def __init__(
        self, path: str | Path = DEFAULT_DB, *, busy_timeout: float = BUSY_TIMEOUT
    ) -> None:
        """Open (or create) the store; a write waits up to ``busy_timeout`` seconds for another
        connection's write lock before it fails."""
        self.path = Path(path)
        if str(self.path) != IN_MEMORY:  # a file of that name in the folder is not the store
            self._check_file()
        try:
            self._connection = sqlite3.connect(
                _database_uri(self.path),
                timeout=busy_timeout,
                check_same_thread=False,
                isolation_level=None,
                uri=True,
            )
        except sqlite3.DatabaseError as error:
            raise StoreError(f"cannot use {self.path} as a run store: {error}") from None
        try:
            self._check_or_create_schema()  # first: a foreign database is left as it was
            self._connection.execute("PRAGMA journal_mode=WAL")
            self._connection.execute("PRAGMA synchronous=NORMAL")
        except BaseException as error:
            self._connection.close()  # a refused store leaves no connection open
            if isinstance(error, sqlite3.DatabaseError):
                raise StoreError(f"cannot use {self.path} as a run store: {error}") from None
            raise
        #: Guards the queue only, so that queuing an evaluation never waits on a write.
        self._lock = threading.Lock()
        #: Serialises the connection's transactions (and guards _owned, changed in them).
        self._write_lock = threading.Lock()
        self._pending: list[tuple] = []
        self._stop = threading.Event()
        self._flusher: threading.Thread | None = None
        self._owned: set[int] = set()
        self._last_heartbeat = 0.0

    def _check_file(self) -> None:
        """StoreError unless the path is a new file or a SQLite database (never a folder)."""
        if self.path.is_dir():
            raise StoreError(f"--db {self.path} is a directory; give a database file path")
        if self.path.exists() and self.path.stat().st_size > 0:
            with self.path.open("rb") as handle:
                if handle.read(16) != b"SQLite format 3\x00":
                    raise StoreError(
                        f"{self.path} is not a SQLite database; give a metaopt store "
                        "or a new file name"
                    )

    def _check_or_create_schema(self) -> None:
        tables = {
            row[0]
            for row in self._connection.execute("SELECT name FROM sqlite_master WHERE type='table'")
        }
        if tables and "meta" not in tables:
            raise StoreError(
                f"{self.path} is a SQLite database of something else (tables: "
                f"{', '.join(sorted(tables))}); give a metaopt store or a new file name"
            )
        if not tables:
            # Two runs may create the same new file at once: every statement tolerates the other.
            self._connection.executescript(
                f"BEGIN IMMEDIATE; {_SCHEMA} "
                f"INSERT OR IGNORE INTO meta VALUES ('format', '{FORMAT_NAME}'); "
                f"INSERT OR IGNORE INTO meta VALUES ('schema_version', '{SCHEMA_VERSION}'); COMMIT;"
            )
            return
        meta = dict(self._connection.execute("SELECT key, value FROM meta"))
        if meta.get("format") != FORMAT_NAME:
            raise StoreError(f"{self.path} is not a metaopt run store")
        if int(meta.get("schema_version", "0")) > SCHEMA_VERSION:
            raise StoreError(
                f"{self.path} was written by a newer metaopt (schema "
                f"{meta['schema_version']}); upgrade metaopt to read it"
            )

    def _transaction(self) -> AbstractContextManager[None]:
        """A write transaction (BEGIN IMMEDIATE): committed, or rolled back on an error; a
        COMMIT that fails (a lock, a full disk) is rolled back too, so none is left open."""
        connection = self._connection

        class _Transaction:
            def __enter__(self) -> None:
                connection.execute("BEGIN IMMEDIATE")

            def __exit__(self, kind: type[BaseException] | None, value: object, tb: object) -> None:
                if kind is None:
                    try:
                        connection.execute("COMMIT")
                        return
                    except BaseException:
                        self._rollback()
                        raise
                self._rollback()

            @staticmethod
            def _rollback() -> None:
                # SQLite rolls some failures back itself (a full disk): then there is none left
                if connection.in_transaction:
                    connection.execute("ROLLBACK")

        return _Transaction()

    # -- writing ---------------------------------------------------------------------------

    def create_run(
        self,
        *,
        optimizer: str,
        optimizer_params: dict[str, Any],
        problem: str,
        problem_params: dict[str, Any],
        seed: int,
        budget: int,
        sense: str,
        space: list[dict],
        settings: dict[str, Any],
        versions: dict[str, str],
    ) -> int:
        """Insert a new run with status 'running' and return its id."""
        with self._write_lock, self._transaction():
            cursor = self._connection.execute(
                "INSERT INTO runs (optimizer, optimizer_params, problem, problem_params, seed, "
                "budget, sense, space, settings, versions, started_at, status) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, 'running')",
                (
                    optimizer,
                    json.dumps(optimizer_params),
                    problem,
                    json.dumps(problem_params),
                    seed,
                    budget,
                    sense,
                    json.dumps(space),
                    json.dumps(settings),
                    json.dumps(versions),
                    _now(),
                ),
            )
            run_id = int(cursor.lastrowid)
            self._record_with_new_run(run_id)
            return run_id

    def _record_with_new_run(self, run_id: int) -> None:
        """What a subclass records about a run it creates, in create_run's transaction (so
        both or neither are stored); nothing here."""

    def add_evaluation(
        self,
        run_id: int,
        index: int,
        candidate: int,
        x: np.ndarray,
        fitness: float | None,
        metrics: dict[str, float] | None,
        error: str | None,
        seed: int,
        wall_time: float,
        screened: bool = False,
    ) -> None:
        """Queue one finished evaluation (screened: only its screen ran, its fitness is None and
        its metrics hold the bound); the flusher commits it within FLUSH_INTERVAL."""
        status = "failed" if error is not None else "screened" if screened else "ok"
        row = (
            run_id,
            index,
            candidate,
            np.asarray(x, dtype="<f8").tobytes(),
            fitness,
            json.dumps(metrics) if metrics else None,
            status,
            error,
            seed,
            wall_time,
            time.time(),
        )
        with self._lock:
            self._pending.append(row)
        if self._flusher is None:
            self._start_flusher()

    def _start_flusher(self) -> None:
        self._stop.clear()
        self._flusher = threading.Thread(target=self._flush_loop, name="metaopt-store", daemon=True)
        self._flusher.start()

    def _flush_loop(self) -> None:
        """Commit queued evaluations (and renew claims) every tick; a failed write (the store
        locked past the busy timeout, a full disk) keeps its rows and is tried again on the
        next tick, and a failure that lasts is raised by the next explicit flush or close."""
        while not self._stop.wait(FLUSH_INTERVAL / 2):
            try:
                self.flush()
                if self._owned and time.time() - self._last_heartbeat >= HEARTBEAT_INTERVAL:
                    self._heartbeat()
            except sqlite3.Error:
                continue  # the rows stay queued: the next tick (or flush, or close) tries again

    def claim(self, run_id: int) -> None:
        """Make this process the run's owner, or StoreError naming the live process that owns
        it; a claim whose process died (or, from another host, went silent) is taken over."""
        with self._write_lock, self._transaction():
            self._connection.execute(_OWNER_SCHEMA)
            row = self._connection.execute(
                "SELECT pid, host, heartbeat FROM run_owners WHERE run_id = ?", (run_id,)
            ).fetchone()
            if row is not None and (row[0], row[1]) != (os.getpid(), HOST) and _owner_alive(*row):
                pid, host, heartbeat = row
                raise StoreError(
                    f"run {run_id} is being run by process {pid} on host {host} (alive "
                    f"{time.time() - heartbeat:.0f} s ago); wait for it to end or stop it "
                    f"before resuming"
                )
            self._connection.execute(
                "INSERT OR REPLACE INTO run_owners VALUES (?, ?, ?, ?)",
                (run_id, os.getpid(), HOST, time.time()),
            )
            # under the write lock: the flusher's heartbeat iterates _owned
            self._owned.add(run_id)
            self._last_heartbeat = time.time()
        if self._flusher is None:
            self._start_flusher()

    def _heartbeat(self) -> None:
        """Renew this process's claims on the runs it owns (a failed renewal is retried on the
        flusher's next tick)."""
        now = time.time()
        with self._write_lock, self._transaction():
            self._connection.executemany(
                "UPDATE run_owners SET heartbeat = ? WHERE run_id = ? AND pid = ? AND host = ?",
                [(now, run_id, os.getpid(), HOST) for run_id in self._owned],
            )
        self._last_heartbeat = now

    def _release(self, run_id: int) -> None:
        """This process no longer runs the run (caller holds the write lock, in a transaction)."""
        if run_id in self._owned:
            self._owned.discard(run_id)
            self._connection.execute(
                "DELETE FROM run_owners WHERE run_id = ? AND pid = ? AND host = ?",
                (run_id, os.getpid(), HOST),
            )

    def flush(self, checkpoint: tuple[int, dict] | None = None) -> None:
        """Commit queued evaluations now; optionally with a (run_id, checkpoint) in the same
        transaction, so the optimizer state never gets ahead of the stored evaluations. When
        the write fails (locked past the busy timeout, a full disk) the error is raised and
        the evaluations stay queued, first, for the next flush; rows leave the queue only once
        committed. Evaluations queued while it writes wait for the next flush."""
        with self._write_lock:  # one flush at a time: each writes what the last one left
            with self._lock:
                rows = list(self._pending)
            if not rows and checkpoint is None:
                return
            self._write(rows, checkpoint)
            with self._lock:  # committed, so off the queue; a flush interrupted before this
                del self._pending[: len(rows)]  # writes them again, each replacing itself

    def _write(self, rows: list[tuple], checkpoint: tuple[int, dict] | None) -> None:
        """Commit evaluation rows and an optional (run_id, checkpoint) in one transaction
        (caller holds the write lock)."""
        with self._transaction():
            self._connection.executemany(
                "INSERT OR REPLACE INTO evaluations VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                rows,
            )
            if checkpoint is not None:
                run_id, content = checkpoint
                self._connection.execute(
                    "UPDATE runs SET checkpoint = ? WHERE id = ?", (json.dumps(content), run_id)
                )

    def mark_running(self, run_id: int, settings: dict[str, Any], budget: int) -> None:
        """A resumed run is running again, with the settings and budget it resumes with (a new
        max time, a larger budget)."""
        with self._write_lock, self._transaction():
            self._connection.execute(
                "UPDATE runs SET status = 'running', ended_at = NULL, message = NULL, "
                "settings = ?, budget = ? WHERE id = ?",
                (json.dumps(settings), budget, run_id),
            )

    def finish_run(
        self, run_id: int, status: str, wall_time: float, message: str | None = None
    ) -> None:
        """Flush, then record the run's end, status and an optional message; this process
        no longer owns it. ``wall_time`` is this session's: a resumed run's stored wall time
        is the sum of its sessions' (a killed session's is not known)."""
        if status not in RUN_STATUSES:
            raise ValueError(f"unknown run status {status!r}")
        self.flush()
        with self._write_lock, self._transaction():
            self._connection.execute(
                "UPDATE runs SET status = ?, ended_at = ?, wall_time = COALESCE(wall_time, 0) + ?, "
                "message = ? WHERE id = ?",
                (status, _now(), wall_time, message, run_id),
            )
            self._release(run_id)

    def close(self) -> None:
        """Stop the flusher, commit what is queued and close the database; a write that still
        fails (the store locked, a full disk) is raised, the database closed all the same."""
        if self._flusher is not None:
            self._stop.set()
            self._flusher.join()
            self._flusher = None
        try:
            self.flush()
            if self._owned:
                with self._write_lock, self._transaction():
                    for run_id in list(self._owned):
                        self._release(run_id)
        finally:
            self._connection.close()

    def __enter__(self) -> RunStore:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- reading ---------------------------------------------------------------------------

    def runs(self) -> list[RunRecord]:
        """Every run, oldest first."""
        cursor = self._connection.execute("SELECT * FROM runs ORDER BY id")
        return [self._run_record(cursor, row) for row in cursor.fetchall()]

    def run(self, run_id: int | str) -> RunRecord:
        """One run by id, or StoreError naming the ids that exist."""
        try:
            run_id = int(run_id)
        except ValueError:
            raise StoreError(f"run id must be a number, got {run_id!r}") from None
        if not 0 < run_id <= MAX_STORED_INT:
            raise StoreError(
                f"run id must be a positive number (as `metaopt runs` lists), got {run_id}"
            )
        cursor = self._connection.execute("SELECT * FROM runs WHERE id = ?", (run_id,))
        row = cursor.fetchone()
        if row is None:
            ids = [str(r[0]) for r in self._connection.execute("SELECT id FROM runs ORDER BY id")]
            known = ", ".join(ids[-10:]) or "none yet"
            if len(ids) > 10:  # the newest, with the count, so that a long list stays one line
                known = f"{len(ids)} runs, the last ten {known} (metaopt runs)"
            raise StoreError(f"no run {run_id} in {self.path}; runs there: {known}")
        return self._run_record(cursor, row)

    @staticmethod
    def _run_record(cursor: sqlite3.Cursor, row: tuple) -> RunRecord:
        data = dict(zip([c[0] for c in cursor.description], row))
        for key in ("optimizer_params", "problem_params", "space", "settings", "versions",
                    "checkpoint"):  # fmt: skip
            if data[key] is not None:
                data[key] = json.loads(data[key])
        return RunRecord(**data)

    def evaluations(
        self, run_id: int, start: int = 0, stop: int | None = None
    ) -> Iterator[EvaluationRecord]:
        """A run's stored evaluations with start <= index < stop, in index order."""
        cursor = self._connection.execute(
            "SELECT idx, candidate, x, fitness, metrics, status, error, seed, wall_time, "
            "finished_at "
            "FROM evaluations WHERE run_id = ? AND idx >= ? AND idx < ? ORDER BY idx",
            (run_id, start, stop if stop is not None else 2**62),
        )
        for idx, candidate, x, fitness, metrics, status, error, seed, wall, finished in cursor:
            yield EvaluationRecord(
                index=idx,
                candidate=candidate,
                x=np.frombuffer(x, dtype="<f8").copy(),
                fitness=fitness,
                metrics=json.loads(metrics) if metrics else {},
                status=status,
                error=error,
                seed=seed,
                wall_time=wall,
                finished_at=finished,
            )

    def last_evaluations(self, run_id: int, count: int) -> list[EvaluationRecord]:
        """The run's ``count`` stored evaluations of highest index (all, when it has fewer),
        in index order."""
        row = self._connection.execute(
            "SELECT idx FROM evaluations WHERE run_id = ? ORDER BY idx DESC LIMIT 1 OFFSET ?",
            (run_id, count - 1),
        ).fetchone()
        return list(self.evaluations(run_id, start=0 if row is None else row[0]))

    def read(self, query: str, parameters: tuple = ()) -> list[tuple]:
        """The rows of a read-only query (for the tables that extensions of the store add)."""
        return self._connection.execute(query, parameters).fetchall()

    def evaluation_counts(self, run_id: int) -> EvaluationCounts:
        """How many evaluations of a run are stored, failed and screened."""
        stored, failed, screened = self._connection.execute(
            "SELECT COUNT(*), COALESCE(SUM(status = 'failed'), 0), "
            "COALESCE(SUM(status = 'screened'), 0) FROM evaluations WHERE run_id = ?",
            (run_id,),
        ).fetchone()
        return EvaluationCounts(int(stored), int(failed), int(screened))

    def best_candidate(self, run: RunRecord) -> CandidateRecord | None:
        """The run's best candidate under its sense by the aggregate over its samples (as the
        optimizer saw it; a candidate with a failed or missing sample does not count), or None.
        Without resampling, the best evaluation."""
        if int(run.settings.get("resample", 1)) == 1:
            best = self.best_evaluation(run)
            if best is None:
                return None
            return CandidateRecord(best.candidate, best.x, best.fitness, best.metrics, [best])
        return next(iter(self.best_candidates(run, 1)), None)

    def best_candidates(
        self, run: RunRecord, count: int, last: int | None = None
    ) -> list[CandidateRecord]:
        """The run's ``count`` best candidates with distinct decision vectors, best first (by
        the aggregate over their samples, as best_candidate ranks them; ties: the earlier
        candidate first), among its ``last`` latest candidates (by number) when given. For
        re-checking the top of a run, whose best is the luckiest of many noisy scores; its
        latest have been through more of its selection than an early lucky one."""
        sign = -1.0 if run.sense == "maximize" else 1.0
        complete = self.complete_candidates(run)
        if last is not None:  # counted back from the latest, whether it succeeded or not
            (latest,) = self._connection.execute(
                "SELECT MAX(candidate) FROM evaluations WHERE run_id = ?", (run.id,)
            ).fetchone()
            complete = (c for c in complete if c.number > latest - last)  # none: no latest
        ranked = sorted(complete, key=lambda c: (sign * c.fitness, c.number))
        chosen: dict[bytes, CandidateRecord] = {}
        for candidate in ranked:
            chosen.setdefault(candidate.x.tobytes(), candidate)
            if len(chosen) == count:
                break
        return list(chosen.values())

    def candidate(self, run: RunRecord, number: int) -> CandidateRecord:
        """Candidate ``number`` of the run with its samples' aggregate (StoreError when the run
        has no such candidate with all its samples successful)."""
        for candidate in self.complete_candidates(run):
            if candidate.number == number:
                return candidate
        raise StoreError(f"run {run.id} has no candidate {number} with all its samples successful")

    def complete_candidates(self, run: RunRecord) -> Iterator[CandidateRecord]:
        """Every candidate of the run whose samples all succeeded, with their aggregate."""
        resample = int(run.settings.get("resample", 1))
        aggregate = run.settings.get("aggregate", "mean")
        by_candidate: dict[int, list[EvaluationRecord]] = {}
        for evaluation in self.evaluations(run.id):
            by_candidate.setdefault(evaluation.candidate, []).append(evaluation)
        for number, samples in by_candidate.items():
            if len(samples) != resample or any(e.fitness is None for e in samples):
                continue
            yield CandidateRecord(
                number,
                samples[0].x,
                aggregate_fitness([e.fitness for e in samples], aggregate),
                aggregate_metrics([e.metrics for e in samples], aggregate),
                samples,
                aggregate,
            )

    def best_evaluation(self, run: RunRecord) -> EvaluationRecord | None:
        """The best successful evaluation of a run under its sense, or None."""
        order = "DESC" if run.sense == "maximize" else "ASC"
        row = self._connection.execute(
            "SELECT idx FROM evaluations WHERE run_id = ? AND status = 'ok' "
            f"ORDER BY fitness {order}, idx LIMIT 1",
            (run.id,),
        ).fetchone()
        if row is None:
            return None
        return next(self.evaluations(run.id, row[0], row[0] + 1))
