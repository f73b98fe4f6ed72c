"""What every metaopt command shares: the consoles, the --db option, the executor options."""

from __future__ import annotations

import os
from pathlib import Path

import click
from rich.console import Console

from metaopt.errors import ConfigError, MetaoptError
from metaopt.executors import Executor, SerialExecutor
from metaopt.plugins import registry
from metaopt.store import DEFAULT_DB

console = Console()
errors = Console(stderr=True, soft_wrap=True)

db_option = click.option(
    "--db",
    "db_path",
    default=DEFAULT_DB,
    show_default=True,
    type=click.Path(dir_okay=False),
    help="SQLite run store.",
)


def scheduling_options(command):
    """Options that choose where evaluations run (not stored: results never depend on them
    in sync mode)."""
    options = [
        click.option("--executor", default=None,
                     help="serial, process or dask (or a plugin's) [serial; process with "
                          "--workers > 1; dask with --scheduler]"),
        click.option("--workers", type=click.IntRange(min=1), default=None,
                     help="Parallel evaluations [all cores for process/dask]."),
        click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
                     help="Join this Dask scheduler (implies --executor dask)."),
    ]  # fmt: skip
    for option in reversed(options):
        command = option(command)
    return command


def build_executor(name: str | None, workers: int | None, scheduler: str | None) -> Executor:
    """The executor the user asked for, with one clear error for a bad combination."""
    if name is None and scheduler is None and (workers or 1) == 1:
        return SerialExecutor()  # the default needs no plugin
    if name is None:
        name = "dask" if scheduler else ("process" if workers and workers > 1 else "serial")
    if scheduler and name != "dask":
        raise ConfigError(f"--scheduler is for the dask executor, not {name!r}")
    info = registry().executor(name)
    default_workers = 1 if name == "serial" else (os.cpu_count() or 1)
    return info.factory(workers or default_workers, scheduler)


def require_store(db_path: str) -> None:
    if not Path(db_path).exists():
        raise MetaoptError(f"no run store at {db_path}; run `metaopt run` first or pass --db PATH")
