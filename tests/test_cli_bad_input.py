"""Generated bad input for every command and option of `metaopt`, run in process through
click's CliRunner (the same code as the console script, without a process per case): wrong
types, out-of-range, empty, huge and negative values, unknown names, and paths that are
folders, missing, unwritable or foreign files. Each must be refused with exit code 2 and one
'Error:' line on stderr that names what was wrong, with no traceback, leaving the store and
every file in the working folder as they were."""

from __future__ import annotations

import hashlib
import json
import sqlite3
import string
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from metaopt.cli import main
from metaopt.errors import ConfigError
from metaopt.plugins import registry
from metaopt.scaffold import plugin_names
from metaopt.storage.run_store import RunStore
from tests.conftest import metaopt_cli

MAX_INT64 = 2**63 - 1
#: Characters of generated names and values: letters, digits, punctuation that means something
#: to a shell, to rich markup ('[', ']') or to paths, and whitespace (a newline included).
ALPHABET = string.ascii_letters + string.digits + "-_.:/=[]'\" \n"

FOREIGN_TEXT = "notes.txt"
FOREIGN_SQLITE = "other.db"
FOLDER = "folder"
BAD_FILE_PATHS = [FOLDER, f"{FOLDER}/", "missing/dir/out.csv", "/proc/metaopt-out.csv"]
BAD_FOLDER_PATHS = [FOREIGN_TEXT, f"{FOREIGN_TEXT}/sub", "/proc/metaopt-out"]
BAD_STORES = [FOLDER, FOREIGN_TEXT, FOREIGN_SQLITE, "missing/dir/x.db", "/proc/x.db"]


def _text(min_size: int = 0) -> st.SearchStrategy[str]:
    return st.text(ALPHABET, min_size=min_size, max_size=12)


def _not_an_integer() -> st.SearchStrategy[str]:
    return st.one_of(
        _text().filter(lambda t: not t.strip().lstrip("+-").isdigit()),
        st.floats(allow_nan=True, allow_infinity=True)
        .filter(lambda f: f != f or f in (float("inf"), -float("inf")) or not f.is_integer())
        .map(repr),
    )


def _int_outside(low: int | None, high: int | None) -> st.SearchStrategy[str]:
    """Integers below low or above high (as text), and text that is no integer."""
    parts = [_not_an_integer()]
    if low is not None:
        parts.append(st.integers(min_value=-(10**30), max_value=low - 1).map(str))
    if high is not None:
        parts.append(st.integers(min_value=high + 1, max_value=10**30).map(str))
    return st.one_of(parts)


def _bad_seconds(option: str, most: float, named: str):
    """A case: `run` with option at no more than 0 s, above ``most`` s, NaN or no number."""
    values = st.one_of(
        st.floats(max_value=0).map(repr),
        st.floats(min_value=most, exclude_min=True).map(repr),
        st.just("nan"),
        _text().filter(lambda t: not _is_float(t)),
    )
    return _option(RUN_BASE, option, values, also=(named,))


def _not_in(choices: list[str]) -> st.SearchStrategy[str]:
    return _text().filter(lambda t: t not in choices and not t.startswith("-"))


def _unknown_name(known: list[str]) -> st.SearchStrategy[str]:
    return _text().filter(lambda t: t not in known and not t.startswith("-"))


#: Run ids of no run: the store holds run 1 only.
_RUN_ID = st.one_of(
    _not_an_integer(), st.integers(-(10**30), 0).map(str), st.integers(2, 10**30).map(str)
)
RUN_BASE = ["run", "-o", "hs", "-p", "sphere", "--budget", "5", "--set", "dim=2"]
COMPARE_BASE = ["compare", "-o", "hs", "-p", "sphere", "--seeds", "1", "--budget", "5"]
COMMANDS = ["list", "run", "resume", "runs", "show", "history", "export", "replay", "report",
            "compare", "robustness", "robustness-summary", "robustness-rank", "new"]  # fmt: skip
#: Every installed name, so that a generated "unknown" name never names a real plugin.
OPTIMIZERS, PROBLEMS = sorted(registry().optimizers), sorted(registry().problems)
PLUGINS = sorted(name for table in registry().tables().values() for name in table)


@st.composite
def bad_invocation(draw) -> tuple[list[str], list[str]]:
    """(arguments, what the error line must name: one of these strings)."""
    kind = draw(st.sampled_from(sorted(_CASES)))
    return _CASES[kind](draw)


def _option(base: list[str], option: str, values: st.SearchStrategy[str], also: tuple = ()):
    """A case: base arguments plus option with a bad value; the line names the option or the
    value (or one of ``also``, for errors found past the option's own parsing)."""

    def case(draw):
        value = draw(values)
        return [*base, option, value], [option, value, repr(value), *also]

    return case


def _argument(before: list[str], values: st.SearchStrategy[str], after: tuple = ()):
    def case(draw):
        value = draw(values)
        names = [value, repr(value), "run id", "run ", "plugin"]
        if value.startswith("-"):  # read as short options: the first one is named
            names += [value[:2], value[:2].encode("unicode_escape").decode()]  # as printed
        return [*before, value, *after], names

    return case


def _set(base: list[str]):
    pairs = st.one_of(
        _text().filter(lambda t: "=" not in t),  # no NAME=VALUE
        _text().map(lambda t: f"={t}"),  # no name
        st.sampled_from(["zz=1", "dim=-3", "dim=x", "dim=1.5", "hmcr=2", "hms=0", "dim="]),
    )

    def case(draw):
        pair = draw(pairs)
        return [*base, "--set", pair], ["--set", pair.partition("=")[0].strip() or pair, "dim"]

    return case


def _db(command: list[str]):
    def case(draw):
        path = draw(st.sampled_from(BAD_STORES))
        return [*command, "--db", path], [path]

    return case


def _unknown_option(draw):
    command = draw(st.sampled_from(COMMANDS))
    name = draw(st.text(string.ascii_lowercase, min_size=1, max_size=8))
    option = "--" + ("x" + name if name in ("help", "version") else name)
    return [command, option], [option]


_CASES = {
    # run
    "run -o": lambda d: _argument(["run", "-o"], _unknown_name(OPTIMIZERS), ("-p", "sphere"))(d),
    "run -p": lambda d: _argument(["run", "-o", "hs", "-p"], _unknown_name(PROBLEMS))(d),
    "run --budget": _option(RUN_BASE[:5], "--budget", _int_outside(1, MAX_INT64)),
    "run --seed": _option(RUN_BASE, "--seed", _int_outside(0, MAX_INT64)),
    "run --batch": _option(RUN_BASE, "--batch", _int_outside(0, None)),
    "run --resample": _option(
        RUN_BASE, "--resample", st.one_of(_int_outside(1, None), st.integers(6, 10**9).map(str))
    ),
    "run --mode": _option(RUN_BASE, "--mode", _not_in(["sync", "async"])),
    "run --aggregate": _option(RUN_BASE, "--aggregate", _not_in(["mean", "median"])),
    "run --time-limit": _bad_seconds("--time-limit", 1e6, "time limit"),
    "run --max-time": _bad_seconds("--max-time", 1e9, "max time"),
    "run --set": _set(RUN_BASE),
    "run --start-from": _option(
        RUN_BASE, "--start-from", st.one_of(_RUN_ID, st.sampled_from(["hs_walk", "stride_mujoco"]))
    ),
    "run --start-spread": _option(
        RUN_BASE,
        "--start-spread",
        st.one_of(
            st.floats(max_value=0, exclude_max=True).map(repr),
            st.floats(min_value=1, exclude_min=True).map(repr),
            _text().filter(lambda t: not _is_float(t)),
        ),
    ),
    "run --start-points": _option(RUN_BASE, "--start-points", _int_outside(0, None)),
    "run --executor": _option(RUN_BASE, "--executor", _unknown_name(["serial", "process", "dask"])),
    "run --workers": _option(RUN_BASE, "--workers", _int_outside(1, 1024)),
    "run --scheduler": _option(
        RUN_BASE,
        "--scheduler",
        st.one_of(
            st.sampled_from(["http://127.0.0.1:8799", "", "tcp://", "a b:1", "tcp://h:p"]),
            _text().map(lambda t: f"http://{t}"),
        ),
    ),
    "run --db": _db(RUN_BASE),
    # resume
    "resume RUN": _argument(["resume"], st.one_of(_RUN_ID, st.just("1"))),  # 1 is finished
    "resume --workers": _option(["resume", "1"], "--workers", _int_outside(1, 1024)),
    "resume --executor": _option(["resume", "1"], "--executor", _unknown_name(["serial"])),
    "resume --db": _db(["resume", "1"]),
    # runs, show, history, export
    "runs --format": _option(["runs"], "--format", _not_in(["table", "csv", "json"])),
    "runs --db": _db(["runs"]),
    "show RUN": _argument(["show"], _RUN_ID),
    "show --format": _option(["show", "1"], "--format", _not_in(["table", "csv", "json"])),
    "show --recent": _option(["show", "1"], "--recent", _int_outside(1, MAX_INT64)),
    "show --db": _db(["show", "1"]),
    "history RUN": _argument(["history"], _RUN_ID),
    "history --format": _option(["history", "1"], "--format", _not_in(["table", "csv", "json"])),
    "history --window": _option(["history", "1"], "--window", _int_outside(1, MAX_INT64)),
    "history --metric": _option(["history", "1"], "--metric", _text()),  # sphere reports none
    "history --db": _db(["history", "1"]),
    "export RUN": _argument(["export"], _RUN_ID),
    "export --format": _option(["export", "1"], "--format", _not_in(["csv", "json"])),
    "export --output": _option(["export", "1"], "--output", st.sampled_from(BAD_FILE_PATHS)),
    "export --db": _db(["export", "1"]),
    # replay
    "replay RUN": _argument(["replay"], _RUN_ID),
    "replay --backend": _option(["replay", "1"], "--backend", _text(), also=("'backend'",)),
    "replay --set": _set(["replay", "1"]),
    "replay --video": _option(
        ["replay", "1"],
        "--video",
        st.one_of(
            st.sampled_from([*BAD_FILE_PATHS, "w.gif", "w.avi", "w"]),
            _text(1).filter(lambda t: "/" not in t and not t.lower().endswith(".mp4")),
        ),
    ),
    "replay --db": _db(["replay", "1"]),
    "replay --seeds": _option(["replay", "1"], "--seeds", _int_outside(1, None)),
    "replay --seed": _option(["replay", "1", "--seeds", "2"], "--seed", _int_outside(0, MAX_INT64)),
    # robustness (a stored nao-walk gait; every case is refused before any episode)
    "robustness NAME": _argument(["robustness"], _RUN_ID),
    "robustness --engines": _option(
        ["robustness", "hs_walk"],
        "--engines",
        _unknown_name(["mujoco", "pybullet", "ode"]),
        also=("unknown physics backend",),
    ),
    "robustness --seeds": _option(["robustness", "hs_walk"], "--seeds", _int_outside(1, 10_000)),
    "robustness --seed": _option(["robustness", "hs_walk"], "--seed", _int_outside(0, MAX_INT64)),
    "robustness --cells": _option(
        ["robustness", "hs_walk"],
        "--cells",
        _text(1).filter(lambda t: t.strip() not in {"nominal", "latency 1"}),
        also=("no perturbation",),
    ),
    "robustness --set": lambda d: _option(
        ["robustness", "hs_walk"],
        "--set",
        st.sampled_from(["zz=1", "noise=-1", "mass_scale=0", "latency=x", "lock=20", "x"]),
        also=("noise", "mass_scale", "latency", "lock", "zz"),
    )(d),
    "robustness --csv": _option(
        ["robustness", "hs_walk"], "--csv", st.sampled_from([*BAD_FILE_PATHS, "out.txt"])
    ),
    "robustness --figure": _option(
        ["robustness", "hs_walk"], "--figure", st.sampled_from([*BAD_FILE_PATHS, "out.jpg"])
    ),
    # report
    "report RUN": _argument(["report"], _RUN_ID),
    "report --out": _option(["report", "1"], "--out", st.sampled_from(BAD_FOLDER_PATHS)),
    "report --group-by": _option(["report", "1"], "--group-by", _not_in(["setup", "optimizer"])),
    "report --db": _db(["report", "1"]),
    "report --only": _option(["report", "1"], "--only", st.just("backend=ode")),
    "report --experiment": _option(
        ["report"],
        "--experiment",
        st.sampled_from([FOLDER, FOREIGN_TEXT, "missing.toml", "bad.toml"]),
    ),
    # compare
    "compare FILE": _argument(
        ["compare"], st.sampled_from([FOLDER, FOREIGN_TEXT, "missing.toml", "bad.toml"])
    ),
    "compare -o": lambda d: _argument(["compare", "-p", "sphere", "-o"], _unknown_name(OPTIMIZERS))(
        d
    ),
    "compare -p": lambda d: _argument(["compare", "-o", "hs", "-p"], _unknown_name(PROBLEMS))(d),
    "compare --seeds": _option(COMPARE_BASE[:5], "--seeds", _int_outside(1, 10_000)),
    "compare --budget": _option(COMPARE_BASE[:7], "--budget", _int_outside(1, MAX_INT64)),
    "compare --target": _option(
        COMPARE_BASE, "--target", _text().filter(lambda t: not _is_float(t))
    ),
    "compare --set": _set(COMPARE_BASE),
    "compare --csv": _option(COMPARE_BASE, "--csv", st.sampled_from(BAD_FILE_PATHS)),
    "compare --transfer-csv": _option(
        [*COMPARE_BASE, "--transfer"], "--transfer-csv", st.sampled_from(BAD_FILE_PATHS)
    ),
    "compare --format": _option(
        COMPARE_BASE, "--format", _not_in(["table", "csv", "json", "markdown"])
    ),
    "compare --no-run --db": _db([*COMPARE_BASE, "--no-run"]),
    "compare --workers": _option(COMPARE_BASE, "--workers", _int_outside(1, 1024)),
    "compare --jobs": _option(COMPARE_BASE, "--jobs", _int_outside(1, 1024)),
    "compare --at": _option(COMPARE_BASE, "--at", _int_outside(1, MAX_INT64)),
    "compare --db": _db(COMPARE_BASE),
    "compare --only": _option(
        COMPARE_BASE,
        "--only",
        st.one_of(
            _text().filter(lambda t: "=" not in t and not t.startswith("-")),
            _text().filter(lambda t: t.strip() != "optimizer").map(lambda t: f"{t}=1"),
            _text().filter(lambda t: t.strip() != "hs").map(lambda t: f"optimizer={t}"),
        ),
    ),
    # new, list
    "new KIND": _argument(["new"], _not_in(["optimizer", "problem"]), ("my_plugin",)),
    "new NAME": _argument(
        ["new", "optimizer"],
        st.one_of(
            st.sampled_from(["", "1abc", "a b", "hs", "a/b", "-"]),
            _text(1).filter(lambda t: _refused_name(t) and not t.startswith("-")),
        ),
    ),
    "new --directory": _option(
        ["new", "optimizer", "fresh_plugin_name"],
        "--directory",
        st.sampled_from([*BAD_FOLDER_PATHS, FOLDER]),
    ),
    "list NAME": _argument(["list"], _unknown_name(PLUGINS)),
    # anywhere
    "unknown option": _unknown_option,
    "unknown command": _argument([], _not_in(COMMANDS).filter(bool)),
}


def _refused_name(name: str) -> bool:
    """Whether `metaopt new`'s own naming rule refuses name ("utf-8" it accepts, though no
    Python identifier)."""
    try:
        plugin_names(name)
    except ConfigError:
        return True
    return False


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _snapshot(folder: Path) -> dict[str, str]:
    """Every file under folder by relative path, with a digest of its content."""
    return {
        str(path.relative_to(folder)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(folder.rglob("*"))
        if path.is_file()
    }


@pytest.fixture(scope="module")
def workplace(tmp_path_factory) -> Path:
    """A folder with a store holding one finished run, foreign files and a subfolder."""
    folder = tmp_path_factory.mktemp("workplace")
    store = str(folder / "metaopt.db")
    done = CliRunner().invoke(
        main, [*RUN_BASE[:5], "--budget", "30", "--set", "dim=2", "--db", store]
    )
    assert done.exit_code == 0, done.output
    (folder / FOREIGN_TEXT).write_text("not a store\n")
    with sqlite3.connect(folder / FOREIGN_SQLITE) as connection:
        connection.execute("CREATE TABLE notes (text TEXT)")
    (folder / FOLDER).mkdir()
    (folder / "bad.toml").write_text('name = "x"\nproblem = "sphere"\nunknown_key = 1\n')
    return folder


TRIED: set[tuple[str, ...]] = set()


@settings(
    max_examples=1500,
    deadline=None,
    derandomize=True,  # the same inputs on every run: a failure is reproducible
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.filter_too_much],
)
@given(case=bad_invocation())
def test_generated_bad_input_is_refused_in_one_line(workplace, monkeypatch, case):
    args, names = case
    monkeypatch.chdir(workplace)
    before = _snapshot(workplace)
    result = CliRunner().invoke(main, args, catch_exceptions=True)
    TRIED.add(tuple(args))
    assert result.exit_code == 2, (args, result.output, result.exception)
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        args,
        result.exception,
    )
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), (args, result.stderr)
    assert "Traceback" not in result.output
    assert any(name and name in lines[0] for name in names), (args, lines[0])
    assert _snapshot(workplace) == before, args


def test_the_sweep_tried_many_distinct_inputs():
    """Runs after the sweep (file order): reports how many distinct argument lists it tried."""
    if not TRIED:
        pytest.skip("run together with the sweep")
    print(f"\n{len(TRIED)} distinct bad invocations, none with a traceback")
    assert len(TRIED) >= 400


def _one_line(result, *needles: str) -> str:
    """The one 'Error: ...' line of a command refused with exit 2, holding needles."""
    assert result.exit_code == 2, (result.output, result.exception)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("target", ["nan", "inf", "-inf"])
def test_compare_refuses_a_target_that_is_no_finite_fitness(workplace, monkeypatch, target):
    """As metaopt run does: a NaN target counted every run a success, inf too."""
    monkeypatch.chdir(workplace)
    before = _snapshot(workplace)
    result = CliRunner().invoke(main, [*COMPARE_BASE, "--set", "dim=2", f"--target={target}"])
    _one_line(result, "target must be a finite fitness", target)
    (workplace / "nan-target.toml").write_text(
        f'name = "t"\nproblem = "sphere"\nseeds = 1\nbudget = 5\ntarget = {target}\n'
        '[[optimizers]]\nname = "random"\n'
    )
    result = CliRunner().invoke(main, ["compare", "nan-target.toml"])
    _one_line(result, "nan-target.toml: target must be a finite fitness", target)
    (workplace / "nan-target.toml").unlink()
    assert _snapshot(workplace) == before


@pytest.mark.parametrize(
    ("pairs", "warned", "stored"),
    [
        (["dim=3"], "--set dim is given twice (2, then 3): the last, 3, is used", {"dim": 3}),
        (["problem.dim=3"], "--set problem.dim is given twice (2, then 3)", {"dim": 3}),
    ],
)
def test_a_setting_given_twice_outside_compare_uses_the_last_and_says_so(
    tmp_path, pairs, warned, stored
):
    """run used the last of two values without a word, while compare makes a grid of them: it
    still uses the last (a script's defaults are overridden so), in one warning line."""
    args = [*RUN_BASE, *(a for pair in pairs for a in ("--set", pair))]
    done = metaopt_cli(*args, "--db", str(tmp_path / "m.db"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.startswith("Warning: --set")]
    assert len(lines) == 1 and warned in lines[0], done.stderr
    assert "a grid over values is metaopt compare's" in lines[0]
    shown = json.loads(metaopt_cli("show", "1", "--format", "json", "--db",
                                   str(tmp_path / "m.db"), cwd=tmp_path).stdout)  # fmt: skip
    assert shown["problem_params"] == stored


def test_compare_still_makes_a_grid_of_a_setting_given_twice(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = [*COMPARE_BASE, "--set", "dim=2", "--set", "dim=3", "--format", "csv"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "dim=2" in result.stdout and "dim=3" in result.stdout


def test_start_points_far_past_the_budget_are_refused_by_check(workplace, monkeypatch):
    """--check said every setting accepted, then the run failed with a MemoryError and stayed
    'running'."""
    monkeypatch.chdir(workplace)
    before = _snapshot(workplace)
    args = ["run", "-o", "cmaes", "-p", "sphere", "--budget", "20", "--set", "dim=2",
            "--start-from", "1", "--start-points", "100000000000000"]  # fmt: skip
    for extra in (["--check"], []):
        _one_line(CliRunner().invoke(main, [*args, *extra]), "100000000000000 start points",
                  "the 20 candidates the budget evaluates", "at most 1000000")  # fmt: skip
    assert _snapshot(workplace) == before


def test_a_run_or_candidate_given_twice_is_refused_not_counted_twice(
    workplace, monkeypatch, tmp_path
):
    """report's bands and robustness's ranking took one run (or candidate) named twice as two
    independent ones: refused in one line, however the second names it, before any work."""
    monkeypatch.chdir(workplace)
    before = _snapshot(workplace)
    with RunStore(workplace / "metaopt.db") as store:
        (best,) = store.best_candidates(store.run(1), 1)
    out = ["--out", str(tmp_path / "figures")]
    for args, needles in (
        (["report", "1", "1", *out], ["run 1 is given twice", "each run counts once"]),
        (["report", "1", "01", *out], ["run 01 is given twice"]),
        (["robustness", "1", "1"], ["'1' names run 1 again", "each candidate counts once"]),
        (["robustness", "1", f"1:{best.number}"], [f"'1:{best.number}' names run 1 candidate"]),
    ):
        _one_line(CliRunner().invoke(main, args), *needles)
    assert _snapshot(workplace) == before and not (tmp_path / "figures").exists()


@pytest.mark.parametrize(
    ("optimizer", "name"), [("ga", "population"), ("random", "batch_size"), ("hs", "hms")]
)
def test_a_population_or_batch_past_a_million_is_refused_in_one_line(
    tmp_path, monkeypatch, optimizer, name
):
    """As cmaes's population: a generation, batch or harmony memory of 10**7 is a slip that
    would fill memory (a GA run of budget 5 stored such a first population as its start points
    and ended in a MemoryError traceback), refused before any run."""
    monkeypatch.chdir(tmp_path)
    args = ["run", "-o", optimizer, "-p", "sphere", "--budget", "5", "--set", "dim=2"]
    result = CliRunner().invoke(main, [*args, "--set", f"{name}=10000000"])
    _one_line(result, f"'{name}' = 10000000 is invalid", "[", "1e+06]")
    assert list(tmp_path.iterdir()) == []


def test_a_sync_batch_past_a_million_is_refused_in_one_line(tmp_path, monkeypatch):
    """As the optimizers' populations: --batch 10**7, or batch = 10**7 in an experiment's run
    settings, is a slip that would fill memory, refused before any run."""
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, [*RUN_BASE, "--batch", "10000000"])
    _one_line(result, "'--batch'", "10000000 is not in the range 0<=x<=1000000")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "batch.toml").write_text(
        'name = "b"\nproblem = "sphere"\nseeds = 1\nbudget = 5\n'
        '[[optimizers]]\nname = "random"\nsettings = { batch = 10000000 }\n'
    )
    result = CliRunner().invoke(main, ["compare", "batch.toml"])
    _one_line(result, "batch.toml", "batch must be 0 (the optimizer's own) to 1,000,000")
    assert [path.name for path in tmp_path.iterdir()] == ["batch.toml"]


@pytest.mark.parametrize("optimizer", ["hs", "ga", "cmaes", "random"])
def test_a_budget_past_64_bits_is_refused_in_one_line_however_given(
    tmp_path, monkeypatch, optimizer
):
    """--set budget= had no upper bound where --budget has MAX_INT64: a budget of 10**30 ran
    (its schedules spanning it), and an experiment's overflowed the store in a traceback. Now
    --budget, --set budget= and an experiment's budget share one bound, refused before any
    run, each refusal writing it in the same digits."""
    monkeypatch.chdir(tmp_path)
    base = ["run", "-o", optimizer, "-p", "sphere", "--set", "dim=2"]
    for budget in (str(10**30), "1e30", str(MAX_INT64 + 1)):
        result = CliRunner().invoke(main, [*base, "--budget", "5", "--set", f"budget={budget}"])
        _one_line(result, "'budget' = ", "is invalid", f"[1, {MAX_INT64}]")
    result = CliRunner().invoke(main, [*base, "--budget", str(MAX_INT64 + 1)])
    _one_line(result, "'--budget'", f"1<=x<={MAX_INT64}")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "big.toml").write_text(
        f'name = "b"\nproblem = "sphere"\nseeds = 1\nbudget = {10**30}\n'
        f'[[optimizers]]\nname = "{optimizer}"\n'
    )
    result = CliRunner().invoke(main, ["compare", "big.toml"])
    _one_line(result, "big.toml", f"budget must be a positive number of evaluations, at most "
              f"{MAX_INT64} ", f"got {10**30}")  # fmt: skip
    assert [path.name for path in tmp_path.iterdir()] == ["big.toml"]


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--backend", "ode", "--set", "backend=pybullet"],
         ["--backend ode and --set backend=pybullet both choose the engine",
          "give one of --backend or --set backend"]),
        (["--set", "p.backend=bullet", "--backend", "bullet"],
         ["--backend bullet and --set backend=bullet both choose the engine"]),
        # alone, either is the engine, unwarned: here an unknown one, refused before any episode
        (["--backend", "bullet"], ["unknown physics backend 'bullet'"]),
        (["--set", "backend=bullet"], ["unknown physics backend 'bullet'"]),
    ],
)  # fmt: skip
def test_replay_takes_the_engine_from_backend_or_set_backend_not_both(
    tmp_path, monkeypatch, args, needles
):
    """replay turned --backend into one more --set backend: given both, it warned of a setting
    given twice and replayed on --backend's engine; now one line, before any episode."""
    monkeypatch.chdir(tmp_path)
    _one_line(CliRunner().invoke(main, ["replay", "hs_walk", *args]), *needles)
    assert list(tmp_path.iterdir()) == []
