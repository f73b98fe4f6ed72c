"""`metaopt robustness-rank`: the candidates of a robustness CSV ranked again against goals,
from the file alone, by the margins `metaopt robustness --goal` ranks by."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from tests.conftest import metaopt_cli, one_error_line

GOALS = ("--goal", "speed>=0.44", "--goal", "|drift|<=0.3")
GAITS = ("goal_walk", "steered_walk", "robust_walk")


@pytest.fixture(scope="module")
def race(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three stored gaits over the nominal cell on MuJoCo and ODE, one seed, ranked by GOALS:
    the table and the ranking that `metaopt robustness` wrote."""
    where = tmp_path_factory.mktemp("race")
    done = metaopt_cli("robustness", *GAITS, "--engines", "mujoco+ode", "--cells", "nominal",
                       "--seeds", "1", *GOALS, "--csv", "race.csv", "--ranking", "ranking.csv",
                       cwd=where)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return where


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def test_the_same_goals_give_robustness_own_ranking_and_margins(race: Path) -> None:
    done = metaopt_cli("robustness-rank", "race.csv", *GOALS, "--ranking", "again.csv", cwd=race)
    assert done.returncode == 0, done.stderr
    own, again = _rows(race / "ranking.csv"), _rows(race / "again.csv")
    assert [r["candidate"] for r in again] == [r["candidate"] for r in own]
    for mine, theirs in zip(again, own, strict=True):
        assert float(mine["goal_margin"]) == float(theirs["goal_margin"])
        assert (mine["goals_missed"], mine["meets_goals"]) == (
            theirs["goals_missed"], theirs["meets_goals"])  # fmt: skip
        assert mine["source"] == "race.csv"


def test_other_goals_rank_by_their_own_margins(race: Path) -> None:
    """A slower speed bound and a tight drift bound: the order follows each candidate's
    smallest margin under these goals, computed here from the CSV's whole-table rows, and it
    is not the file's (steered_walk, second by GOALS, walks straightest)."""
    whole = [r for r in _rows(race / "race.csv") if r["cell"] == "whole table"]

    def margin(label: str) -> float:
        rows = [r for r in whole if r["candidate"] == label]
        speed = [(float(r["speed_median"]) - 0.2) / 0.2 for r in rows]
        drift = [(0.05 - float(r["|drift|_median"])) / 0.05 for r in rows]
        return min(speed + drift)

    expected = sorted(GAITS, key=lambda label: -margin(label))
    done = metaopt_cli("robustness-rank", "race.csv", "--goal", "speed>=0.2", "--goal",
                       "|drift|<=0.05", "--ranking", "other.csv", cwd=race)  # fmt: skip
    assert done.returncode == 0, done.stderr
    ranked = _rows(race / "other.csv")
    assert [r["candidate"] for r in ranked] == expected
    assert expected != [r["candidate"] for r in _rows(race / "ranking.csv")]
    assert [float(r["goal_margin"]) for r in ranked] == [margin(label) for label in expected]
    assert expected[0] in done.stdout and "misses" in done.stdout


def test_several_files_rank_together_each_candidate_named_with_its_file(race: Path) -> None:
    """Two races' tables pooled: every candidate of both, ranked as one, the file beside it."""
    (race / "copy.csv").write_bytes((race / "race.csv").read_bytes())
    done = metaopt_cli("robustness-rank", "race.csv", "copy.csv", *GOALS, "--ranking",
                       "pooled.csv", cwd=race)  # fmt: skip
    assert done.returncode == 0, done.stderr
    pooled = _rows(race / "pooled.csv")
    own = [r["candidate"] for r in _rows(race / "ranking.csv")]
    assert [r["candidate"] for r in pooled] == [label for label in own for _ in (1, 2)]
    assert [r["source"] for r in pooled[:2]] == ["race.csv", "copy.csv"]  # ties: file order
    assert "file" in done.stdout


def test_bad_input_is_refused_in_one_line(race: Path, tmp_path: Path) -> None:
    (tmp_path / "not.csv").write_text("a,b\n1,2\n")
    one_error_line(metaopt_cli("robustness-rank", "not.csv", *GOALS, cwd=tmp_path),
                   "not a robustness table")  # fmt: skip
    one_error_line(metaopt_cli("robustness-rank", str(race / "race.csv"), "--goal", "pace>=1",
                               cwd=tmp_path), "goal 'pace>=1'", "speed")  # fmt: skip
    one_error_line(metaopt_cli("robustness-rank", str(race / "race.csv"), cwd=tmp_path),
                   "--goal")  # fmt: skip
    assert list(tmp_path.iterdir()) == [tmp_path / "not.csv"]
