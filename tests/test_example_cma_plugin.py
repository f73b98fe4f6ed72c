"""examples/metaopt-cma, installed like any outside package: its tests pass and it beats HS."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from metaopt.storage.run_store import RunStore
from tests.conftest import metaopt_cli, pip_install_isolated

EXAMPLE = Path(__file__).parent.parent / "examples" / "metaopt-cma"


@pytest.fixture(scope="module")
def cma_plugin_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The example, pip-installed into its own directory from a clean copy of its sources."""
    source = tmp_path_factory.mktemp("metaopt-cma-source") / "metaopt-cma"
    shutil.copytree(EXAMPLE, source, ignore=shutil.ignore_patterns("build", "*.egg-info"))
    target = tmp_path_factory.mktemp("metaopt-cma")
    return pip_install_isolated(target, source)


def test_its_own_tests_pass_the_conformance_kit(cma_plugin_path: Path, tmp_path: Path):
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(EXAMPLE / "tests")],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(cma_plugin_path)},
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert " passed" in result.stdout and "skipped" not in result.stdout


def test_it_reaches_a_small_value_on_rosenbrock_well_below_hs(cma_plugin_path: Path, tmp_path):
    db = tmp_path / "runs.db"
    for optimizer in ("pycma", "hs"):
        run = metaopt_cli(
            "run", "-o", optimizer, "-p", "rosenbrock", "--budget", "3000", "--seed", "1",
            "--db", str(db), cwd=tmp_path, extra_path=cma_plugin_path,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr
    with RunStore(db) as store:
        best = {run.optimizer: store.best_evaluation(run).fitness for run in store.runs()}
    # Measured with seed 1: pycma 0.50, hs 10.0 (10-D Rosenbrock, 3000 evaluations).
    assert best["pycma"] < 2.0
    assert best["hs"] > 4 * best["pycma"]
