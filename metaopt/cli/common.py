"""What every metaopt command shares: the consoles, the --db option, the executor options."""

from __future__ import annotations

import os
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
from rich.console import Console

from metaopt.cli.output import check_output_file
from metaopt.errors import ConfigError, MetaoptError
from metaopt.executors.base import Executor, SerialExecutor
from metaopt.optimizer import MAX_BUDGET
from metaopt.plugins import registry
from metaopt.reporting.plain import plain
from metaopt.storage.run_store import DEFAULT_DB, RunStore

#: Output for a file or a pipe is never cut to a terminal's width: tables come out whole.
console = Console() if sys.stdout.isatty() else Console(width=100_000)
errors = Console(stderr=True, soft_wrap=True)
#: Dask scheduler addresses: SCHEME://HOST:PORT for Dask's own schemes, or HOST:PORT (tcp).
SCHEDULER_ADDRESS = re.compile(r"((tcp|tls|ucx|inproc)://)?[^\s/:]+(:\d+)?")

#: More local workers than this is a typing slip, not a machine.
MAX_WORKERS = 1024
#: what every --budget accepts: a whole number of evaluations, as the budget parameter does
BUDGET = click.IntRange(min=1, max=MAX_BUDGET)

db_option = click.option(
    "--db",
    "db_path",
    default=DEFAULT_DB,
    show_default=True,
    type=click.Path(dir_okay=False),
    help="SQLite run store.",
)


def scheduling_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """Options that choose where evaluations run (not stored: results never depend on them
    in sync mode)."""
    options = [
        click.option("--executor", default=None,
                     help="serial, process or dask (or a plugin's) [serial; process with "
                          "--workers > 1; dask with --scheduler]"),
        click.option("--workers", type=click.IntRange(min=1, max=MAX_WORKERS), default=None,
                     help="Parallel evaluations [all cores for process/dask]."),
        click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
                     help="Join this Dask scheduler (implies --executor dask)."),
    ]  # fmt: skip
    for option in reversed(options):
        command = option(command)
    return command


def build_executor(name: str | None, workers: int | None, scheduler: str | None) -> Executor:
    """The executor the user asked for, with one clear error for a bad combination and a
    warning for more workers than cores. Its ``startup_time`` is the seconds it took to start
    (worker processes, a Dask cluster), counted in the run's wall time."""
    check_executor_options(name, workers, scheduler)
    if name is None and scheduler is None and (workers or 1) == 1:
        return SerialExecutor()  # the default needs no plugin
    if name is None:
        name = "dask" if scheduler else ("process" if workers and workers > 1 else "serial")
    info = registry().executor(name)
    cores = os.cpu_count() or 1
    if workers is not None and workers > cores and scheduler is None:
        errors.print(
            f"Warning: --workers {workers} on {cores} cores: evaluations will share cores and "
            "each takes longer (time limits count that)",
            highlight=False,
        )
    started = time.perf_counter()
    executor = info.factory(workers or (1 if name == "serial" else cores), scheduler)
    executor.startup_time = time.perf_counter() - started
    if executor.dashboard:  # a free port each time, so only this line tells where it is
        missing = executor.dashboard_needs
        note = f" (install {missing} to see it; until then a placeholder)" if missing else ""
        line = f"The {name} executor's dashboard: {executor.dashboard}{note}"
        errors.print(plain(line))
    return executor


def check_executor_options(name: str | None, workers: int | None, scheduler: str | None) -> None:
    """ConfigError for executor options that cannot go together, before anything runs."""
    if scheduler is not None and not SCHEDULER_ADDRESS.fullmatch(scheduler):
        raise ConfigError(
            f"--scheduler {scheduler!r} is not a Dask scheduler address; accepted: "
            "tcp://HOST:PORT (or tls://, ucx://, inproc://) or HOST:PORT"
        )
    if scheduler and name not in (None, "dask"):
        raise ConfigError(f"--scheduler is for the dask executor, not {name!r}")
    if name == "serial" and workers is not None and workers > 1:
        raise ConfigError(
            f"--executor serial runs one evaluation at a time, not --workers {workers}; "
            "use --executor process (or dask) for parallel evaluations"
        )
    if name is not None:
        registry().executor(name)  # an unknown name, with the installed ones


def require_store(db_path: str) -> None:
    """MetaoptError unless a store file exists at db_path (reading commands never create one)."""
    if not Path(db_path).exists():
        raise MetaoptError(f"no run store at {db_path}; run `metaopt run` first or pass --db PATH")


def check_store_path(db_path: str) -> None:
    """StoreError or ConfigError unless a run can store in db_path, creating nothing: an
    existing file is opened as it is (a directory, or a file that is no store, is refused), a
    new one's folder must take files (check_output_file). `metaopt run` checks this first and
    creates its store once every other setting has passed."""
    if Path(db_path).exists():
        RunStore(db_path).close()
    else:
        check_output_file(db_path, "--db")
