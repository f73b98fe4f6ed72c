"""The command line through a real subprocess: happy paths and every kind of bad input."""

import csv
import io
import json

import pytest

from tests.conftest import metaopt_cli

BASIC = {"METAOPT_LOAD_PLUGINS": "harmony_search,genetic_algorithm,random_search,functions"}


def test_run_then_runs_show_and_export(tmp_path):
    done = metaopt_cli(
        "run", "--optimizer", "hs", "--problem", "sphere", "--budget", "500", "--seed", "4",
        "--set", "hmcr=0.95", "--set", "dim=5", cwd=tmp_path, env=BASIC,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "best fitness" in done.stdout and "500 (0 failed)" in done.stdout
    assert (tmp_path / "metaopt.db").exists()  # default store in the working directory
    listing = metaopt_cli("runs", cwd=tmp_path, env=BASIC)
    assert listing.returncode == 0 and "500/500" in listing.stdout and "finished" in listing.stdout
    assert "screened" not in listing.stdout  # a column only where a listed run screened
    shown = metaopt_cli("show", "1", cwd=tmp_path, env=BASIC)
    assert "hmcr" in shown.stdout and "0.95" in shown.stdout and "dim" in shown.stdout

    exported = metaopt_cli("export", "1", "--format", "csv", cwd=tmp_path, env=BASIC)
    rows = list(csv.DictReader(io.StringIO(exported.stdout)))
    assert len(rows) == 500 and {"x0", "x4", "fitness", "status"} <= set(rows[0])
    as_json = metaopt_cli("export", "1", "--format", "json", cwd=tmp_path, env=BASIC)
    document = json.loads(as_json.stdout)
    assert document["run"]["optimizer_params"]["hmcr"] == 0.95
    assert len(document["evaluations"]) == 500
    best_csv = min(float(r["fitness"]) for r in rows)
    assert best_csv == min(e["fitness"] for e in document["evaluations"])


def test_list_shows_every_plugin_and_one_in_full(tmp_path):
    overview = metaopt_cli("list", cwd=tmp_path, env={"METAOPT_LOAD_PLUGINS": None})
    assert overview.returncode == 0
    for name in ("hs", "ga", "random", "sphere", "rastrigin", "schwefel"):
        assert name in overview.stdout
    one = metaopt_cli("list", "hs", cwd=tmp_path)
    assert one.returncode == 0
    assert "hmcr" in one.stdout and "[0, 1]" in one.stdout and "pitch_adjust" in one.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "-o", "hss", "-p", "sphere"], "unknown optimizer 'hss'. Did you mean 'hs'?"),
        (["run", "-o", "hs", "-p", "spher"], "unknown problem 'spher'. Did you mean 'sphere'?"),
        (["run", "-o", "hs", "-p", "sphere", "--set", "hmcr=1.5"], "expected a float in [0, 1]"),
        (["run", "-o", "hs", "-p", "sphere", "--set", "hmcx=1"], "has a parameter 'hmcx'"),
        (["run", "-o", "hs", "-p", "sphere", "--set", "dim=ten"], "cannot read 'ten'"),
        (["run", "-o", "hs", "-p", "sphere", "--set", "dim"], "--set expects NAME=VALUE"),
        (["run", "-o", "hs", "-p", "sphere", "--budget", "0"], "0 is not in the range 1<=x"),
        # refused by the optimizer as it is built: after the settings' checks, before a store
        (
            ["run", "-o", "hs", "-p", "sphere", "--set", "par_min=0.9", "--set", "par_max=0.1"],
            "par_min (0.9) must not exceed par_max (0.1)",
        ),
        (["run", "-o", "ga", "-p", "sphere", "--mode", "async"], "cannot run in async mode"),
        (["list", "nonesuch"], "unknown plugin 'nonesuch'"),
        (["show", "3"], "no run store at metaopt.db"),
    ],
)
def test_bad_input_gives_one_clear_line_and_exit_2(tmp_path, args, message):
    done = metaopt_cli(*args, cwd=tmp_path, env=BASIC)
    assert done.returncode == 2
    assert message in done.stderr
    assert "Traceback" not in done.stderr + done.stdout
    assert not (tmp_path / "metaopt.db").exists() or args[0] != "run"


def test_foreign_db_file_is_refused_and_kept(tmp_path):
    precious = tmp_path / "thesis.db"
    precious.write_bytes(b"not a database at all")
    done = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--db", str(precious), cwd=tmp_path,
                       env=BASIC)  # fmt: skip
    assert done.returncode == 2 and "not a SQLite database" in done.stderr
    assert precious.read_bytes() == b"not a database at all"


def test_replay_reproduces_the_stored_best_and_rejects_foreign_settings(tmp_path):
    metaopt_cli("run", "-o", "ga", "-p", "rastrigin", "--budget", "300", "--seed", "2",
                cwd=tmp_path, env=BASIC)  # fmt: skip
    stored = metaopt_cli("export", "1", "--format", "json", cwd=tmp_path, env=BASIC)
    best = min(e["fitness"] for e in json.loads(stored.stdout)["evaluations"])
    replayed = metaopt_cli("replay", "1", cwd=tmp_path, env=BASIC)
    assert replayed.returncode == 0, replayed.stderr
    fitness_row = next(line for line in replayed.stdout.splitlines() if "fitness" in line)
    assert fitness_row.count(f"{best:.6g}") == 2  # stored and replayed agree
    wrong = metaopt_cli("replay", "1", "--backend", "pybullet", cwd=tmp_path, env=BASIC)
    assert wrong.returncode == 2
    assert "problem 'rastrigin' has no parameter 'backend'" in wrong.stderr
    # RUN:CANDIDATE replays another candidate than the best, with its own seed
    evaluations = json.loads(stored.stdout)["evaluations"]
    worse = next(e for e in evaluations if e["fitness"] > 2 * best)
    other = metaopt_cli("replay", f"1:{worse['candidate']}", cwd=tmp_path, env=BASIC)
    assert other.returncode == 0, other.stderr
    fitness_row = next(line for line in other.stdout.splitlines() if "fitness" in line)
    assert fitness_row.count(f"{worse['fitness']:.6g}") == 2
    for target, message in (
        (
            "1:x",
            "neither a stored candidate (none) nor a run (RUN, RUN:CANDIDATE or RUN:recommended)",
        ),
        ("1:9999", "no candidate 9999"),
    ):
        refused = metaopt_cli("replay", target, cwd=tmp_path, env=BASIC)
        assert refused.returncode == 2 and message in refused.stderr
        assert "Traceback" not in refused.stderr


def test_run_stops_at_the_target_and_refuses_a_non_finite_one(tmp_path):
    done = metaopt_cli(
        "run", "-o", "hs", "-p", "sphere", "--budget", "20000", "--seed", "1", "--target", "0.01",
        cwd=tmp_path, env=BASIC,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    stored = metaopt_cli("export", "1", "--format", "json", cwd=tmp_path, env=BASIC)
    fitness = [e["fitness"] for e in json.loads(stored.stdout)["evaluations"]]
    assert len(fitness) < 20000 and fitness[-1] <= 0.01 < min(fitness[:-1])
    bad = metaopt_cli("run", "-o", "hs", "-p", "sphere", "--target", "inf", cwd=tmp_path, env=BASIC)
    assert bad.returncode == 2 and "target must be a finite fitness" in bad.stderr


def _untimed_evaluations(run: str, cwd) -> list[dict]:
    """A run's exported evaluations without their wall time, the one thing timing decides."""
    exported = json.loads(metaopt_cli("export", run, "--format", "json", cwd=cwd).stdout)
    return [{k: v for k, v in e.items() if k != "wall_time"} for e in exported["evaluations"]]


def test_run_stops_at_its_max_time_having_done_what_a_longer_run_does_first(tmp_path):
    """--max-time ends the run finished, its budget unspent, and says so; its evaluations are
    the first ones of the same run given more time (sync: the seed and budget decide them),
    and `metaopt resume --max-time` continues it as that run."""
    for max_time in ("0.8", "1.6"):
        done = metaopt_cli(
            "run", "-o", "hs", "-p", "sphere", "--budget", "10000000", "--seed", "3",
            "--batch", "4", "--max-time", max_time, cwd=tmp_path, env=BASIC,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
    shown = [
        json.loads(metaopt_cli("show", run, "--format", "json", cwd=tmp_path).stdout)
        for run in ("1", "2")
    ]
    counts = [run["evaluations"] for run in shown]
    assert 0 < counts[0] < counts[1] < 10_000_000
    assert shown[0]["status"] == "finished"
    assert shown[0]["message"] == (
        f"stopped at its max time of 0.8 s after {counts[0]} of 10000000 evaluations"
    )
    assert shown[1]["settings"]["max_time"] == 1.6 and shown[1]["wall_time"] < 1.6 + 5
    assert counts[0] % 4 == 0  # the batch in flight finished
    runs = [_untimed_evaluations(run, tmp_path) for run in ("1", "2")]
    assert runs[0] == runs[1][: counts[0]]
    resumed = metaopt_cli("resume", "1", "--max-time", "0.8", cwd=tmp_path, env=BASIC)
    assert resumed.returncode == 0, resumed.stderr
    more = json.loads(metaopt_cli("show", "1", "--format", "json", cwd=tmp_path).stdout)
    assert more["evaluations"] > counts[0] and more["settings"]["max_time"] == 0.8
    longer = _untimed_evaluations("1", tmp_path)
    shared = min(len(longer), counts[1])
    assert longer[:shared] == runs[1][:shared]  # the same run, continued
    bad = metaopt_cli("resume", "1", "--max-time", "0", cwd=tmp_path, env=BASIC)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


def test_resume_with_a_larger_budget_continues_a_run_that_spent_its_budget(tmp_path):
    """`metaopt resume RUN --budget N` continues a finished CMA-ES run (no schedule over its
    budget) as the run given N at once; a budget not above the evaluations it has made, or none
    for a finished run, is refused in one line and leaves the run as it was."""
    cmaes = {"METAOPT_LOAD_PLUGINS": "cma_es,functions"}
    for budget in ("60", "120"):
        done = metaopt_cli("run", "-o", "cmaes", "-p", "sphere", "--budget", budget, "--seed",
                           "4", cwd=tmp_path, env=cmaes)  # fmt: skip
        assert done.returncode == 0, done.stderr
    for args, says in (((), "already finished; nothing to resume"),
                       (("--budget", "60"), "more than the 60 evaluations run 1 has made"),
                       (("--budget", "0"), "Invalid value for '--budget'")):  # fmt: skip
        refused = metaopt_cli("resume", "1", *args, cwd=tmp_path, env=cmaes)
        assert refused.returncode == 2 and says in refused.stderr
        assert len(refused.stderr.strip().splitlines()) == 1
    assert json.loads(metaopt_cli("show", "1", "--format", "json", cwd=tmp_path).stdout)[
        "budget"] == 60  # fmt: skip
    resumed = metaopt_cli("resume", "1", "--budget", "120", cwd=tmp_path, env=cmaes)
    assert resumed.returncode == 0, resumed.stderr
    shown = json.loads(metaopt_cli("show", "1", "--format", "json", cwd=tmp_path).stdout)
    assert (shown["evaluations"], shown["budget"], shown["status"]) == (120, 120, "finished")
    assert _untimed_evaluations("1", tmp_path) == _untimed_evaluations("2", tmp_path)
