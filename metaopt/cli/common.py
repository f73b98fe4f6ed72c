"""What every metaopt command shares: the consoles, the --db option, the executor options."""

from __future__ import annotations

import csv
import json
import os
import re
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TextIO

import click
from rich.console import Console

from metaopt.errors import ConfigError, MetaoptError
from metaopt.executors import Executor, SerialExecutor
from metaopt.plugins import registry
from metaopt.store import DEFAULT_DB

#: Output for a file or a pipe is never cut to a terminal's width: tables come out whole.
console = Console() if sys.stdout.isatty() else Console(width=100_000)
errors = Console(stderr=True, soft_wrap=True)
#: Dask scheduler addresses: SCHEME://HOST:PORT for Dask's own schemes, or HOST:PORT (tcp).
SCHEDULER_ADDRESS = re.compile(r"((tcp|tls|ucx|inproc)://)?[^\s/:]+(:\d+)?")

#: More local workers than this is a typing slip, not a machine.
MAX_WORKERS = 1024
OUTPUT_FORMATS = ("table", "csv", "json")
format_option = click.option(
    "--format",
    "fmt",
    type=click.Choice(OUTPUT_FORMATS),
    default="table",
    show_default=True,
    help="table for reading; csv or json (every field, full precision) for programs.",
)

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


def check_output_file(path: str, option: str, suffix: str | None = None) -> Path:
    """ConfigError unless ``path`` can be written as a new or replaced file: not a directory,
    its folder exists and is writable, and it ends in ``suffix`` when one is required. Checked
    before any work, so a bad path never costs a run; nothing is left behind here."""
    target = Path(path)
    if path.endswith(("/", os.sep)) or target.is_dir():
        raise ConfigError(f"{option} {path} is a directory; give a file path")
    if suffix is not None and target.suffix.lower() != suffix:
        raise ConfigError(f"{option} {path}: only {suffix} files are written; give a {suffix} path")
    folder = target.parent
    if not folder.is_dir():
        raise ConfigError(f"{option} {path}: folder {folder} does not exist; create it first")
    _check_writable(folder, option, path)
    if target.exists() and not os.access(target, os.W_OK):
        raise ConfigError(f"{option} {path}: no permission to write that file")
    return target


def check_output_folder(path: Path, option: str) -> None:
    """ConfigError unless ``path`` is, or can be made, a folder to write files in: not a file,
    and its nearest existing ancestor a folder that takes files. Nothing is left behind."""
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{option} {path} is a file; give a folder")
    existing = next(p for p in (path, *path.parents) if p.exists())
    if not existing.is_dir():
        raise ConfigError(f"{option} {path}: {existing} is a file, not a folder")
    _check_writable(existing, option, path)


def _check_writable(folder: Path, option: str, path: Path | str) -> None:
    """The one sure test of a folder (permissions, read-only mounts, /proc): write in it."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise ConfigError(f"{option} {path}: cannot write in {folder} ({error.strerror})") from None


@contextmanager
def written_whole(path: Path) -> Iterator[TextIO]:
    """A text handle whose content lands at ``path`` only when the block succeeds: written to
    a temporary file beside it and renamed, so a failure never leaves a half-written file."""
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(temporary, 0o666 & ~umask)  # as open() would make it, not mkstemp's 0600
    try:
        with open(descriptor, "w", newline="") as handle:
            yield handle
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def print_records(records: list[dict[str, Any]] | dict[str, Any], fmt: str) -> None:
    """Records (or one record) on stdout as JSON, or as CSV: one column per key, nested
    values as JSON."""
    if fmt == "json":
        json.dump(records, sys.stdout, indent=1)
        sys.stdout.write("\n")
        return
    if isinstance(records, dict):
        records = [records]
    fields = list(dict.fromkeys(key for record in records for key in record))
    writer = csv.DictWriter(sys.stdout, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for record in records:
        writer.writerow(
            {k: json.dumps(v) if isinstance(v, dict | list) else v for k, v in record.items()}
        )


def require_store(db_path: str) -> None:
    """MetaoptError unless a store file exists at db_path (reading commands never create one)."""
    if not Path(db_path).exists():
        raise MetaoptError(f"no run store at {db_path}; run `metaopt run` first or pass --db PATH")
