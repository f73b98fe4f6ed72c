"""The robust-walk search script refuses a bad knob in one line, before any work is done."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[1] / "docs" / "robustness" / "robust-walk-search.sh"

pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="the script is bash")


def refusal(tmp_path: Path, path: str, knob: str, value: str, **knobs: str) -> str:
    """The one stderr line of the script run with knob=value (and knobs) and PATH=path; asserts
    that it exits 2 and leaves the working folder empty (no store, no CSV: refused before any
    work)."""
    done = subprocess.run(
        ["bash", str(SCRIPT), "7"],
        cwd=tmp_path,
        env={"PATH": path, knob: value, **knobs},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert list(tmp_path.iterdir()) == []
    return lines[0]


@pytest.mark.parametrize(
    ("knob", "value", "accepted"),
    [
        ("PIPELINES", "abc", "a whole number, 1 or more"),
        ("PIPELINES", "-1", "a whole number, 1 or more"),
        ("STAGE1_RUNS", "0", "a whole number, 1 or more"),
        ("STAGE1_RUNS", "00", "a whole number, 1 or more"),
        ("STAGE1B_START", "best", "raced, all or pool"),
        ("BASIN_FELL", "1.5", "a fall rate from 0 to 1"),
        ("BASIN_FELL", "-0.1", "a fall rate from 0 to 1"),
        ("BASIN_FELL", "5%", "a fall rate from 0 to 1"),
        ("RACE_FELL", "0,05", "a fall rate from 0 to 1"),
        ("DEADLINE", "30m", "a whole number, 1 or more"),
        ("LATER_STAGES", "6m", "a whole number, 1 or more"),
        ("LATER_STAGES", "automatic", "a whole number, 1 or more, or auto"),
        ("STAGE1_TIME", "0", "a whole number, 1 or more"),
        ("RACE_SEEDS", "ten", "a whole number, 1 or more"),
        ("RECHECK_LAST", "1k", "a whole number, 1 or more"),
        ("FLAT_BEST", "1m", "a fitness in metres, 0 or more"),
        ("FLAT_BEST", "-1", "a fitness in metres, 0 or more"),
        ("FLAT_FELL", "90%", "a share of candidates from 0 to 1"),
        ("FLAT_FELL", "1.5", "a share of candidates from 0 to 1"),
        ("TRIALS", "two", "a whole number, 1 or more"),
        ("TRIAL_TIME", "5m", "a whole number, 1 or more"),
        ("FINALS", "8,9", "whole numbers 1 or more separated by spaces"),
        ("FINALS", "", "whole numbers 1 or more separated by spaces"),
        ("FINALS", "0", "whole numbers 1 or more separated by spaces"),
    ],
)
def test_a_bad_knob_stops_the_search_with_one_line(tmp_path, knob, value, accepted):
    """PATH holds no metaopt: a check that let the value through would end in exit 127."""
    line = refusal(tmp_path, "/usr/bin:/bin", knob, value)
    assert knob in line and accepted in line and repr(value) in line


def test_finals_run_the_later_stages_on_a_searchs_store_and_say_where_it_is_missing(tmp_path):
    """FINALS skips stages 1 and 1b: without the search's store there is nothing to choose
    from, and PATH holds no metaopt, so no stage was started before the refusal."""
    line = refusal(tmp_path, "/usr/bin:/bin", "FINALS", "8")
    assert "FINALS runs the later stages on a search's store: no robust-walk-s7.db here" in line


def test_a_deadline_needs_every_stage_1_first(tmp_path):
    """Stage 1b's share of the time left is known only once every stage 1 has run."""
    line = refusal(tmp_path, "/usr/bin:/bin", "DEADLINE", "1800")
    assert "DEADLINE needs STAGE1B_START=pool" in line and "raced" in line


def test_a_stage_1_time_needs_every_stage_1_in_one_stretch(tmp_path):
    """With pipelines each running their own stage 1 before their stage 1b, no one share fits."""
    line = refusal(tmp_path, "/usr/bin:/bin", "STAGE1_TIME", "700")
    assert "STAGE1_TIME needs STAGE1B_START=pool" in line and "raced" in line


def test_a_stage_1_time_must_leave_stage_1b_time_before_the_deadline(tmp_path):
    """DEADLINE less the later stages' 390 s leaves 1410 s: stage 1 may take at most 1409."""
    line = refusal(
        tmp_path, "/usr/bin:/bin", "STAGE1_TIME", "1410", DEADLINE="1800", STAGE1B_START="pool"
    )
    assert "STAGE1_TIME must leave stage 1b time" in line and "at most 1409" in line


def test_the_later_stages_time_is_a_knob(tmp_path):
    """LATER_STAGES=480 leaves 1320 s of a 1800 s deadline: stage 1 may take at most 1319."""
    line = refusal(
        tmp_path,
        "/usr/bin:/bin",
        "STAGE1_TIME",
        "1320",
        DEADLINE="1800",
        LATER_STAGES="480",
        STAGE1B_START="pool",
    )
    assert "at most 1319" in line and "480 s kept" in line


def test_the_later_stages_time_needs_a_deadline_that_leaves_time(tmp_path):
    """Without DEADLINE the knob would do nothing; at or past DEADLINE no stage 1b would run."""
    line = refusal(tmp_path, "/usr/bin:/bin", "LATER_STAGES", "480", STAGE1B_START="pool")
    assert "LATER_STAGES needs DEADLINE" in line
    line = refusal(
        tmp_path, "/usr/bin:/bin", "LATER_STAGES", "1800", DEADLINE="1800", STAGE1B_START="pool"
    )
    assert "DEADLINE must leave time" in line and "more than 1800" in line


def test_auto_later_stages_keep_nothing_before_the_calibration(tmp_path):
    """LATER_STAGES=auto passes the knob check and keeps no time until the calibration before
    stage 1: stage 1 may then take all of a 1800 s deadline but a second."""
    line = refusal(
        tmp_path,
        "/usr/bin:/bin",
        "STAGE1_TIME",
        "1800",
        DEADLINE="1800",
        LATER_STAGES="auto",
        STAGE1B_START="pool",
    )
    assert "before DEADLINE: at most 1799" in line and "kept" not in line


def script_part(name: str) -> str:
    """The script's function `name` (or `name=...` assignment line), as bash source."""
    source = SCRIPT.read_text()
    found = re.search(rf"^{name}\(\) \{{.*?^\}}$|^{name}=[^\n]*$", source, re.S | re.M)
    return found.group(0)


def later_stages_for(milliseconds: int, **knobs: str) -> int:
    """The script's own later_stages_for for a calibration of milliseconds, with the script's
    defaults for TOP, PIPELINES and RACE_SEEDS unless knobs set them."""
    values = {"top": "3", "pipelines": "3", "race_seeds": "10", **knobs}
    assigned = "\n".join(f"{name}={value}" for name, value in values.items())
    parts = "\n".join(script_part(name) for name in ("calibration_seeds", "later_stages_for"))
    done = subprocess.run(
        ["bash", "-c", f"{parts}\n{assigned}\nlater_stages_for {milliseconds}"],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(done.stdout)


def test_auto_later_stages_scale_the_calibration_by_the_later_stages_passes():
    """Design X's shape (one pipeline, TOP=6, the race at 10 seeds): the later stages walk
    6 + 30 + 10 = 46 passes over the standard table against the calibration's 3, so a 15.5 s
    calibration keeps 15.5 * 46 / 3 s, a quarter more (297 s) and 20 s for the commands; the
    time grows with the calibration's, the race's seeds and the re-check's candidates."""
    design_x = {"top": "6", "pipelines": "1"}
    assert later_stages_for(15_500, **design_x) == 317
    assert later_stages_for(31_000, **design_x) == 614
    assert (
        later_stages_for(15_500, race_seeds="5", **design_x)
        < 317
        < later_stages_for(15_500, top="12", pipelines="1")
    )


@pytest.mark.slow
def test_the_calibration_times_a_gait_that_stands_over_the_standard_table(tmp_path):
    """calibrated_later_stages() walks the calibration gait over the standard table on every
    engine, writes its table beside the store, and keeps the commands' 20 s plus the passes'
    time it measured and a quarter more (here 9 s walks at one seed, so that it is quick); a
    calibration that fails stops the search before any time is kept."""
    metaopt = shutil.which("metaopt")
    if metaopt is None:
        pytest.skip("the metaopt command is not installed")
    names = ("calibration_gait", "later_stages_for", "milliseconds", "calibrated_later_stages")
    script = "set -euo pipefail\n" + "\n".join(script_part(name) for name in names)
    script += "\ncalibration_seeds=1\ntop=1\npipelines=1\nrace_seeds=1\nseed=7\n"

    def calibrated(duration: str) -> subprocess.CompletedProcess:
        timed = f"{script}standard_walk=(--set duration={duration})\nstarted=$SECONDS\n"
        timed += 'kept=$(calibrated_later_stages)\necho "$kept $((SECONDS - started))"\n'
        return subprocess.run(
            ["bash", "-c", timed], cwd=tmp_path, capture_output=True, text=True, timeout=300
        )

    done = calibrated("9")
    assert done.returncode == 0, done.stderr
    kept, took = map(int, done.stdout.split())
    assert 20 + (took - 2) * 14 * 5 // 4 <= kept <= 20 + (took + 1) * 14 * 5 // 4  # 14 passes
    table = (tmp_path / "robust-walk-s7-calibration.txt").read_text()
    assert "hazard_walk" in table
    for engine in ("mujoco", "pybullet", "ode"):
        assert re.search(rf"whole table\s*│\s*{engine}", table), engine
    refused = calibrated("1")  # shorter than the gait's 3 s lock: metaopt refuses it
    assert refused.returncode != 0 and refused.stdout == ""
    assert "must be shorter than duration" in refused.stderr


def test_a_calibration_that_keeps_too_much_stops_the_search_in_one_line(tmp_path):
    """After the calibration, the time it kept must leave stage 1 its STAGE1_TIME and stage 1b a
    second before DEADLINE; otherwise one line says by how much, and the search stops (exit 2)."""
    check = script_part("refuse_a_calibration_that_leaves_no_stage1b")

    def checked(
        deadline: int, gone: int, kept: int, stage1_time: int
    ) -> subprocess.CompletedProcess:
        knobs = f"DEADLINE={deadline} SECONDS={gone} later_stages={kept} STAGE1_TIME={stage1_time}"
        # unset, SECONDS stops ticking: the boundary below is exact whenever the clock turns
        program = f"set -euo pipefail\n{check}\nunset SECONDS\nseed=7 {knobs}\n"
        program += "refuse_a_calibration_that_leaves_no_stage1b\necho stage 1"
        return subprocess.run(["bash", "-c", program], capture_output=True, text=True, timeout=60)

    left = checked(1800, 19, 360, 490)  # design AC's seed 147: 931 s left to stage 1b
    assert left.returncode == 0 and left.stdout == "stage 1\n" and left.stderr == ""
    assert checked(1800, 19, 1290, 490).returncode == 0  # one second left
    refused = checked(1800, 19, 1291, 490)
    assert refused.returncode == 2 and refused.stdout == ""
    assert refused.stderr.splitlines() == [
        "LATER_STAGES=auto kept 1291 s for the later stages (robust-walk-s7-calibration.txt),"
        " which with 19 s gone and STAGE1_TIME=490 leaves stage 1b no time before"
        " DEADLINE=1800: give a DEADLINE of at least 1801, or LATER_STAGES in seconds"
    ]


@pytest.mark.slow
def test_the_search_stops_after_a_calibration_that_leaves_no_stage1b_and_keeps_no_store(tmp_path):
    """The whole script: a deadline the check before the calibration passes (LATER_STAGES=auto
    keeps nothing until then) but the calibration's time does not leave, is refused after the
    calibration, in one line, with nothing written but the calibration's table."""
    if shutil.which("metaopt") is None:
        pytest.skip("the metaopt command is not installed")
    knobs = {"LATER_STAGES": "auto", "DEADLINE": "120", "STAGE1_TIME": "100"}
    done = subprocess.run(
        ["bash", str(SCRIPT), "7"],
        cwd=tmp_path,
        env={"PATH": os.environ["PATH"], "STAGE1B_START": "pool", **knobs},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 2, done.stderr
    calibration, refusal = done.stderr.strip().splitlines()  # the calibration's line, then one
    kept = re.fullmatch(r"LATER_STAGES=auto: .* keeps (\d+) s for the later stages", calibration)
    assert kept, calibration
    said = re.fullmatch(
        r"LATER_STAGES=auto kept (\d+) s for the later stages \(robust-walk-s7-calibration.txt\),"
        r" which with (\d+) s gone and STAGE1_TIME=100 leaves stage 1b no time before"
        r" DEADLINE=120: give a DEADLINE of at least (\d+), or LATER_STAGES in seconds",
        refusal,
    )
    assert said, refusal
    later, gone, needed = map(int, said.groups())
    assert later == int(kept.group(1)) and needed == later + gone + 100 + 1
    assert [path.name for path in tmp_path.iterdir()] == ["robust-walk-s7-calibration.txt"]


def test_flat_best_needs_the_pooled_basins(tmp_path):
    """Only the pooled basin race ranks more basins than there are pipelines."""
    line = refusal(tmp_path, "/usr/bin:/bin", "FLAT_BEST", "1")
    assert "FLAT_BEST needs STAGE1B_START=pool" in line and "raced" in line


def test_flat_fell_needs_flat_best(tmp_path):
    """FLAT_FELL widens FLAT_BEST's test; alone it would do nothing, so it is refused."""
    line = refusal(tmp_path, "/usr/bin:/bin", "FLAT_FELL", "0.9", STAGE1B_START="pool")
    assert "FLAT_FELL needs FLAT_BEST" in line


def test_the_flat_check_reads_the_runs_best_from_the_store(tmp_path):
    """The script's own flat(): yes when the run's best (from `metaopt show`) scores below
    FLAT_BEST, no otherwise; a store it cannot read stops the search (exit not 0)."""
    metaopt = shutil.which("metaopt")
    if metaopt is None:
        pytest.skip("the metaopt command is not installed")
    db = tmp_path / "s.db"
    run = ["run", "-o", "random", "-p", "sphere", "--budget", "5", "--seed", "1", "--db", str(db)]
    subprocess.run([metaopt, *run], check=True, capture_output=True, timeout=120)
    shown = subprocess.run([metaopt, "show", "1", "--db", str(db), "--format", "json"],
                           check=True, capture_output=True, text=True, timeout=60)  # fmt: skip
    best = json.loads(shown.stdout)["best"]["fitness"]

    def verdict(flat_best: float, store: Path) -> subprocess.CompletedProcess:
        script = f"set -euo pipefail\n{script_part('flat')}\ndb={store}\nFLAT_BEST={flat_best}\n"
        script += 'verdict=$(flat 1)\necho "$verdict"\n'
        return subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=60)

    assert verdict(best + 1, db).stdout == "yes\n"
    assert verdict(best - 1, db).stdout == "no\n"
    unread = verdict(best + 1, tmp_path / "missing.db")
    assert unread.returncode != 0 and unread.stdout == ""  # stopped before any verdict


def test_the_flat_check_also_reads_the_share_of_the_last_candidates_that_fell(tmp_path):
    """With FLAT_FELL, flat() says yes when at least that share of the run's last 100
    candidates fell (`metaopt show --recent 100`), whatever the best scored, and no below it;
    a problem without a fall metric is flat only by its best; a run without an evaluation is
    flat whatever FLAT_FELL says."""
    metaopt = shutil.which("metaopt")
    if metaopt is None:
        pytest.skip("the metaopt command is not installed")

    def show(db: Path) -> dict:
        """`metaopt show 1 --recent 100` of the store at db, as flat() reads it."""
        return json.loads(subprocess.run(
            [metaopt, "show", "1", "--recent", "100", "--db", str(db), "--format", "json"],
            check=True, capture_output=True, text=True, timeout=60).stdout)  # fmt: skip

    def stored(problem: str, *settings: str) -> tuple[Path, float, float | None]:
        db = tmp_path / f"{problem}.db"
        run = ["run", "-o", "random", "-p", problem, "--budget", "6", "--seed", "2",
               *settings, "--db", str(db)]  # fmt: skip
        subprocess.run([metaopt, *run], check=True, capture_output=True, timeout=300)
        shown = show(db)
        fell = shown["recent"]["metrics"].get("fell", {}).get("share")
        return db, shown["best"]["fitness"], fell

    def verdict(store: Path, flat_best: float, flat_fell: float | str) -> str:
        script = f"set -euo pipefail\n{script_part('flat')}\ndb={store}\n"
        script += f"FLAT_BEST={flat_best}\nFLAT_FELL={flat_fell}\n"
        script += 'verdict=$(flat 1)\necho "$verdict"\n'
        done = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    walk, best, fell = stored("nao-walk", "--set", "duration=2", "--set", "lock=1")
    assert fell is not None and 0.0 < fell < 1.0  # some fell, some did not (4 of 6)
    below = min(best, 0.0) - 1.0  # a FLAT_BEST the best passes, so only the falls decide
    assert verdict(walk, below, "") == "no"
    assert verdict(walk, below, fell) == "yes"
    assert verdict(walk, below, round(fell + 0.01, 6)) == "no"
    sphere, best, fell = stored("sphere")
    assert fell is None  # no fall metric: FLAT_FELL never makes it flat
    assert verdict(sphere, min(best, 0.0) - 1.0, 0.0) == "no"
    empty = tmp_path / "empty.db"  # stopped by its time limit before its first evaluation
    subprocess.run([metaopt, "run", "-o", "random", "-p", "sphere", "--budget", "5",
                    "--max-time", "0.000001", "--db", str(empty)],
                   capture_output=True, timeout=120)  # fmt: skip
    shown = show(empty)
    assert shown["best"] is None and shown["recent"] is None  # no evaluation, as meant
    assert verdict(empty, 1.0, "") == verdict(empty, 1.0, 0.9) == "yes"


TRIAL_KNOBS = {"STAGE1B_START": "pool", "DEADLINE": "1800", "PIPELINES": "1"}


@pytest.mark.parametrize(
    ("value", "knobs", "says"),
    [
        ("2", {"STAGE1B_START": "raced", "PIPELINES": "1"}, "TRIALS needs STAGE1B_START=pool"),
        ("2", {**TRIAL_KNOBS, "PIPELINES": "2"}, "DEADLINE and PIPELINES=1"),
        ("2", {"STAGE1B_START": "pool", "PIPELINES": "1"}, "DEADLINE and PIPELINES=1"),
        ("2", TRIAL_KNOBS, "TRIALS needs TRIAL_TIME"),
        ("2", {**TRIAL_KNOBS, "TRIAL_TIME": "300", "FLAT_BEST": "1"}, "no FLAT_BEST"),
    ],
)
def test_trials_need_one_pooled_pipeline_under_a_deadline_and_their_time(
    tmp_path, value, knobs, says
):
    """TRIALS share one pipeline's time before a deadline: anything else is refused."""
    assert says in refusal(tmp_path, "/usr/bin:/bin", "TRIALS", value, **knobs)


def test_a_trial_time_needs_trials(tmp_path):
    line = refusal(tmp_path, "/usr/bin:/bin", "TRIAL_TIME", "300", **TRIAL_KNOBS)
    assert "TRIAL_TIME needs TRIALS" in line


def trial_functions() -> str:
    """The script's trial_window, slowest_speed() and fastest_trial(), as bash source."""
    text = SCRIPT.read_text()
    return re.search(r"^trial_window=.*?^fastest_trial\(\) \{.*?^\}$", text, re.S | re.M).group(0)


def test_fastest_trial_names_the_run_fastest_on_its_slowest_engine(tmp_path):
    """fastest_trial() reads each run's last candidates from the store (`metaopt show
    --recent`) and names the run whose median speed on its slowest engine is highest; a run
    without a per-engine speed (no evaluation, or one engine) ranks last; a store it cannot
    read stops the search."""
    metaopt = shutil.which("metaopt")
    if metaopt is None:
        pytest.skip("the metaopt command is not installed")
    db = tmp_path / "trials.db"
    walk = ["-p", "nao-walk", "--set", "backend=mujoco+ode", "--set", "duration=2.5",
            "--set", "lock=1", "--db", str(db)]  # fmt: skip
    for seed in (3, 4):
        run = [metaopt, "run", "-o", "random", "--budget", "4", "--seed", str(seed), *walk]
        subprocess.run(run, check=True, capture_output=True, timeout=300)
    subprocess.run([metaopt, "run", "-o", "random", "--budget", "4", "--max-time", "0.000001",
                    *walk], capture_output=True, timeout=120)  # fmt: skip  # run 3: none

    def slowest(run: int) -> float:
        shown = subprocess.run(
            [metaopt, "show", str(run), "--recent", "300", "--db", str(db), "--format", "json"],
            check=True, capture_output=True, text=True, timeout=60).stdout  # fmt: skip
        metrics = json.loads(shown)["recent"]["metrics"]
        return min(metrics[f"speed@{engine}"]["median"] for engine in ("mujoco", "ode"))

    speeds = {run: slowest(run) for run in (1, 2)}
    assert speeds[1] != speeds[2]  # the choice below is not a tie's
    fastest = max(speeds, key=speeds.get)

    def chosen(store: Path, *runs: int) -> subprocess.CompletedProcess:
        script = f"set -euo pipefail\ndb={store}\n{trial_functions()}\n"
        script += f'chosen=$(fastest_trial {" ".join(map(str, runs))})\necho "$chosen"\n'
        return subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=120)

    assert chosen(db, 1, 2).stdout == chosen(db, 2, 1).stdout == f"{fastest}\n"
    assert chosen(db, 3, 1).stdout == "1\n"  # no evaluation: -inf, never the choice
    assert chosen(db, 3).stdout == "3\n"  # alone, still the choice
    unread = chosen(tmp_path / "missing.db", 1, 2)
    assert unread.returncode != 0 and unread.stdout == ""


@pytest.mark.parametrize(
    ("knob", "value", "says", "knobs"),
    [
        ("STAGE1_OPTIMIZER", "bogus", "unknown optimizer 'bogus'", {}),
        ("STAGE1_BATCH", "-1", "'--batch': -1 is not in the range", {}),
        ("STAGE1B_OPTIMIZER", "bogus", "unknown optimizer 'bogus'", {}),
        ("STAGE1B_COMMON", "generation", "'generation' is not one of 'off', 'run', 'batch'", {}),
        ("STAGE1B_SET", "engine_score=best", "engine_score", {}),
        ("STAGE1B_SCREEN", "1", "no cheaper bound to screen with", {}),
        ("STAGE1B_SCREEN", "1", "reads every candidate's fitness",
         {"STAGE1B_SET": "engine_score=worst"}),
        ("STAGE1B_CELLS", "nominal,servo x2", "no perturbation 'servo x2'",
         {"STAGE1B_SET": "worlds=pushes"}),
        ("STAGE1B_DURATIONS", "latency 1=15", "'latency 1', which world_cells does not draw",
         {"STAGE1B_SET": "worlds=pushes", "STAGE1B_CELLS": "nominal,servo gain x1.2"}),
    ],
)  # fmt: skip
def test_a_bad_stage_setting_is_refused_by_metaopt_before_a_store_exists(
    tmp_path, knob, value, says, knobs
):
    """The knobs handed to `metaopt run` as they are: metaopt's own check (`run --check`, for
    stage 1b's before stage 1 starts) stops the search before any run."""
    metaopt = shutil.which("metaopt")
    if metaopt is None:
        pytest.skip("the metaopt command is not installed")
    path = f"{Path(metaopt).parent}:/usr/bin:/bin"
    assert says in refusal(tmp_path, path, knob, value, **knobs)
