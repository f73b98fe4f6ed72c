"""Shared fixtures: an isolated install of the outside example plugin, CLI helpers, and stored
evaluations for the reporting tests."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from metaopt.storage.run_store import EvaluationRecord

FIXTURES = Path(__file__).parent / "fixtures"
ROOT = Path(__file__).parents[1]


def load_script(relative: str) -> ModuleType:
    """A script of the repository (e.g. "scripts/engine_transfer.py") imported as a module, to
    test its functions; it is registered under its file name so dataclasses in it work."""
    path = ROOT / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = sys.modules[path.stem] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def pip_install_isolated(target: Path, *sources: Path) -> Path:
    """pip-install packages into ``target`` (put it on PYTHONPATH), not into site-packages."""
    subprocess.run(
        [
            sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
            "--no-build-isolation", "--target", str(target), *map(str, sources),
        ],
        check=True,
        capture_output=True,
    )  # fmt: skip
    return target


@pytest.fixture(scope="session")
def outside_plugin_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The example plugin package, pip-installed into its own directory (not site-packages)."""
    return pip_install_isolated(
        tmp_path_factory.mktemp("outside_plugin"), FIXTURES / "outside_plugin"
    )


def metaopt_cli(
    *args: str, cwd: Path, extra_path: Path | None = None, env: dict | None = None
) -> subprocess.CompletedProcess:
    """Run the real `metaopt` command in a subprocess; env values of None unset a variable."""
    environment = {**os.environ, "COLUMNS": "200", **(env or {})}
    environment = {key: value for key, value in environment.items() if value is not None}
    if extra_path is not None:
        environment["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(extra_path), environment.get("PYTHONPATH", "")) if p
        )
    return subprocess.run(
        [sys.executable, "-m", "metaopt", *args],
        cwd=cwd,
        env=environment,
        capture_output=True,
        text=True,
        timeout=600,
    )


def evaluation_record(index: int, fitness: float | None, **metrics: float) -> EvaluationRecord:
    """A stored evaluation as the run store reads it back: failed (status and error) when
    ``fitness`` is None, with these metrics."""
    failed = fitness is None
    return EvaluationRecord(
        index, index, np.zeros(2), fitness, metrics, "failed" if failed else "ok",
        "boom" if failed else None, index, 0.1, 0.0,
    )  # fmt: skip


def one_error_line(done: subprocess.CompletedProcess, *needles: str) -> str:
    """The single stderr line of a refused command (exit 2, no traceback), holding needles."""
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), done.stderr
    assert "Traceback" not in done.stdout + done.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]
