"""`metaopt robustness-summary`: several searches' tables (each search's chosen candidate over
the perturbation table, as `metaopt robustness --csv` writes it) summarised per engine as the
median over the searches, checked against goals; bad input is one clear line."""

from __future__ import annotations

import csv
import re
import statistics
from pathlib import Path

import numpy as np
import pytest

from metaopt.assessment.candidates import Candidate
from metaopt.assessment.robustness import CellResult, PerturbationTable, whole_table, write_csv
from metaopt_problems.nao_walk.robustness import STANDARD_TABLE
from tests.conftest import metaopt_cli, one_error_line

TABLE = PerturbationTable("t-1", (), ("speed", "|drift|", "fell", "flight"))
GOALS = ("--goal", "speed>=0.44", "--goal", "fell<=0.05", "--goal", "|drift|<=0.3")


def _search(path: Path, label: str, speeds: dict[str, list[float]], falls: int = 0,
            table: PerturbationTable = TABLE, failed: int = 0) -> None:  # fmt: skip
    """A search's table over two cells: ``speeds`` per engine (half in each cell), drift of a
    tenth of the speed, the first ``falls`` episodes on 'ode' fallen."""
    results = []
    for engine, values in speeds.items():
        samples = [
            {"speed": v, "drift": -v / 10, "fell": float(engine == "ode" and i < falls),
             "flight": 0.01} for i, v in enumerate(values)
        ]  # fmt: skip
        for i, sample in enumerate(samples):
            if sample["fell"]:
                sample["time_to_fall"] = 2.0 + i  # reported by the episodes that fell alone
        half = len(samples) // 2
        results += [CellResult("nominal", engine, samples[:half], 0, [1.0] * half),
                    CellResult("push", engine, samples[half:], failed, [1.0] * half)]  # fmt: skip
    write_csv(
        path, table, [(Candidate(label, "p", {}, np.zeros(1)), [*results, *whole_table(results)])]
    )


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def test_the_summary_is_the_median_over_the_searches_of_each_whole_table_figure(
    tmp_path: Path,
) -> None:
    speeds = {
        "s1.csv": {"mujoco": [0.5, 0.6, 0.7, 0.8], "ode": [0.3, 0.4, 0.5, 0.6]},
        "s2.csv": {"mujoco": [0.4, 0.4, 0.5, 0.5], "ode": [0.5, 0.5, 0.5, 0.5]},
        "s3.csv": {"mujoco": [0.2, 0.3, 0.3, 0.9], "ode": [0.6, 0.7, 0.8, 0.9]},
    }
    falls = {"s1.csv": 0, "s2.csv": 1, "s3.csv": 2}
    for name, per_engine in speeds.items():
        _search(tmp_path / name, f"run {name[1]}", per_engine, falls[name])
    done = metaopt_cli("robustness-summary", *speeds, *GOALS, "--csv", "out.csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    rows = _rows(tmp_path / "out.csv")
    medians = {r["engine"]: r for r in rows if r["search"] == "median of 3"}
    for engine in ("mujoco", "ode"):
        per_search = [statistics.median(s[engine]) for s in speeds.values()]
        assert float(medians[engine]["speed"]) == pytest.approx(statistics.median(per_search))
        drift = [statistics.median(v / 10 for v in s[engine]) for s in speeds.values()]
        assert float(medians[engine]["|drift|"]) == pytest.approx(statistics.median(drift))
    # ode's fall rates are 0, 1/4 and 2/4: their median is 1/4
    assert float(medians["ode"]["fell"]) == pytest.approx(0.25)
    # the spread over the searches: each figure's sample standard deviation over them
    spreads = {r["engine"]: r for r in rows if r["search"] == "sd over 3"}
    for engine in ("mujoco", "ode"):
        per_search = [statistics.median(s[engine]) for s in speeds.values()]
        assert float(spreads[engine]["speed"]) == pytest.approx(statistics.stdev(per_search))
    assert float(spreads["ode"]["fell"]) == pytest.approx(0.25)  # 0, 1/4, 2/4
    assert float(spreads["mujoco"]["fell"]) == 0.0
    shown = re.search(r"sd over 3\s*│\s*│\s*ode\s*│\s*(\S+)", done.stdout)
    assert shown and float(shown[1]) == pytest.approx(statistics.stdev([0.45, 0.5, 0.75]), abs=5e-4)
    assert [(r["search"], r["engine"]) for r in rows[:2]] == [("s1.csv", "mujoco"),
                                                              ("s1.csv", "ode")]  # fmt: skip
    # mujoco's medians: speeds 0.65, 0.45, 0.3 -> 0.45; ode: 0.45, 0.5, 0.75 -> 0.5, falls 25 %
    assert "mujoco: meets all" in done.stdout
    assert "ode: misses fell<=0.05 (0.25)" in done.stdout
    # s1 meets every goal on both engines; s2 falls on ode; s3 is slow on mujoco
    assert "meets every goal on every engine: 1 of 3 (s1.csv)" in done.stdout


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda d: (d / "b.csv").write_text("a,b\n1,2\n"), "b.csv: not a robustness table"),
        (lambda d: _search(d / "b.csv", "run 2", {"mujoco": [0.5, 0.5]},
                           table=PerturbationTable("t-2", (), TABLE.metrics)),
         "b.csv has table version t-2, a.csv t-1"),
        (lambda d: _search(d / "b.csv", "run 2", {"ode": [0.5, 0.5]}),
         "b.csv has engines ['ode'], a.csv ['mujoco']"),
        (lambda d: None, "b.csv: no such file"),
    ],
    ids=["not a robustness table", "another version", "other engines", "missing"],
)  # fmt: skip
def test_unlike_or_bad_tables_are_one_clear_error(tmp_path: Path, make, message: str) -> None:
    _search(tmp_path / "a.csv", "run 1", {"mujoco": [0.5, 0.5]})
    make(tmp_path)
    done = metaopt_cli("robustness-summary", "a.csv", "b.csv", "--csv", "out.csv", cwd=tmp_path)
    assert done.returncode == 2, done.stdout
    assert "Traceback" not in done.stderr and message in done.stderr
    assert not (tmp_path / "out.csv").exists()


def test_tables_from_before_a_metric_joined_their_version_are_compared_on_those_they_share(
    tmp_path: Path,
) -> None:
    """nao-walk-3's time_to_fall came after its first tables: a summary over older and newer
    tables of one version compares them on the metrics every one has, and a metric no episode
    of a search measured (no fall: no time_to_fall) is left out of the median over searches."""
    newer = PerturbationTable("t-1", (), (*TABLE.metrics, "time_to_fall"))
    speeds = {"mujoco": [0.5, 0.6, 0.5, 0.6], "ode": [0.5, 0.5, 0.6, 0.6]}
    _search(tmp_path / "new.csv", "run 1", speeds, falls=3, table=newer)  # times 2, 3, 4: 3
    _search(tmp_path / "steady.csv", "run 2", speeds, falls=0, table=newer)
    _search(tmp_path / "old.csv", "run 3", speeds, falls=1)
    # baselines of the same figures as the searches, in files of their own
    _search(tmp_path / "new-base.csv", "run 4", speeds, falls=3, table=newer)
    _search(tmp_path / "steady-base.csv", "run 5", speeds, falls=0, table=newer)
    _search(tmp_path / "old-base.csv", "run 6", speeds, falls=1)
    both = metaopt_cli("robustness-summary", "new.csv", "steady.csv", "--csv", "n.csv",
                       cwd=tmp_path)  # fmt: skip
    assert both.returncode == 0, both.stderr
    rows = _rows(tmp_path / "n.csv")
    # new, steady, their median, their sd: one search measured it, so no spread
    ode = [r["time_to_fall"] for r in rows if r["engine"] == "ode"]
    assert ode == ["3.0", "nan", "3.0", "nan"]
    assert "–" in both.stdout and "nan" not in both.stdout  # the steady one's: none fell
    steady = metaopt_cli("robustness-summary", "steady.csv", "--against", "steady-base.csv",
                         cwd=tmp_path)  # fmt: skip
    assert steady.returncode == 0, steady.stderr
    assert "nan" not in steady.stdout  # no pair measured time_to_fall: a dash, not +nan
    assert re.search(r"ode\s.*│\s+–\s+│", steady.stdout.split("pair by pair")[1])
    mixed = metaopt_cli("robustness-summary", "new.csv", "old.csv", "--against", "old-base.csv",
                        "--against", "new-base.csv", "--csv", "m.csv", cwd=tmp_path)  # fmt: skip
    assert mixed.returncode == 0, mixed.stderr
    rows = _rows(tmp_path / "m.csv")
    assert list(rows[0]) == ["search", "candidate", "engine", "failed", *TABLE.metrics]
    assert "time_to_fall" not in mixed.stdout
    paired = {r["engine"]: r for r in rows if r["search"] == "median difference of 2 pairs"}
    assert float(paired["ode"]["fell"]) == pytest.approx(0.0)  # +0.5 and -0.5 pair off


def test_a_goal_on_the_time_to_fall_is_met_by_a_search_whose_gait_never_fell(
    tmp_path: Path,
) -> None:
    """On the installed table (nao-walk-3 declares time_to_fall measured where a gait fell),
    a search whose gait never fell meets time_to_fall>=3.5; one whose ode episodes fell at 2,
    3 and 4 s misses it there (median 3 s), and meets it on mujoco, where none fell."""
    table = PerturbationTable(STANDARD_TABLE.version, (), (*TABLE.metrics, "time_to_fall"))
    speeds = {"mujoco": [0.5, 0.6, 0.5, 0.6], "ode": [0.5, 0.5, 0.6, 0.6]}
    _search(tmp_path / "steady.csv", "run 1", speeds, falls=0, table=table)
    _search(tmp_path / "early.csv", "run 2", speeds, falls=3, table=table)
    for name, verdict in (("steady.csv", "meets all"), ("early.csv", "misses time_to_fall")):
        done = metaopt_cli("robustness-summary", name, "--goal", "time_to_fall>=3.5",
                           cwd=tmp_path)  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert "mujoco: meets all" in done.stdout
        assert f"ode: {verdict}" in done.stdout
    ranked = metaopt_cli("robustness-rank", "early.csv", "steady.csv", "--goal",
                         "time_to_fall>=3.5", cwd=tmp_path)  # fmt: skip
    assert ranked.returncode == 0, ranked.stderr
    assert ranked.stdout.index("steady.csv") < ranked.stdout.index("early.csv")


def test_a_table_of_several_candidates_is_refused(tmp_path: Path) -> None:
    """A race's table ranks several candidates; a search's result is its one chosen."""
    rows = [CellResult("nominal", "mujoco", [{"speed": 0.5, "drift": 0.0, "fell": 0.0,
                                              "flight": 0.0}], 0, [1.0])]  # fmt: skip
    write_csv(tmp_path / "race.csv", TABLE, [
        (Candidate(label, "p", {}, np.zeros(1)), [*rows, *whole_table(rows)])
        for label in ("run 1 candidate 3", "run 2 candidate 7")
    ])  # fmt: skip
    done = metaopt_cli("robustness-summary", "race.csv", cwd=tmp_path)
    assert done.returncode == 2
    assert "race.csv: holds 2 candidates (run 1 candidate 3, run 2 candidate 7)" in done.stderr


def test_one_search_has_no_spread_to_show(tmp_path: Path) -> None:
    """A standard deviation needs two searches: with one, every figure's is a dash (NaN in the
    CSV), a rate's too, never a number made up."""
    _search(tmp_path / "s1.csv", "run 1", {"mujoco": [0.5, 0.6]}, falls=0)
    done = metaopt_cli("robustness-summary", "s1.csv", "--csv", "out.csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert re.search(r"sd over 1\s*│\s*│\s*mujoco\s*│\s*–\s*│\s*–\s*│\s*–", done.stdout)
    spread = next(r for r in _rows(tmp_path / "out.csv") if r["search"] == "sd over 1")
    assert all(np.isnan(float(spread[m])) for m in ("speed", "|drift|", "fell", "flight"))


def test_a_failed_evaluation_misses_every_goal_on_its_engine(tmp_path: Path) -> None:
    """Both searches walk 0.5 m/s without a fall, within both goals; one evaluation of s2
    failed, so the medians miss both (a failure counts as outside every bound)."""
    for name in ("s1.csv", "s2.csv"):
        _search(tmp_path / name, name, {"mujoco": [0.5, 0.5]}, failed=int(name == "s2.csv"))
    done = metaopt_cli("robustness-summary", "s1.csv", "s2.csv", "--goal", "speed>=0.44",
                       "--goal", "fell<=0.05", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "mujoco: misses speed>=0.44 (0.5), fell<=0.05 (0)" in done.stdout
    assert "mujoco (1 failed)" in done.stdout
    assert "meets every goal on every engine: 1 of 2 (s1.csv)" in done.stdout


def test_against_gives_the_median_paired_difference_and_the_sign_test(tmp_path: Path) -> None:
    """Three searches, each against its baseline on the same seed: every later table walks
    faster on mujoco (by 0.1, 0.02 and 0.05), two fall more on ode; the median differences
    are 0.05 m/s and 50 percentage points, the 3-0 split's two-sided sign test p = 2/8."""
    base = {"mujoco": [0.4, 0.4], "ode": [0.5, 0.5]}
    later = {"mujoco": [0.5, 0.42, 0.45], "falls": [0, 1, 1]}
    for i in range(3):
        _search(tmp_path / f"b{i}.csv", f"run {i}", base)
        faster = {"mujoco": [later["mujoco"][i]] * 2, "ode": [0.5, 0.5]}
        _search(tmp_path / f"l{i}.csv", f"run {i}", faster, falls=later["falls"][i])
    tables = [f"l{i}.csv" for i in range(3)]
    against = [arg for i in range(3) for arg in ("--against", f"b{i}.csv")]
    done = metaopt_cli("robustness-summary", *tables, *against, "--csv", "out.csv",
                       cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    (mujoco, ode) = [r for r in _rows(tmp_path / "out.csv")
                     if r["search"] == "median difference of 3 pairs"]  # fmt: skip
    assert float(mujoco["speed"]) == pytest.approx(0.05)
    assert float(ode["fell"]) == pytest.approx(0.5)  # falls 0, 1 and 1 of 2: 0, 50 and 50 %
    assert float(ode["speed"]) == 0.0
    assert "+0.050 (3↑ 0↓, p 0.25)" in done.stdout
    assert "+50.0 pp (2↑ 0↓, p 0.50)" in done.stdout
    assert "+0.000 (0↑ 0↓, p 1.00)" in done.stdout  # ode's speed: three ties
    unpaired = metaopt_cli("robustness-summary", *tables, "--against", "b0.csv", cwd=tmp_path)
    assert unpaired.returncode == 2
    assert "3 tables against 1: give one --against table per table" in unpaired.stderr


def test_the_figure_draws_each_search_at_its_fall_rate_and_speed_against_the_goals(
    tmp_path: Path,
) -> None:
    """One panel per engine: each search's whole-table fall rate and median speed, the search
    within every goal filled, the median over the searches as the cross, the goals on speed
    and falls as the bounds; the command writes it as a PNG beside its table."""
    from metaopt.assessment import robustness, search_medians

    speeds = {"s1.csv": 0.5, "s2.csv": 0.4, "s3.csv": 0.6}
    falls = {"s1.csv": 0, "s2.csv": 0, "s3.csv": 2}  # of 4 ode episodes: 0, 0 and 50 %
    for name, speed in speeds.items():
        _search(tmp_path / name, name, {"mujoco": [speed] * 4, "ode": [speed] * 4}, falls[name])
    tables = [search_medians.read_table(tmp_path / name) for name in speeds]
    goals = [robustness.parse_goal(g, TABLE.metrics, "t-1") for g in GOALS[1::2]]
    drawn = search_medians.figure(tables, search_medians.medians(tables), goals)
    panels = drawn.axes
    assert [ax.get_title() for ax in panels] == ["mujoco", "ode"]
    for ax, engine in zip(panels, ("mujoco", "ode"), strict=True):
        hollow, filled, median = (c.get_offsets().tolist() for c in ax.collections)
        ode_falls = {"s1.csv": 0.0, "s2.csv": 0.0, "s3.csv": 0.5}
        fell = {name: ode_falls[name] if engine == "ode" else 0.0 for name in speeds}
        # only s1 meets every goal on every engine: s2 is slow, s3 falls on ode
        assert filled == [[fell["s1.csv"], 0.5]]
        assert sorted(hollow) == sorted([[fell["s2.csv"], 0.4], [fell["s3.csv"], 0.6]])
        assert median == [[statistics.median(fell.values()), 0.5]]
        assert any(list(line.get_ydata()) == [0.44, 0.44] for line in ax.lines)  # speed bound
        assert any(list(line.get_xdata()) == [0.05, 0.05] for line in ax.lines)  # falls bound
    done = metaopt_cli("robustness-summary", *speeds, *GOALS, "--figure", "searches.png",
                       cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "searches.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_figure_of_a_table_without_a_fall_rate_is_refused_before_any_file(
    tmp_path: Path,
) -> None:
    """Speed is drawn against a fall rate: a table without one is one clear line (exit 2),
    and neither the CSV nor the figure is written."""
    table = PerturbationTable("t-1", (), ("speed", "|drift|"))
    _search(tmp_path / "a.csv", "run 1", {"mujoco": [0.5, 0.5]}, table=table)
    done = metaopt_cli("robustness-summary", "a.csv", "--csv", "out.csv", "--figure", "f.png",
                       cwd=tmp_path)  # fmt: skip
    assert done.returncode == 2, done.stdout
    assert "Traceback" not in done.stderr and "has no fall rate" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out.csv").exists() and not (tmp_path / "f.png").exists()


def test_a_table_given_twice_is_refused_not_counted_as_two_searches(tmp_path: Path) -> None:
    """The same file twice would pass for two independent searches ("sd over 2"): refused in
    one line by robustness-summary (CSV and --against) and robustness-rank, however written."""
    for name in ("s1.csv", "s2.csv"):
        _search(tmp_path / name, "run 1", {"mujoco": [0.5, 0.6]})
    for args, needle in (
        (("robustness-summary", "s1.csv", "./s1.csv"), "s1.csv is given twice"),
        (("robustness-summary", "s1.csv", "s2.csv", "--against", "s2.csv", "--against",
          "s2.csv"), "--against s2.csv is given twice"),
        (("robustness-rank", "s1.csv", "s1.csv", "--goal", "speed>=0.4"),
         "s1.csv is given twice"),
    ):  # fmt: skip
        one_error_line(metaopt_cli(*args, cwd=tmp_path), needle)


def test_a_search_given_against_itself_is_refused_not_paired_with_itself(tmp_path: Path) -> None:
    """A search's table also given as a baseline (--against), however written ('./', a
    symlink), was paired with itself (every difference 0, shown as a comparison) or stood for
    both designs: refused in one line, nothing written."""
    for name in ("s1.csv", "s2.csv", "s3.csv"):
        _search(tmp_path / name, "run 1", {"mujoco": [0.5, 0.6]})
    (tmp_path / "link.csv").symlink_to("s1.csv")
    for args in (
        ("s1.csv", "--against", "s1.csv"),
        ("s1.csv", "--against", "./s1.csv"),
        ("s1.csv", "s2.csv", "--against", "s3.csv", "--against", "link.csv"),
    ):
        done = metaopt_cli("robustness-summary", *args, "--csv", "out.csv", cwd=tmp_path)
        one_error_line(done, f"--against {Path(args[-1])} is also given as a search", "give each")
    assert not (tmp_path / "out.csv").exists()


def test_robustness_summary_names_a_written_path_with_brackets_as_it_is(tmp_path: Path) -> None:
    """'wrote PATH' prints the path as written, not as rich markup ('[final]' kept)."""
    _search(tmp_path / "s1.csv", "run 1", {"mujoco": [0.5, 0.6]})
    done = metaopt_cli("robustness-summary", "s1.csv", "--csv", "m[final].csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "wrote m[final].csv" in done.stdout
    assert (tmp_path / "m[final].csv").exists()


def test_robustness_summary_shows_labels_and_paths_as_typed_whatever_their_characters(
    tmp_path: Path,
) -> None:
    """rich's escape doubles a trailing backslash wherever no tag follows ('gait\\' showed as
    'gait\\\\' in the table) and leaves emoji codes to rich (':cd:' in a path showed as a CD):
    a table cell, 'wrote PATH' and an Error line show the label and the paths as typed."""
    _search(tmp_path / "s:cd:1.csv", "gait\\", {"mujoco": [0.5, 0.6]})
    done = metaopt_cli("robustness-summary", "s:cd:1.csv", "--csv", "m:cd:\\[x].csv",
                       cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert re.search(r"│ s:cd:1\.csv\s+│ gait\\ ", done.stdout), done.stdout
    assert "wrote m:cd:\\[x].csv" in done.stdout
    assert (tmp_path / "m:cd:\\[x].csv").exists()
    one_error_line(metaopt_cli("robustness-summary", "no:cd:.csv", cwd=tmp_path),
                   "Error: no:cd:.csv: no such file")  # fmt: skip
