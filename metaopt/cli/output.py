"""What commands write: the --format option, records as CSV or JSON, and output paths checked
before any work (storage.whole_file then writes them whole or not at all)."""

from __future__ import annotations

import csv
import json
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from metaopt.errors import ConfigError
from metaopt.storage.export import dump_json, finite_json
from metaopt.storage.whole_file import check_regular

OUTPUT_FORMATS = ("table", "csv", "json")
format_option = click.option(
    "--format",
    "fmt",
    type=click.Choice(OUTPUT_FORMATS),
    default="table",
    show_default=True,
    help="table for reading; csv or json (every field, full precision) for programs.",
)


def check_output_file(path: str, option: str, suffix: str | None = None) -> Path:
    """ConfigError unless ``path`` can be written as a new or replaced file: not a directory,
    its folder exists and is writable, and it ends in ``suffix`` when one is required. Checked
    before any work, so a bad path never costs a run; nothing is left behind here."""
    target = Path(path)
    if path.endswith(("/", os.sep)) or target.is_dir():
        raise ConfigError(f"{option} {path} is a directory; give a file path")
    if suffix is not None and target.suffix.lower() != suffix:
        raise ConfigError(f"{option} {path}: only {suffix} files are written; give a {suffix} path")
    folder = Path(os.path.realpath(path)).parent  # a symlink is written where it points
    if not folder.is_dir():
        raise ConfigError(f"{option} {path}: folder {folder} does not exist; create it first")
    _check_writable(folder, option, path)
    check_regular(target)  # a FIFO or device: written whole, it would be replaced
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


def output_file_option(flag: str, dest: str, help: str, suffix: str | None = None) -> Callable:
    """A click option naming a file a command writes: checked by check_output_file as the
    command line is read, before any work, and passed on as a Path (None when not given)."""

    def checked(ctx: click.Context, param: click.Parameter, value: str | None) -> Path | None:
        return None if value is None else check_output_file(value, flag, suffix)

    return click.option(
        flag, dest, type=click.Path(dir_okay=False), default=None, callback=checked, help=help
    )


def print_records(records: list[dict[str, Any]] | dict[str, Any], fmt: str) -> None:
    """Records (or one record) on stdout as JSON, or as CSV: one column per key, nested
    values as strict JSON (see finite_json)."""
    if fmt == "json":
        dump_json(records, sys.stdout)
        return
    if isinstance(records, dict):
        records = [records]
    fields = list(dict.fromkeys(key for record in records for key in record))
    writer = csv.DictWriter(sys.stdout, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for record in records:
        writer.writerow({key: _csv_cell(value) for key, value in record.items()})


def _csv_cell(value: Any) -> Any:
    """A nested value as strict JSON (see finite_json); anything else as csv writes it."""
    if isinstance(value, dict | list):
        return json.dumps(finite_json(value), allow_nan=False)
    return value
