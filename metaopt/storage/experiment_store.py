"""A run store that also knows which runs make up each experiment's cells.

Membership lives in one extra table, ``experiment_runs(experiment, cell, seed, run_id)``, in
the same SQLite file; the runs and evaluations tables are untouched, so every other command
(`metaopt runs`, `show`, `export`, `replay`, `resume`) sees experiment runs as ordinary runs.
A run joins its cell the moment it is created, so a compare killed mid-run leaves a member
that the next compare resumes rather than an orphan it would run again.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from metaopt.storage.run_store import DEFAULT_DB, RunRecord, RunStore

_MEMBERSHIP_SCHEMA = """
CREATE TABLE IF NOT EXISTS experiment_runs (
    experiment TEXT NOT NULL,
    cell TEXT NOT NULL,
    seed INTEGER NOT NULL,
    run_id INTEGER NOT NULL REFERENCES runs(id),
    PRIMARY KEY (experiment, cell, seed)
);
"""


def experiment_names(store: RunStore) -> dict[int, str]:
    """Run id -> the experiment it belongs to, for the runs that belong to one (read only: a
    store without experiments is not changed)."""
    if not store.read("SELECT 1 FROM sqlite_master WHERE name = 'experiment_runs'"):
        return {}
    return {
        run_id: name
        for name, run_id in store.read("SELECT experiment, run_id FROM experiment_runs")
    }


class ExperimentStore(RunStore):
    """A RunStore with experiment membership: which run is (experiment, cell, seed)."""

    def __init__(self, path: str | Path = DEFAULT_DB) -> None:
        super().__init__(path)
        self._connection.executescript(_MEMBERSHIP_SCHEMA)
        self._joining: tuple[str, str, int] | None = None

    @contextmanager
    def joining(self, experiment: str, cell: str, seed: int) -> Iterator[None]:
        """The run created inside becomes the member (experiment, cell, seed)."""
        self._joining = (experiment, cell, seed)
        try:
            yield
        finally:
            self._joining = None

    def _record_with_new_run(self, run_id: int) -> None:
        """A run created while joining becomes that member, in the run's own transaction: no
        interruption can leave a member's run outside its cell."""
        if self._joining is not None:
            self._connection.execute(
                "INSERT OR REPLACE INTO experiment_runs VALUES (?, ?, ?, ?)",
                (*self._joining, run_id),
            )

    def member(self, experiment: str, cell: str, seed: int) -> RunRecord | None:
        """The run recorded as (experiment, cell, seed), or None."""
        row = self._connection.execute(
            "SELECT run_id FROM experiment_runs WHERE experiment = ? AND cell = ? AND seed = ?",
            (experiment, cell, seed),
        ).fetchone()
        return None if row is None else self.run(row[0])
