"""scripts/paper_study.py: the two analyses the paper's study keeps outside metaopt (Table 2's
swing bounds, the rhythm of each cell's best gaits), on a real tiny experiment."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import ROOT, load_script, metaopt_cli

EXPERIMENTS = ROOT / "docs" / "paper-reproduction" / "experiments"


@pytest.fixture(scope="module")
def study():
    return load_script("scripts/paper_study.py")


def test_the_study_files_are_valid_experiments() -> None:
    from metaopt.comparison.experiment import load_experiment
    from metaopt.plugins import registry

    files = sorted(EXPERIMENTS.glob("*.toml"))
    assert {f.stem for f in files} >= {"paper-study", "paper-slip", "paper-noise"}
    for path in files:
        experiment = load_experiment(path, registry())
        assert experiment.problem == "nao-walk" and len(experiment.seeds) >= 5


def test_swing_bounds_are_deterministic_and_scale_with_the_weights(study) -> None:
    bounds = study.swing_bounds(samples=20, seed=3)
    assert bounds == study.swing_bounds(samples=20, seed=3)
    assert 0 < bounds["oscillating_fraction"] < 1
    assert bounds["hip_swing_median"] == pytest.approx(4 * bounds["y_swing_median"])
    assert bounds["y_swing_median"] <= bounds["y_swing_p90"] <= bounds["y_swing_max"]


def test_rhythms_of_a_tiny_experiment(study, tmp_path: Path) -> None:
    (tmp_path / "tiny.toml").write_text(
        'name = "tiny"\nproblem = "nao-walk"\nseeds = 2\n'
        '[problem_settings]\nbackend = "ode"\nduration = 6.0\n'
        '[[optimizers]]\nname = "random"\nbudget = 3\n'
    )
    done = metaopt_cli("compare", "tiny.toml", "--db", "t.db", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    table = study.rhythms_table([tmp_path / "tiny.toml"], tmp_path / "t.db").splitlines()
    assert len(table) == 3 and table[2].startswith("| tiny | random | - | 2 |")
