"""docs/paper-reproduction.md is exactly what scripts/paper_study.py builds from the committed
result files, and those files agree with each other."""

from __future__ import annotations

import csv
import importlib.util
import statistics
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
SCRIPT = ROOT / "scripts" / "paper_study.py"
OUT = ROOT / "docs" / "paper-reproduction"
DOC = ROOT / "docs" / "paper-reproduction.md"

pytestmark = pytest.mark.skipif(
    not (OUT / "runs.csv").exists(), reason="the study's result files are not committed"
)


@pytest.fixture(scope="module")
def study():
    """The script, imported as a module."""
    spec = importlib.util.spec_from_file_location("paper_study", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["paper_study"] = module
    spec.loader.exec_module(module)
    return module


def read(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def test_report_only_rebuilds_the_committed_document(study):
    assert study.build_report(OUT) == DOC.read_text(), (
        "docs/paper-reproduction.md differs from what its result files give: run "
        "`python scripts/paper_study.py --report-only`"
    )


def test_every_run_has_its_convergence_gait_and_transfer_rows():
    runs = read(OUT / "runs.csv")
    assert runs
    gaits = {row["run"] for row in read(OUT / "gaits.csv")}
    transfer = {row["run"]: row for row in read(OUT / "transfer.csv")}
    for run in runs:
        curve = read(OUT / "convergence" / f"{run['run']}.csv")
        assert int(curve[-1]["evaluations"]) == int(run["evaluations"])
        assert curve[-1]["best_so_far"] == run["best_fitness"]
        bests = [float(row["best_so_far"]) for row in curve]
        assert bests == sorted(bests), "best so far never gets worse"
        assert run["run"] in gaits
        assert transfer[run["run"]]["found_fitness"] == run["best_fitness"]
        assert transfer[run["run"]]["replay_engine"] != run["engine"]
    assert len({run["run"] for run in runs}) == len(runs)


def test_the_documents_medians_are_the_csv_medians():
    text = DOC.read_text()
    runs = read(OUT / "runs.csv")
    for label, engine in {(r["label"], r["engine"]) for r in runs}:
        chosen = [r for r in runs if r["label"] == label and r["engine"] == engine]
        distance = statistics.median(float(r["distance"]) for r in chosen)
        row = next(
            line
            for line in text.splitlines()
            if line.startswith(f"| `{label}` | {'MuJoCo' if engine == 'mujoco' else 'PyBullet'} |")
        )
        assert f"{distance:.3f} (" in row, (label, engine, row)
