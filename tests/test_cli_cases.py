"""The cases of issue 18 through the real `metaopt` command: right numbers for resampled runs,
one line (exit 2) for bad input checked before any work, failing runs, run ownership, complete
output for files and pipes, suggestions, and warnings for settings that cannot work."""

from __future__ import annotations

import csv
import io
import json
import multiprocessing
import os
import shlex
import shutil
import signal
import sqlite3
import statistics
import subprocess
import sys
import time
from collections import defaultdict

import numpy as np
import pytest
from click.testing import CliRunner

from metaopt.cli import main
from metaopt.storage.export import dump_json
from metaopt.storage.run_store import RunStore
from metaopt_problems.functions import BenchmarkFunction
from tests.conftest import FIXTURES, metaopt_cli, one_error_line
from tests.engines import needs_ode
from tests.fixtures.breaking_executor import PLUGIN_BREAKS_AT

BASIC = {"METAOPT_LOAD_PLUGINS": "harmony_search,genetic_algorithm,random_search,functions"}
#: nao-walk kept short: 1 s episodes after a 0.2 s lock phase.
SHORT_WALK = ("--set", "duration=1", "--set", "lock=0.2")


def in_process(*args: str, folder) -> str:
    """stdout of a reading command on folder's store, run in this process (the commands that
    show each case's answer; the case itself goes through a real subprocess)."""
    done = CliRunner().invoke(main, [*args, "--db", str(folder / "metaopt.db")])
    assert done.exit_code == 0, (args, done.output, done.exception)
    return done.stdout


@pytest.fixture(scope="module")
def noisy_run(tmp_path_factory):
    """A resampled run of a noisy problem: nao-walk with noise, 3 samples per candidate."""
    folder = tmp_path_factory.mktemp("noisy")
    done = metaopt_cli(
        "run", "-o", "hs", "-p", "nao-walk", "--budget", "36", "--resample", "3", "--seed", "1",
        "--set", "noise=1", "--set", "hms=4", *SHORT_WALK, cwd=folder,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return folder, done


def test_a_resampled_run_reports_its_best_candidates_aggregate_everywhere(noisy_run):
    folder, done = noisy_run
    rows = list(csv.DictReader(io.StringIO(in_process("export", "1", folder=folder))))
    samples = defaultdict(list)
    for row in rows:
        samples[int(row["candidate"])].append(float(row["fitness"]))
    assert len(samples) == 12 and all(len(s) == 3 for s in samples.values())
    best_mean = max(statistics.fmean(s) for s in samples.values())
    luckiest = max(float(row["fitness"]) for row in rows)
    assert luckiest > best_mean  # the noise makes a single sample's best a lucky one

    shown = json.loads(metaopt_cli("show", "1", "--format", "json", cwd=folder).stdout)
    assert shown["best"]["fitness"] == pytest.approx(best_mean, rel=1e-12)
    assert len(shown["best"]["evaluations"]) == 3
    assert shown["settings"]["resample"] == 3 and shown["settings"]["aggregate"] == "mean"
    listed = json.loads(in_process("runs", "--format", "json", folder=folder))
    assert listed[0]["best"] == pytest.approx(best_mean, rel=1e-12)
    assert listed[0]["settings"] == "sync, resample 3 (mean)"
    assert f"{best_mean:.6g}" in done.stdout  # the run's own summary agrees

    replayed = metaopt_cli("replay", "1", cwd=folder)
    assert replayed.returncode == 0, replayed.stderr
    assert "mean of evaluations" in replayed.stdout
    fitness_row = next(line for line in replayed.stdout.splitlines() if "fitness" in line)
    assert fitness_row.count(f"{best_mean:.6g}") == 2  # stored and replayed: the same mean

    as_json = json.loads(in_process("export", "1", "--format", "json", folder=folder))
    assert as_json["run"]["settings"]["resample"] == 3
    assert [e["candidate"] for e in as_json["evaluations"][:6]] == [0, 0, 0, 1, 1, 1]


def test_show_summarises_the_last_evaluations_as_the_export_holds_them(noisy_run):
    """`show --recent N`: the last N evaluations' median fitness and quartiles, each metric's
    median, and a 0/1 metric's share (nao-walk's falls), equal to the exported evaluations'."""
    folder, _ = noisy_run
    rows = list(csv.DictReader(io.StringIO(in_process("export", "1", folder=folder))))[-12:]
    shown = json.loads(in_process("show", "1", "--recent", "12", "--format", "json",
                                  folder=folder))["recent"]  # fmt: skip
    assert shown["evaluations"] == [24, 35] and shown["count"] == shown["succeeded"] == 12
    fitness = [float(row["fitness"]) for row in rows]
    lower, median, upper = np.percentile(fitness, [25, 50, 75])  # as robustness and compare
    assert shown["fitness"] == {"lower_quartile": lower, "median": median, "upper_quartile": upper}
    fell = [float(row["fell"]) for row in rows]
    assert 0 < sum(fell) < 12  # noise 1 makes some of the episodes fall, not all
    assert shown["metrics"]["fell"] == {"share": sum(fell) / 12, "count": 12}
    speeds = [float(row["speed"]) for row in rows]
    assert shown["metrics"]["speed"] == {"median": statistics.median(speeds), "count": 12}

    table = in_process("show", "1", "--recent", "12", folder=folder)
    assert "last 12 evaluations (24-35)" in table
    assert f"{sum(fell) / 12:.0%} at 1 (share)" in table
    everything = json.loads(in_process("show", "1", "--recent", "1000", "--format", "json",
                                       folder=folder))["recent"]  # fmt: skip
    assert everything["evaluations"] == [0, 35] and everything["count"] == 36


def test_compare_medians_use_the_candidates_aggregate(tmp_path):
    experiment = tmp_path / "noisy.toml"
    experiment.write_text(
        'name = "noisy"\nproblem = "nao-walk"\nseeds = [1]\n'
        "[problem_settings]\nnoise = 1.0\nduration = 1.0\nlock = 0.2\n"
        '[[optimizers]]\nname = "hs"\nbudget = 36\nparams = { hms = 4 }\n'
        "settings = { resample = 3 }\n"
    )
    done = metaopt_cli("compare", str(experiment), "--format", "json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)
    shown = json.loads(in_process("show", "1", "--format", "json", folder=tmp_path))
    assert rows[0]["fitness_median"] == pytest.approx(shown["best"]["fitness"], rel=1e-12)


def test_a_run_whose_evaluations_all_fail_stops_and_says_why(tmp_path):
    done = metaopt_cli(
        "run", "-o", "hs", "-p", "nao-walk", "--budget", "200", "--seed", "1",
        "--set", "servo_gain=1e9", "--set", "duration=4", cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 1
    line = done.stderr.strip().splitlines()[-1]
    assert "all 10 evaluations failed" in line and "fell during the lock phase" in line
    assert "Traceback" not in done.stderr
    shown = json.loads(in_process("show", "1", "--format", "json", folder=tmp_path))
    assert shown["status"] == "failed" and "all 10 evaluations failed" in shown["message"]
    assert shown["recent"]["succeeded"] == 0 and shown["recent"]["fitness"] is None
    assert "fitness: all 10 failed" in in_process("show", "1", folder=tmp_path)


def test_a_broken_executor_is_one_error_line_and_keeps_what_finished(tmp_path):
    """An executor broken for good (an outside plugin's, found through its entry point) fails
    the run with one Error line naming the break, exit 1, no traceback; every evaluation that
    finished before it is stored with the failed run."""
    plugin = tmp_path / "plugin"
    info = plugin / "breaking_executor-0.1.dist-info"
    info.mkdir(parents=True)
    shutil.copy(FIXTURES / "breaking_executor.py", plugin)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: breaking-executor\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[metaopt]\nbreaking = breaking_executor\n")
    done = metaopt_cli(
        "run", "-o", "random", "-p", "sphere", "--budget", "16", "--set", "batch_size=4",
        "--executor", "breaking", "--workers", "2", cwd=tmp_path, extra_path=plugin,
        env={"METAOPT_LOAD_PLUGINS": "random_search,functions,breaking"},
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), done.stderr
    assert f"the breaking executor broke at task {PLUGIN_BREAKS_AT}" in lines[0]
    assert "Traceback" not in done.stdout + done.stderr
    with RunStore(tmp_path / "metaopt.db") as store:
        (record,) = store.runs()
        assert record.status == "failed"
        stored = sorted(e.index for e in store.evaluations(record.id))
        assert stored == [i for i in range(8) if i != PLUGIN_BREAKS_AT] == [0, 1, 2, 3, 4, 5, 7]


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--seed", "-1"], ["--seed", "-1 is not in the range 0<=x"]),
        (["--seed", "99999999999999999999999"], ["--seed", "0<=x<=9223372036854775807"]),
        (["--scheduler", "http://127.0.0.1:8799"], ["not a Dask scheduler address", "tcp://"]),
        (["--workers", "2", "--executor", "serial"], ["--executor serial", "process"]),
    ],
)
def test_run_refuses_bad_options_in_one_line_before_storing(tmp_path, args, needles):
    done = metaopt_cli("run", "-o", "hs", "-p", "sphere", *args, cwd=tmp_path, env=BASIC)
    one_error_line(done, *needles)
    assert not (tmp_path / "metaopt.db").exists()


@pytest.mark.parametrize("command", [["run"], ["compare", "--seeds", "1", "--budget", "2"]])
def test_a_problem_refusing_its_settings_stops_a_run_before_a_store_exists(tmp_path, command):
    """The problem's own checks (here nao-walk's, which no parameter declaration can say) run
    before the store is opened, in `run` and in `compare`: no empty store is left behind."""
    done = metaopt_cli(*command, "-o", "hs", "-p", "nao-walk", "--set", "worlds=pushes",
                       "--set", "push=1", cwd=tmp_path)  # fmt: skip
    one_error_line(done, "worlds=pushes draws each evaluation's push", "leave push at 0")
    assert not (tmp_path / "metaopt.db").exists()


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["-p", "sphere", "--set", "sigma0=-1"], ["'sigma0' = -1.0 is invalid", "(0, 1]"]),
        (["-p", "sphere", "--mode", "async"], ["'cmaes' is generational", "--mode sync"]),
        (["-p", "nao-walk", "--set", "worlds=pushes", "--set", "world_cells=nominal,servo x2"],
         ["world_cells: no perturbation 'servo x2'", "accepted: nominal"]),
    ],
)  # fmt: skip
def test_run_check_makes_a_runs_checks_and_runs_and_stores_nothing(tmp_path, args, needles):
    """`run --check` refuses what the run would refuse, including what only the built problem
    (nao-walk's cells) or optimizer (CMA-ES cannot run async) can say, and accepts the rest."""
    accepted = metaopt_cli("run", "-o", "cmaes", "-p", "sphere", "--mode", "sync", "--check",
                           cwd=tmp_path)  # fmt: skip
    assert accepted.returncode == 0, accepted.stderr
    assert accepted.stdout.strip() == "cmaes on sphere: every setting accepted; nothing run"
    one_error_line(metaopt_cli("run", "-o", "cmaes", *args, "--check", cwd=tmp_path), *needles)
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def sphere_store(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sphere")
    done = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "50", "--seed", "2",
                       cwd=folder, env=BASIC)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return folder


def _snapshot(folder) -> dict:
    return {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["replay", "1", "--video", "/nonexistent/dir/w.mp4"], ["folder", "does not exist"]),
        (["replay", "1", "--video", "w.gif"], ["only .mp4 files"]),
        (["replay", "1", "--video", "newdir/"], ["is a directory"]),
        (["export", "1", "--output", "/nonexistent/dir/x.csv"], ["does not exist"]),
        (["robustness", "hs_walk", "--csv", "newdir/"], ["--csv newdir/ is a directory"]),
        (["robustness", "hs_walk", "--figure", "r.jpg"], ["--figure r.jpg", "only .png"]),
        (
            ["compare", "-o", "hs", "-p", "sphere", "--csv", "/nonexistent/dir/x.csv"],
            ["--csv", "does not exist"],
        ),
    ],
)
def test_output_paths_are_checked_before_any_work(sphere_store, args, needles):
    before = _snapshot(sphere_store)
    started = time.perf_counter()
    done = metaopt_cli(*args, cwd=sphere_store, env=BASIC)
    one_error_line(done, *needles)
    assert time.perf_counter() - started < 20  # refused up front, not after running
    assert _snapshot(sphere_store) == before  # no file left behind, the store untouched


def test_an_unwritable_folder_is_refused(sphere_store):
    done = metaopt_cli("export", "1", "--output", "/proc/x.csv", cwd=sphere_store)
    one_error_line(done, "--output /proc/x.csv: cannot write in /proc")


@pytest.mark.parametrize("db", ["file:u.db", "dir[/x.db"])
def test_a_store_path_names_the_file_it_is_whatever_its_characters(tmp_path, monkeypatch, db):
    """A --db path that SQLite could read as a URI ('file:...') or that holds what rich markup
    or a glob give meaning to ('[/') is the file it names: the run stores there and nowhere
    else, and `runs` reads that file back."""
    (tmp_path / "dir[").mkdir()
    done = metaopt_cli(
        "run", "-o", "random", "-p", "sphere", "--budget", "5", "--db", db, cwd=tmp_path, env=BASIC
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert [p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()] == [db]
    monkeypatch.chdir(tmp_path)
    listed = CliRunner().invoke(main, ["runs", "--format", "json", "--db", db])
    assert listed.exit_code == 0, listed.output
    assert [run["id"] for run in json.loads(listed.stdout)] == [1]


def _interrupt(self, x, seed):
    """An evaluation that Ctrl-C stops."""
    raise KeyboardInterrupt


@pytest.mark.parametrize("name", ["my runs.db", "it's $HOME;.db"])
def test_the_resume_hint_of_an_interrupted_run_pastes_back_into_a_shell(
    tmp_path, monkeypatch, name
):
    """The line after an interrupted run quotes its store path for a shell: a path with a
    space or shell characters, split as a shell does, names the store again."""
    monkeypatch.setattr(BenchmarkFunction, "evaluate", _interrupt)
    db = str(tmp_path / name)
    args = ["run", "-o", "random", "-p", "sphere", "--budget", "5", "--db", db]
    done = CliRunner().invoke(main, args)
    assert done.exit_code == 130, (done.output, done.exception)
    (hint,) = [line for line in done.stderr.splitlines() if "Resume with: " in line]
    command = hint.partition("Resume with: ")[2]
    assert shlex.split(command) == ["metaopt", "resume", "1", "--db", db]


def test_export_to_a_file_is_whole(sphere_store):
    done = metaopt_cli("export", "1", "--output", "whole.csv", cwd=sphere_store, env=BASIC)
    assert done.returncode == 0, done.stderr
    rows = list(csv.DictReader((sphere_store / "whole.csv").open()))
    assert len(rows) == 50 and "candidate" in rows[0]
    assert not [p for p in sphere_store.iterdir() if p.name.startswith(".whole.csv")]
    (sphere_store / "whole.csv").unlink()


def test_tables_for_a_pipe_are_complete_at_any_width(sphere_store):
    narrow = {**BASIC, "COLUMNS": "40"}
    listing = metaopt_cli("runs", cwd=sphere_store, env=narrow)
    assert "…" not in listing.stdout and "finished" in listing.stdout
    assert "sphere" in listing.stdout and "sync" in listing.stdout  # settings tell runs apart
    shown = in_process("show", "1", folder=sphere_store)
    assert "…" not in shown and "settings" in shown
    row = next(
        csv.DictReader(io.StringIO(in_process("runs", "--format", "csv", folder=sphere_store)))
    )
    assert row["problem"] == "sphere" and row["evaluations"] == "50"


def test_compare_table_at_80_columns_is_complete(tmp_path):
    done = metaopt_cli(
        "compare", "-o", "hs", "-o", "random", "-p", "sphere", "--seeds", "2", "--budget", "40",
        cwd=tmp_path, env={**BASIC, "COLUMNS": "80"},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "…" not in done.stdout and "rank-sum" in done.stdout
    as_csv = in_process("compare", "-o", "hs", "-o", "random", "-p", "sphere", "--seeds", "2",
                        "--budget", "40", "--format", "csv", folder=tmp_path)  # fmt: skip
    rows = list(csv.DictReader(io.StringIO(as_csv)))
    assert [r["optimizer"] for r in rows] == ["hs", "random"]


@pytest.mark.parametrize(
    ("args", "env", "needles"),
    [
        (["list", "sphre"], BASIC, ["unknown plugin 'sphre'", "'sphere' (problem)"]),
        (["run", "-o", "HS", "-p", "sphere"], BASIC, ["Did you mean 'hs'?"]),
        (
            ["list"],
            {"METAOPT_LOAD_PLUGINS": "hs,sphere"},
            ["'hs', 'sphere'", "entry-point names", "harmony_search"],
        ),
    ],
)
def test_names_get_suggestions(tmp_path, args, env, needles):
    one_error_line(metaopt_cli(*args, cwd=tmp_path, env=env), *needles)


def test_list_shows_an_executor(tmp_path):
    done = metaopt_cli("list", "process", cwd=tmp_path)
    assert done.returncode == 0 and "process (executor)" in done.stdout


@pytest.mark.parametrize(
    ("args", "warning"),
    [
        (["-o", "hs", "--budget", "10"], "hms 20 is not smaller than the budget's 10"),
        (["-o", "ga", "--budget", "30"], "population 100 is not smaller than the budget's 30"),
        (["-o", "cmaes", "--budget", "8"], "8 candidates are no more than its first generation"),
    ],
)
def test_settings_that_cannot_work_as_meant_are_warned_in_one_line(tmp_path, args, warning):
    """One line, named once by the optimizer it is about."""
    env = {"METAOPT_LOAD_PLUGINS": "harmony_search,genetic_algorithm,cma_es,functions"}
    done = metaopt_cli("run", *args, "-p", "sphere", "--seed", "1", cwd=tmp_path, env=env)
    assert done.returncode == 0, done.stderr
    warnings = [line for line in done.stderr.splitlines() if line.startswith("Warning: ")]
    assert len(warnings) == 1 and warnings[0].startswith(f"Warning: {args[1]}: {warning}")


@pytest.mark.skipif((os.cpu_count() or 1) > 2, reason="warns of more workers than cores")
def test_more_workers_than_cores_is_warned_in_one_line(tmp_path):
    env = {"METAOPT_LOAD_PLUGINS": "harmony_search,functions,executors"}
    done = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "30", "--workers", "3",
                       "--batch", "3", "--executor", "process", cwd=tmp_path, env=env)  # fmt: skip
    assert done.returncode == 0, done.stderr
    warnings = [line for line in done.stderr.splitlines() if line.startswith("Warning: ")]
    assert len(warnings) == 1 and f"--workers 3 on {os.cpu_count()} cores" in warnings[0]


def test_workers_a_sync_batch_leaves_waiting_are_warned_in_one_line(tmp_path):
    """HS asks one candidate per batch: a second worker would wait at every batch, unless the
    batch or the resampling fills it."""
    env = {"METAOPT_LOAD_PLUGINS": "harmony_search,functions,executors"}
    base = ["run", "-o", "hs", "-p", "sphere", "--budget", "60", "--workers", "2", "--executor",
            "process"]  # fmt: skip
    warned = {}
    for extra in ([], ["--batch", "2"], ["--resample", "2"], ["--mode", "async"]):
        done = metaopt_cli(*base, *extra, cwd=tmp_path, env=env)
        assert done.returncode == 0, done.stderr
        warned[" ".join(extra)] = [
            line for line in done.stderr.splitlines() if line.startswith("Warning: ")
        ]
    assert warned[""] == [
        "Warning: hs asks 1 candidate per batch: 1 of the 2 workers waits at every batch; ask "
        "for 2 per batch (--batch 2; sync results depend on the batch, not the workers) or run "
        "in --mode async"
    ]
    assert not any(warned[key] for key in ("--batch 2", "--resample 2", "--mode async"))


def test_pybullet_prints_no_build_time_line(tmp_path):
    done = subprocess.run(
        [sys.executable, "-c", "import metaopt_problems.physics.pybullet_engine"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert "build time" not in done.stdout + done.stderr


def _wait_for_running_run(db, seconds: float = 60) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if db.exists():
            with sqlite3.connect(db) as connection:
                try:
                    owners = connection.execute("SELECT COUNT(*) FROM run_owners").fetchone()[0]
                except sqlite3.OperationalError:
                    owners = 0
            if owners:
                return
        time.sleep(0.2)
    raise AssertionError("the run never started")


def test_a_live_run_cannot_be_resumed_twice_but_a_dead_ones_can(tmp_path):
    env = {**os.environ, **BASIC}
    command = [sys.executable, "-m", "metaopt"]
    owner = subprocess.Popen(
        [*command, "run", "-o", "random", "-p", "sphere", "--budget", "100000000", "--seed", "1",
         "--set", "dim=2"],
        cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        _wait_for_running_run(tmp_path / "metaopt.db")
        refused = metaopt_cli("resume", "1", cwd=tmp_path, env=BASIC)
        one_error_line(refused, f"process {owner.pid} on host", "run 1 is being run")
    finally:
        owner.kill()
        owner.wait()
    with sqlite3.connect(tmp_path / "metaopt.db") as connection:
        stored = connection.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0]
    second = subprocess.Popen(
        [*command, "resume", "1"], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # until the resumed run stores evaluations of its own
        with sqlite3.connect(tmp_path / "metaopt.db") as connection:
            owner_pid = connection.execute("SELECT pid FROM run_owners").fetchone()
            now = connection.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0]
        if owner_pid == (second.pid,) and now > stored:
            break
        time.sleep(0.2)
    assert owner_pid == (second.pid,) and now > stored  # the dead owner's claim taken over
    second.send_signal(signal.SIGTERM)
    _, err = second.communicate(timeout=60)
    assert second.returncode == 130 and "Resume with: metaopt resume 1" in err


@pytest.mark.parametrize("executor", [[], ["--executor", "process", "--workers", "2"]])
def test_a_time_limit_shorter_than_the_engines_set_up_counts_only_evaluations(tmp_path, executor):
    """Importing MuJoCo and building its model take longer than this limit; episodes do not.
    The set-up is not timed, so no evaluation fails (none is cut short mid-import)."""
    done = metaopt_cli(
        "run", "-o", "hs", "-p", "nao-walk", "--budget", "12", "--seed", "1", "--set", "hms=4",
        "--time-limit", "0.3", *SHORT_WALK, *executor, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "12 (0 failed)" in done.stdout


@pytest.mark.slow
def test_dask_wall_time_includes_starting_the_cluster(tmp_path):
    done = metaopt_cli(
        "run", "-o", "hs", "-p", "sphere", "--budget", "8", "--seed", "1", "--executor", "dask",
        "--workers", "1", cwd=tmp_path, env={"METAOPT_LOAD_PLUGINS": None},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    wall_line = next(line for line in done.stdout.splitlines() if "wall time" in line)
    starting = float(wall_line.split("starting workers ")[1].split(" s")[0])
    # a LocalCluster spawns a worker process that imports distributed: never under 50 ms
    assert starting > 0.05
    shown = json.loads(in_process("show", "1", "--format", "json", folder=tmp_path))
    assert shown["wall_time"] > starting


def _strict_json(text: str):
    """Parsed as strict JSON: Infinity, -Infinity and NaN are not JSON numbers."""

    def refuse(constant: str):
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_json_output_is_strict_with_each_list_element_on_a_line_of_its_own():
    """dump_json (export, show, compare --format json): non-finite floats anywhere, in a nested
    object or inside a list's element, become the strings float() reads back; every element of
    a list is one line, so a run's evaluations are one per line."""
    value = {
        "run": {"friction": float("inf"), "name": "a", "empty": [], "none": {}},
        "evaluations": [
            {"index": 0, "metrics": {"speed": float("nan")}, "x": [1.0, -float("inf")]},
            {"index": 1, "metrics": {"speed": 0.5}, "x": [0.25, 2.0]},
        ],
    }
    out = io.StringIO()
    dump_json(value, out)
    text = out.getvalue()
    assert text.endswith("}\n")
    read = _strict_json(text)
    assert read["run"] == {"friction": "inf", "name": "a", "empty": [], "none": {}}
    assert read["evaluations"][0] == {"index": 0, "metrics": {"speed": "nan"}, "x": [1.0, "-inf"]}
    assert read["evaluations"][1] == value["evaluations"][1]
    lines = text.splitlines()
    for row in read["evaluations"]:
        assert sum(line.strip().rstrip(",") == json.dumps(row) for line in lines) == 1


@needs_ode
def test_infinite_settings_export_as_strict_json_that_reads_back(tmp_path):
    """An infinite friction (ODE's dInfinity, which nao-walk accepts there) is written as
    "inf", which float() reads back, by export and show alike: strict JSON readers refuse
    Python's Infinity."""
    done = metaopt_cli(
        "run", "-o", "hs", "-p", "nao-walk", "--budget", "2", "--seed", "1", "--set", "hms=2",
        "--set", "backend=ode", "--set", "friction=inf", *SHORT_WALK, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    exported = _strict_json(in_process("export", "1", "--format", "json", folder=tmp_path))
    shown = _strict_json(in_process("show", "1", "--format", "json", folder=tmp_path))
    as_csv = in_process("show", "1", "--format", "csv", folder=tmp_path)
    (row,) = csv.DictReader(io.StringIO(as_csv))
    in_csv = _strict_json(row["problem_params"])
    for params in (exported["run"]["problem_params"], shown["problem_params"], in_csv):
        assert params["friction"] == "inf" and float(params["friction"]) == float("inf")
    assert len(exported["evaluations"]) == 2


def _refused_in_process(*args: str) -> str:
    """The one error line of a command refused (exit 2) in this process, checked to have left
    none of the worker processes it may have started alive."""
    before = set(multiprocessing.active_children())
    done = CliRunner().invoke(main, list(args))
    assert done.exit_code == 2, (done.output, done.exception)
    assert set(multiprocessing.active_children()) - before == set()  # every worker stopped
    lines = done.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), done.output
    return lines[0]


def test_a_refused_run_or_resume_leaves_no_worker_process(tmp_path):
    """`run` and `resume` checks that only the built optimizer or the stored run can make
    (CMA-ES is generational; the run already finished; a budget not above it) are one line and
    leave no worker process behind: they are made before any worker starts."""
    db = str(tmp_path / "metaopt.db")
    workers = ("--executor", "process", "--workers", "2", "--db", db)
    line = _refused_in_process("run", "-o", "cmaes", "-p", "sphere", "--mode", "async", *workers)
    assert "'cmaes' is generational" in line
    done = CliRunner().invoke(main, ["run", "-o", "hs", "-p", "sphere", "--budget", "4",
                                     "--db", db])  # fmt: skip
    assert done.exit_code == 0, (done.output, done.exception)
    assert "already finished" in _refused_in_process("resume", "1", *workers)
    line = _refused_in_process("resume", "1", "--budget", "3", *workers)
    assert "budget must be more than the 4 evaluations" in line


def test_a_run_the_built_optimizer_refuses_starts_no_dask_cluster(tmp_path):
    """Refused before any executor is built: one error line, not the line of a Dask
    cluster's dashboard started in vain, and no store."""
    done = metaopt_cli("run", "-o", "cmaes", "-p", "sphere", "--mode", "async", "--executor",
                       "dask", "--workers", "1", cwd=tmp_path)  # fmt: skip
    one_error_line(done, "'cmaes' is generational", "--mode sync")
    assert not (tmp_path / "metaopt.db").exists()
    finished = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--budget", "4", cwd=tmp_path)
    assert finished.returncode == 0, finished.stderr
    done = metaopt_cli("resume", "1", "--executor", "dask", "--workers", "1", cwd=tmp_path)
    one_error_line(done, "already finished")
