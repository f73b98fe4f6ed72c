"""The paper's study, reproduced: Harmony Search vs GA tuning the Matsuoka CPG of nao-walk.

Three steps, each usable alone:

* ``--run``: every cell of the grid (optimizer setting x engine x seed) not yet finished in the
  run store (``--db``, default /tmp/paper-study.db) is run, two at a time in separate processes,
  each run serial inside (so a run depends only on its seed). Unfinished runs are resumed.
* ``--export``: small result files from the store into docs/paper-reproduction/: runs.csv (one
  row per run), convergence/*.csv (best so far and block mean per 25 evaluations), transfer.csv
  (each run's best replayed on the other engine), gaits.csv, and figures/ (PNG figures and
  MP4 videos drawn by `metaopt report`'s and `metaopt replay --video`'s code).
* ``--report-only``: docs/paper-reproduction.md rebuilt from those files alone.

With no option it does all three.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "paper-reproduction"
DOC = ROOT / "docs" / "paper-reproduction.md"
DEFAULT_DB = Path("/tmp/paper-study.db")
SEEDS = (1, 2, 3, 4, 5)
BLOCK = 25  # evaluations per row of a convergence file
ENGINES = ("mujoco", "pybullet")


@dataclass(frozen=True)
class Setting:
    """One optimizer configuration of the study."""

    label: str
    optimizer: str
    params: dict[str, Any] = field(hash=False)
    budget: int
    meaning: str


SETTINGS = {
    s.label: s
    for s in (
        # HMCR 0.9 and the GA's generational survival were the defaults when the study ran;
        # pinned here since the defaults changed (issue 17), so the runs still match.
        Setting("hs-paper", "hs", {"pitch_adjust": "resample", "hmcr": 0.9}, 750,
                "HS, the paper's pitch adjustment (a new uniform value)"),
        Setting("hs-classic", "hs", {"pitch_adjust": "bandwidth", "hmcr": 0.9}, 750,
                "HS, classic pitch adjustment (step within 1% of the range)"),
        Setting("hs-ihs", "hs", {"pitch_adjust": "ihs", "hmcr": 0.9}, 750,
                "improved HS (rising PAR, shrinking bandwidth)"),
        Setting("hs-ghs", "hs", {"pitch_adjust": "ghs", "hmcr": 0.9}, 750,
                "global-best HS"),
        Setting("ga", "ga", {"population": 200, "survival": "elites"}, 2000,
                "GA, 10 generations of 200 (the paper's)"),
    )
}  # fmt: skip


@dataclass(frozen=True)
class Cell:
    """One run of the grid."""

    label: str
    engine: str
    seed: int

    @property
    def setting(self) -> Setting:
        return SETTINGS[self.label]

    @property
    def name(self) -> str:
        return f"{self.label}-{self.engine}-s{self.seed}"


def grid(pybullet_ga_seeds: tuple[int, ...] = SEEDS) -> list[Cell]:
    """The study's runs, cheapest first: all MuJoCo (HS before GA), then PyBullet HS, then
    PyBullet GA (the most expensive, about 10x a MuJoCo episode and 2000 of them)."""
    cells = [Cell(label, "mujoco", s) for label in ("hs-paper", "hs-classic") for s in SEEDS]
    cells += [Cell(label, "mujoco", s) for label in ("hs-ihs", "hs-ghs") for s in SEEDS]
    cells += [Cell("ga", "mujoco", s) for s in SEEDS]
    cells += [Cell(label, "pybullet", s) for s in SEEDS for label in ("hs-paper", "hs-classic")]
    cells += [Cell("ga", "pybullet", s) for s in pybullet_ga_seeds]
    return cells


# -- running ---------------------------------------------------------------------------------


def _resolved(cell: Cell) -> tuple[dict[str, Any], dict[str, Any]]:
    """The cell's optimizer and problem parameters as the run loop stores them."""
    from metaopt.params import resolve
    from metaopt.plugins import registry

    plugins = registry()
    optimizer = plugins.optimizer(cell.setting.optimizer)
    problem = plugins.problem("nao-walk")
    given = dict(cell.setting.params)
    if any(p.name == "budget" for p in optimizer.params):
        given.setdefault("budget", cell.setting.budget)
    return (
        resolve(optimizer.params, given, optimizer.name),
        resolve(problem.params, {"backend": cell.engine}, problem.name),
    )


def is_done(store: Any, record: Any | None) -> bool:
    """The run finished and at least one evaluation succeeded (a run whose every evaluation
    failed, e.g. because the engine would not import, is run again)."""
    if record is None or record.status != "finished":
        return False
    total, failed = store.evaluation_counts(record.id)
    return failed < total


def find_run(store: Any, cell: Cell) -> Any | None:
    """The stored run of this cell (the latest if several), or None. A problem parameter the
    run does not record was added later and ran at its default."""
    optimizer_params, problem_params = _resolved(cell)
    found = None
    for record in store.runs():
        if (
            record.optimizer == cell.setting.optimizer
            and record.problem == "nao-walk"
            and record.seed == cell.seed
            and record.budget == cell.setting.budget
            and record.optimizer_params == optimizer_params
            and {**problem_params, **record.problem_params} == problem_params
            and record.settings.get("mode") == "sync"
            and record.settings.get("resample") == 1
        ):
            found = record
    return found


def run_cell(db: str, cell: Cell) -> tuple[str, int, str, float]:
    """Run (or resume) one cell serially in this process; (name, run id, status, wall s)."""
    from metaopt.plugins import registry
    from metaopt.run_loop import RunSpec, resume, run
    from metaopt.store import RunStore

    plugins = registry()
    optimizer = plugins.optimizer(cell.setting.optimizer)
    problem = plugins.problem("nao-walk")
    with RunStore(db) as store:
        record = find_run(store, cell)
        if is_done(store, record):
            return cell.name, record.id, "finished", float(record.wall_time or 0.0)
        if record is not None and record.status != "finished":
            result = resume(record.id, store, optimizer, problem)
        else:
            spec = RunSpec(
                optimizer=cell.setting.optimizer,
                problem="nao-walk",
                budget=cell.setting.budget,
                seed=cell.seed,
                optimizer_params=dict(cell.setting.params),
                problem_params={"backend": cell.engine},
            )
            result = run(spec, optimizer, problem, store)
        wall = float(store.run(result.run_id).wall_time or result.wall_time)
        return cell.name, result.run_id, result.status, wall


def record_code(db: Path) -> None:
    """Note beside the store which code runs the study: the metaopt package's folder and the
    commit (PAPER_STUDY_COMMIT, else the repository's HEAD), in DB.code.json."""
    import os
    import subprocess

    import metaopt

    commit = (
        os.environ.get("PAPER_STUDY_COMMIT")
        or subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
    )
    note = {"metaopt": str(Path(metaopt.__file__).parent), "commit": commit}
    Path(f"{db}.code.json").write_text(json.dumps(note, indent=2) + "\n")


def run_grid(db: Path, cells: list[Cell], workers: int) -> None:
    """Every unfinished cell, ``workers`` runs at a time, in grid order."""
    from metaopt.store import RunStore

    with RunStore(db) as store:
        todo = [c for c in cells if not is_done(store, find_run(store, c))]
    record_code(db)
    print(f"{len(cells) - len(todo)} of {len(cells)} runs already finished; {len(todo)} to run")
    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        pending: dict[Future, Cell] = {}
        queue = list(todo)
        while queue or pending:
            while queue and len(pending) < workers:
                cell = queue.pop(0)
                pending[pool.submit(run_cell, str(db), cell)] = cell
            done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            for future in done:
                cell = pending.pop(future)
                try:
                    name, run_id, status, wall = future.result()
                    print(f"[{time.perf_counter() - started:7.0f} s] {name}: run {run_id} "
                          f"{status} in {wall:.0f} s", flush=True)  # fmt: skip
                except Exception as error:  # one bad cell must not stop the study
                    print(f"{cell.name}: {type(error).__name__}: {error}", flush=True)


# -- exporting -------------------------------------------------------------------------------

PARAM_NAMES = ("tau1", "tau2", "alpha", "beta", "gamma", "c", "w11", "w12", "b1", "b2")
RUN_COLUMNS = (
    "run", "label", "optimizer", "settings", "engine", "seed", "status", "evaluations",
    "failed", "best_fitness", "distance", "speed", "drift", "fell", "time_walked",
    "height_min", "best_index", "wall_time", "cpu_eval_time", *PARAM_NAMES,
)  # fmt: skip
CONVERGENCE_COLUMNS = ("evaluations", "best_so_far", "mean", "block_best", "fell", "eval_time")
TRANSFER_COLUMNS = (
    "run", "label", "engine", "seed", "found_fitness", "found_distance", "found_fell",
    "replay_engine", "replay_fitness", "replay_distance", "replay_drift", "replay_fell",
    "replay_time_walked",
)  # fmt: skip


def _fmt(value: Any) -> str:
    """CSV text of a value: floats with 6 significant digits, the rest as str."""
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _write_csv(path: Path, columns: tuple[str, ...], rows: list[dict[str, Any]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(columns)
        for row in rows:
            writer.writerow([_fmt(row[c]) for c in columns])


def _read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def settings_text(setting: Setting) -> str:
    """The setting's explicit parameters as NAME=VALUE pairs."""
    return " ".join(f"{k}={v}" for k, v in setting.params.items())


def convergence(evaluations: list[Any], block: int = BLOCK) -> list[dict[str, Any]]:
    """Best so far (fitness, maximized), block mean and best, fall fraction and mean
    evaluation time per ``block`` evaluations; failed evaluations count in no mean."""
    rows, best = [], -math.inf
    for start in range(0, len(evaluations), block):
        chunk = evaluations[start : start + block]
        values = [e.fitness for e in chunk if e.fitness is not None]
        falls = [e.metrics.get("fell", 0.0) for e in chunk if e.fitness is not None]
        if values:
            best = max(best, *values)
        rows.append(
            {
                "evaluations": start + len(chunk),
                "best_so_far": best,
                "mean": sum(values) / len(values) if values else math.nan,
                "block_best": max(values) if values else math.nan,
                "fell": sum(falls) / len(falls) if falls else math.nan,
                "eval_time": sum(e.wall_time for e in chunk) / len(chunk),
            }
        )
    return rows


def export(db: Path, cells: list[Cell], out: Path = OUT, transfer: bool = True) -> None:
    """runs.csv, convergence/NAME.csv and transfer.csv from the finished runs in the store."""
    from metaopt.plugins import registry
    from metaopt.replay import replay_best
    from metaopt.store import RunStore

    runs, transfers = [], []
    old = {r["run"]: r for r in _read_csv(out / "transfer.csv")} if (
        out / "transfer.csv").exists() else {}  # fmt: skip
    with RunStore(db) as store:
        for cell in cells:
            record = find_run(store, cell)
            if not is_done(store, record):
                continue
            evaluations = list(store.evaluations(record.id))
            best = store.best_evaluation(record)
            metrics = best.metrics
            runs.append(
                {
                    "run": cell.name, "label": cell.label, "optimizer": record.optimizer,
                    "settings": settings_text(cell.setting), "engine": cell.engine,
                    "seed": cell.seed, "status": record.status, "evaluations": len(evaluations),
                    "failed": sum(e.status == "failed" for e in evaluations),
                    "best_fitness": best.fitness, "distance": metrics["distance"],
                    "speed": metrics["speed"], "drift": metrics["drift"],
                    "fell": int(metrics["fell"]), "time_walked": metrics["time_walked"],
                    "height_min": metrics["height_min"], "best_index": best.index,
                    # serial runs: never less than their evaluations took (a resumed run's
                    # stored wall time covers only its last session)
                    "wall_time": max(
                        float(record.wall_time or 0.0), sum(e.wall_time for e in evaluations)
                    ),
                    "cpu_eval_time": sum(e.wall_time for e in evaluations),
                    **dict(zip(PARAM_NAMES, (float(v) for v in best.x))),
                }
            )  # fmt: skip
            _write_csv(
                out / "convergence" / f"{cell.name}.csv",
                CONVERGENCE_COLUMNS,
                convergence(evaluations),
            )
            if not transfer:
                continue
            other = ENGINES[1 - ENGINES.index(cell.engine)]
            if cell.name in old and old[cell.name]["found_fitness"] == _fmt(best.fitness):
                transfers.append(old[cell.name])
                continue
            replay = replay_best(store, record.id, registry(), {"backend": other})
            got = replay.replayed
            transfers.append(
                {
                    "run": cell.name, "label": cell.label, "engine": cell.engine,
                    "seed": cell.seed, "found_fitness": best.fitness,
                    "found_distance": metrics["distance"], "found_fell": int(metrics["fell"]),
                    "replay_engine": other,
                    "replay_fitness": got.fitness if got.fitness is not None else math.nan,
                    "replay_distance": got.metrics.get("distance", math.nan),
                    "replay_drift": got.metrics.get("drift", math.nan),
                    "replay_fell": int(got.metrics.get("fell", 1)),
                    "replay_time_walked": got.metrics.get("time_walked", math.nan),
                }
            )  # fmt: skip
    _write_csv(out / "runs.csv", RUN_COLUMNS, runs)
    if transfer:
        _write_csv(out / "transfer.csv", TRANSFER_COLUMNS, transfers)
    print(f"exported {len(runs)} runs to {out}")


# -- figures and video --------------------------------------------------------------------------

FIGURES = OUT / "figures"
#: The paper's two optimizers: the best run of each on each engine gets its own figures.
FIGURE_LABELS = ("hs-paper", "ga")


def export_figures(db: Path, cells: list[Cell], out: Path = FIGURES) -> None:
    """PNG figures and MP4 videos drawn by metaopt's own report and video code from the store:
    per engine, the best-so-far bands of every setting; for the best hs-paper and ga run per
    engine, its convergence (Figs. 4-5) and its best gait (Figs. 6-10); and a video of the
    study's best walk on each engine."""
    from metaopt.convergence import best_so_far_band, run_convergence
    from metaopt.plots import bands_figure, save_figure
    from metaopt.plugins import registry
    from metaopt.report import run_figures
    from metaopt.store import RunStore
    from metaopt.video import film_best

    plugins = registry()
    out.mkdir(parents=True, exist_ok=True)
    with RunStore(db) as store:
        for engine in ENGINES:
            done = [(c, find_run(store, c)) for c in cells if c.engine == engine]
            done = [(c, r) for c, r in done if is_done(store, r)]
            if not done:
                continue
            bands = {
                label: best_so_far_band([run_convergence(store, r) for c, r in done
                                         if c.label == label])
                for label in SETTINGS if any(c.label == label for c, _ in done)
            }  # fmt: skip
            title = f"nao-walk on {ENGINE_NAMES[engine]}: best fitness so far"
            save_figure(bands_figure(bands, True, title), out / f"convergence-{engine}.png")
            best_fitness = {c: store.best_evaluation(r).fitness for c, r in done}
            for label in FIGURE_LABELS:
                runs = [(c, r) for c, r in done if c.label == label]
                if runs:
                    cell, record = max(runs, key=lambda pair: best_fitness[pair[0]])
                    for stem, figure in run_figures(store, record.id, plugins).figures.items():
                        save_figure(figure, out / f"{cell.name}-{stem}.png")
            cell, record = max(done, key=lambda pair: best_fitness[pair[0]])
            film_best(store, record.id, plugins, {}, out / f"best-walk-{engine}-{cell.name}.mp4")
    print(f"figures and videos in {out}")


# -- what the best gaits do --------------------------------------------------------------------

GAIT_COLUMNS = (
    "run", "label", "engine", "seed", "distance", "free_oscillation", "period",
    "hip_target_swing", "hip_swing", "knee_target_swing", "knee_swing", "knee_mean",
    "hip_mean", "height_min", "torso_drop",
)  # fmt: skip
SETTLE = 2.0  # seconds of walking left out before a gait's swing and period are measured


def gait_features(trajectory: dict[str, Any], period: float = 0.02) -> dict[str, float]:
    """Swing (peak to peak, degrees, paper convention), mean angles and dominant period (s) of
    the left leg after the first SETTLE seconds; the period is nan when the hip swings < 0.5°."""
    import numpy as np

    keep = trajectory["time"] > SETTLE
    hip_target = -np.degrees(trajectory["llj3_target"][keep])
    hip = -np.degrees(trajectory["llj3_angle"][keep])
    knee_target = np.degrees(trajectory["llj4_target"][keep])
    knee = np.degrees(trajectory["llj4_angle"][keep])
    features = {
        "hip_target_swing": float(np.ptp(hip_target)) if len(hip) else math.nan,
        "hip_swing": float(np.ptp(hip)) if len(hip) else math.nan,
        "knee_target_swing": float(np.ptp(knee_target)) if len(hip) else math.nan,
        "knee_swing": float(np.ptp(knee)) if len(hip) else math.nan,
        "knee_mean": float(np.mean(knee)) if len(hip) else math.nan,
        "hip_mean": float(np.mean(hip)) if len(hip) else math.nan,
        "period": math.nan,
    }
    if len(hip) >= 50 and features["hip_swing"] >= 0.5:
        spectrum = np.abs(np.fft.rfft(hip - hip.mean()))
        frequencies = np.fft.rfftfreq(len(hip), period)
        peak = int(np.argmax(spectrum[1:])) + 1
        features["period"] = float(1.0 / frequencies[peak])
    return features


def export_gaits(db: Path, cells: list[Cell], out: Path = OUT) -> None:
    """gaits.csv: each run's best gait replayed with a recorded trajectory on its own engine."""
    from metaopt.plugins import registry
    from metaopt.store import RunStore
    from metaopt_problems.nao_walk.controller import oscillation_conditions_hold

    info = registry().problem("nao-walk")
    problems: dict[str, Any] = {}
    rows = []
    with RunStore(db) as store:
        for cell in cells:
            record = find_run(store, cell)
            if not is_done(store, record):
                continue
            best = store.best_evaluation(record)
            if cell.engine not in problems:
                problems[cell.engine] = info.factory(backend=cell.engine)
            problem = problems[cell.engine]
            result = problem.runner.run(problem.gait(best.x), record=True)
            rows.append(
                {
                    "run": cell.name, "label": cell.label, "engine": cell.engine,
                    "seed": cell.seed, "distance": result.distance,
                    "free_oscillation": int(oscillation_conditions_hold(best.x)),
                    **gait_features(result.trajectory), "height_min": result.height_min,
                    "torso_drop": 0.385 - result.height_min,
                }
            )  # fmt: skip
    for problem in problems.values():
        problem.close()
    _write_csv(out / "gaits.csv", GAIT_COLUMNS, rows)


def swing_bounds(samples: int = 400, seed: int = 0) -> dict[str, float]:
    """How far Table 2's box lets the hip and knee targets swing: the peak-to-peak output of
    free (alpha = 0) oscillators drawn uniformly from the box where Matsuoka's conditions hold,
    times the largest |w11| = 4 and |w12| = 5."""
    import numpy as np

    from metaopt_problems.nao_walk.controller import (
        MatsuokaCpg,
        cpg_space,
        oscillation_conditions_hold,
    )

    space = cpg_space()
    lower = np.array([v.lower for v in space.variables])
    upper = np.array([v.upper for v in space.variables])
    rng = np.random.default_rng(seed)
    loose = (-3.0, 3.0)
    swings, drawn = [], 0
    while len(swings) < samples:
        x = lower + rng.random(10) * (upper - lower)
        x[2] = 0.0  # alpha: the free oscillator
        drawn += 1
        if not oscillation_conditions_hold(x):
            continue
        cpg = MatsuokaCpg(list(x), loose, loose, loose)
        outputs = []
        for _ in range(750):
            cpg.step(0.0, 0.0)
            outputs.append(cpg.outputs[0])
        tail = np.array(outputs[250:])
        swings.append(float(tail.max() - tail.min()))
    y = np.array(swings)
    result = {"samples": samples, "oscillating_fraction": samples / drawn}
    for name, q in (("median", 50), ("p90", 90), ("max", 100)):
        result[f"y_swing_{name}"] = float(np.percentile(y, q))
        result[f"hip_swing_{name}"] = 4.0 * float(np.percentile(y, q))
        result[f"knee_swing_{name}"] = 5.0 * float(np.percentile(y, q))
    return result


# -- the study record (machine, versions, elapsed time) ----------------------------------------


def write_study_record(db: Path, cells: list[Cell], out: Path = OUT) -> None:
    """study.json: the machine, the engine versions and when the study ran."""
    import os
    import platform
    from datetime import datetime

    from metaopt.store import RunStore

    with RunStore(db) as store:
        finished = [r for c in cells if is_done(store, r := find_run(store, c))]
    started = min(datetime.fromisoformat(r.started_at) for r in finished)
    ended = max(datetime.fromisoformat(r.ended_at) for r in finished)
    model = "unknown"
    if Path("/proc/cpuinfo").exists():
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    record = {
        "machine": f"{os.cpu_count()} cores ({model}), shared with other work; "
        f"{platform.system()} {platform.release()}",
        "workers": 2,
        "versions": finished[-1].versions,
        "started": started.isoformat(),
        "ended": ended.isoformat(),
        "elapsed_s": (ended - started).total_seconds(),
        "runs_finished": len(finished),
        "runs_in_grid": len(cells),
    }
    code = Path(f"{db}.code.json")
    if code.exists():
        record["code"] = json.loads(code.read_text())["commit"]
    (out / "study.json").write_text(json.dumps(record, indent=2) + "\n")


# -- the report ------------------------------------------------------------------------------

PAPER = {
    "hs": {"distance": 5.3, "speed": 0.44, "evaluations": 750, "hours": 2.0},
    "ga": {"distance": 4.2, "speed": 0.35, "evaluations": 2000, "hours": 7.0},
}
ENGINE_NAMES = {"mujoco": "MuJoCo", "pybullet": "PyBullet"}


def _quartiles(values: list[float]) -> tuple[float, float, float]:
    import numpy as np

    q1, q2, q3 = np.percentile(np.asarray(values, dtype=float), [25, 50, 75])
    return float(q1), float(q2), float(q3)


def median_iqr(values: list[float], digits: int = 3) -> str:
    """'median (Q1–Q3)' with the given decimals; '–' for no values."""
    if not values:
        return "–"
    q1, q2, q3 = _quartiles(values)
    return f"{q2:.{digits}f} ({q1:.{digits}f}–{q3:.{digits}f})"


def median(values: list[float]) -> float:
    return _quartiles(values)[1] if values else math.nan


def p_value(a: list[float], b: list[float]) -> float:
    """Two-sided Mann–Whitney U (rank-sum) p-value; nan when a side is empty."""
    from scipy.stats import mannwhitneyu

    if not a or not b:
        return math.nan
    return float(mannwhitneyu(a, b, alternative="two-sided").pvalue)


def _p(value: float) -> str:
    return "–" if math.isnan(value) else f"{value:.3f}"


def _table(header: list[str], rows: list[list[str]], align: str = "") -> str:
    align = align or "l" + "r" * (len(header) - 1)
    marks = {"l": "---", "r": "--:", "c": ":-:"}
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(marks[a] for a in align) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


class Results:
    """The committed result files, read back."""

    def __init__(self, out: Path = OUT) -> None:
        self.out = out
        self.runs = _read_csv(out / "runs.csv")
        self.transfer = _read_csv(out / "transfer.csv") if (out / "transfer.csv").exists() else []
        self.study = json.loads((out / "study.json").read_text())
        self.gaits = _read_csv(out / "gaits.csv")
        self.bounds = json.loads((out / "swing-bounds.json").read_text())
        self.curves = {
            r["run"]: _read_csv(out / "convergence" / f"{r['run']}.csv") for r in self.runs
        }

    def select(self, label: str, engine: str) -> list[dict[str, str]]:
        return [r for r in self.runs if r["label"] == label and r["engine"] == engine]

    def values(self, label: str, engine: str, column: str = "distance") -> list[float]:
        return [float(r[column]) for r in self.select(label, engine)]

    def best_at(self, label: str, engine: str, evaluations: int) -> list[float]:
        """Each run's best fitness after ``evaluations`` evaluations."""
        found = []
        for r in self.select(label, engine):
            rows = [c for c in self.curves[r["run"]] if int(c["evaluations"]) <= evaluations]
            if rows and int(rows[-1]["evaluations"]) == evaluations:
                found.append(float(rows[-1]["best_so_far"]))
        return found


def _cells_present(results: Results) -> list[tuple[str, str]]:
    order = [(s, e) for e in ENGINES for s in SETTINGS]
    return [(s, e) for s, e in order if results.select(s, e)]


def results_table(results: Results) -> str:
    """The paper's numbers beside ours, per setting and engine."""
    rows = []
    for key, name in (("hs", "paper: HS"), ("ga", "paper: GA")):
        paper = PAPER[key]
        rows.append([
            name, "rcssserver3d (ODE)", "1", f"{paper['distance']:.1f}", f"{paper['speed']:.2f}",
            "no", "–", str(paper["evaluations"]), f"{paper['hours']:.0f} h",
        ])  # fmt: skip
    for label, engine in _cells_present(results):
        chosen = results.select(label, engine)
        falls = sum(int(r["fell"]) for r in chosen)
        rows.append([
            f"`{label}`", ENGINE_NAMES[engine], str(len(chosen)),
            median_iqr(results.values(label, engine)),
            median_iqr(results.values(label, engine, "speed")),
            f"{falls} of {len(chosen)}", median_iqr(results.values(label, engine, "best_fitness")),
            str(SETTINGS[label].budget),
            median_iqr(results.values(label, engine, "wall_time"), 0) + " s",
        ])  # fmt: skip
    header = ["optimizer", "engine", "runs", "distance in 12 s, m", "speed, m/s", "best fell",
              "best fitness", "evaluations", "wall time per run"]  # fmt: skip
    return _table(header, rows, "llrrrrrrr")


CHECKPOINTS = (50, 100, 250, 500, 750, 1000, 1500, 2000)


def convergence_table(results: Results) -> str:
    """Median best fitness so far at fixed numbers of evaluations."""
    rows = []
    for label, engine in _cells_present(results):
        cells = []
        for n in CHECKPOINTS:
            values = results.best_at(label, engine, n)
            cells.append(f"{median(values):.3f}" if values else "")
        rows.append([f"`{label}`", ENGINE_NAMES[engine], *cells])
    return _table(["optimizer", "engine", *map(str, CHECKPOINTS)], rows)


def hs_vs_ga_table(results: Results) -> str:
    """Each HS setting against the GA: at its full budget and at the HS's 750 evaluations."""
    rows = []
    for engine in ENGINES:
        ga_full = results.values("ga", engine, "best_fitness")
        ga_750 = results.best_at("ga", engine, 750)
        for label in ("hs-paper", "hs-classic"):
            hs = results.values(label, engine, "best_fitness")
            if not hs or not ga_full:
                continue
            rows.append([
                ENGINE_NAMES[engine], f"`{label}`", median_iqr(hs), median_iqr(ga_750),
                _p(p_value(hs, ga_750)), median_iqr(ga_full), _p(p_value(hs, ga_full)),
            ])  # fmt: skip
    header = ["engine", "HS", "HS best fitness (750)", "GA at 750", "p", "GA at 2000", "p"]
    return _table(header, rows, "llrrrrr")


def pairwise_table(results: Results, labels: list[str], engine: str) -> str:
    """Median and IQR of best fitness per setting and the rank-sum p-value of every pair."""
    present = [s for s in labels if results.select(s, engine)]
    rows = []
    for a in present:
        va = results.values(a, engine, "best_fitness")
        rows.append([
            f"`{a}`", median_iqr(va), median_iqr(results.values(a, engine)),
            *(("" if a == b else _p(p_value(va, results.values(b, engine, "best_fitness"))))
              for b in present),
        ])  # fmt: skip
    header = ["setting", "best fitness", "distance, m", *(f"p vs `{b}`" for b in present)]
    return _table(header, rows)


def transfer_table(results: Results) -> str:
    """Found on one engine, replayed on the other: distances and falls."""
    rows = []
    for label, engine in _cells_present(results):
        chosen = [t for t in results.transfer if t["label"] == label and t["engine"] == engine]
        if not chosen:
            continue
        found = [float(t["found_distance"]) for t in chosen]
        replayed = [float(t["replay_distance"]) for t in chosen]
        falls = sum(int(t["replay_fell"]) for t in chosen)
        change = [r - f for f, r in zip(found, replayed)]
        other = chosen[0]["replay_engine"]
        rows.append([
            f"`{label}`", ENGINE_NAMES[engine], ENGINE_NAMES[other], str(len(chosen)),
            median_iqr(found), median_iqr(replayed), median_iqr(change),
            f"{falls} of {len(chosen)}",
        ])  # fmt: skip
    header = ["optimizer", "found on", "replayed on", "runs", "distance there, m",
              "distance replayed, m", "change, m", "fell on replay"]  # fmt: skip
    return _table(header, rows, "lllrrrrr")


def wall_table(results: Results) -> str:
    """Wall time per run, evaluations per second and the time per evaluation."""
    rows = []
    for label, engine in _cells_present(results):
        chosen = results.select(label, engine)
        walls = [float(r["wall_time"]) for r in chosen]
        rate = [int(r["evaluations"]) / float(r["wall_time"]) for r in chosen]
        per = [1000 * float(r["cpu_eval_time"]) / int(r["evaluations"]) for r in chosen]
        rows.append([
            f"`{label}`", ENGINE_NAMES[engine], str(SETTINGS[label].budget),
            median_iqr(walls, 0), median_iqr(rate, 1), median_iqr(per, 0), f"{sum(walls):.0f}",
        ])  # fmt: skip
    header = ["optimizer", "engine", "evaluations", "wall per run, s", "evaluations/s",
              "ms per evaluation", "sum of walls, s"]  # fmt: skip
    return _table(header, rows, "llrrrrr")


def runs_table(results: Results) -> str:
    """Every run: its best evaluation and cost."""
    rows = []
    for r in results.runs:
        rows.append([
            r["run"], r["settings"], f"{float(r['best_fitness']):.3f}",
            f"{float(r['distance']):.3f}", f"{float(r['drift']):+.3f}", r["fell"],
            r["best_index"], r["evaluations"], f"{float(r['wall_time']):.0f}",
        ])  # fmt: skip
    header = ["run", "settings", "best fitness", "distance, m", "drift, m", "fell",
              "found at evaluation", "evaluations", "wall, s"]  # fmt: skip
    return _table(header, rows, "llrrrrrrr")


def best_run(results: Results, label: str, engine: str) -> dict[str, str] | None:
    chosen = results.select(label, engine)
    return max(chosen, key=lambda r: float(r["best_fitness"])) if chosen else None


def gait_table(results: Results) -> str:
    """The best gait of each main setting: its 10 parameters, with Table 2's bounds."""
    from metaopt_problems.nao_walk.controller import cpg_space

    space = cpg_space()
    picks = [(s, e) for s, e in _cells_present(results) if s in ("hs-paper", "hs-classic", "ga")]
    chosen = [(s, e, best_run(results, s, e)) for s, e in picks]
    header = ["parameter", "bounds", *(f"`{s}` {ENGINE_NAMES[e]}" for s, e, _ in chosen)]
    rows = []
    for variable in space.variables:
        rows.append([
            variable.name, f"[{variable.lower:g}, {variable.upper:g}]",
            *(f"{float(r[variable.name]):.3g}" for _, _, r in chosen),
        ])  # fmt: skip
    rows.append(["distance, m", "", *(f"{float(r['distance']):.3f}" for _, _, r in chosen)])
    return _table(header, rows)


SERVO_GAIN = 10.0  # nao-walk's default: joint velocity command per radian of error, 1/s
LEG_LENGTH = 0.22  # m, hip to ankle pitch axis of the rcssserver3d NAO (nao-model.md)


def gait_kind(row: dict[str, str]) -> str:
    """static (the hip swings < 1°), rhythmic (a period of at most 3 s) or slow (a swing
    without a rhythm: one slow change of posture over the episode)."""
    if float(row["hip_swing"]) < 1.0:
        return "static"
    period = float(row["period"])
    return "rhythmic" if not math.isnan(period) and period <= 3.0 else "slow"


def servo_pass(period: float, gain: float = SERVO_GAIN) -> float:
    """The fraction of a sinusoidal target's swing a velocity servo v = K (target - angle)
    passes at this period (a first-order lag; velocity and torque limits ignored)."""
    omega = 2.0 * math.pi / period
    return 1.0 / math.sqrt(1.0 + (omega / gain) ** 2)


def gait_summary_table(results: Results) -> str:
    """Per setting and engine: how many best gaits are static, slow or rhythmic."""
    rows = []
    for label, engine in _cells_present(results):
        chosen = [g for g in results.gaits if g["label"] == label and g["engine"] == engine]
        kinds = [gait_kind(g) for g in chosen]
        rows.append([
            f"`{label}`", ENGINE_NAMES[engine], str(len(chosen)),
            *(str(kinds.count(k)) for k in ("static", "slow", "rhythmic")),
            f"{median([float(g['knee_mean']) for g in chosen]):.0f}°",
            f"{100 * median([float(g['torso_drop']) for g in chosen]):.1f} cm",
        ])  # fmt: skip
    header = ["optimizer", "engine", "runs", "static", "slow", "rhythmic", "median knee angle",
              "median torso drop"]  # fmt: skip
    return _table(header, rows, "llrrrrrr")


def rhythmic_table(results: Results) -> str:
    """Every rhythmic best gait: distance, period, commanded and measured hip swing."""
    rows = []
    chosen = [g for g in results.gaits if gait_kind(g) == "rhythmic"]
    for g in sorted(chosen, key=lambda g: -float(g["distance"])):
        period = float(g["period"])
        rows.append([
            g["run"], f"{float(g['distance']):.3f}", f"{period:.2f}",
            f"{float(g['hip_target_swing']):.1f}°", f"{float(g['hip_swing']):.1f}°",
            f"{float(g['hip_swing']) / float(g['hip_target_swing']):.2f}",
            f"{servo_pass(period):.2f}", f"{float(g['knee_mean']):.0f}°",
            f"{100 * float(g['torso_drop']):.1f} cm", "yes" if g["free_oscillation"] == "1"
            else "no",
        ])  # fmt: skip
    header = ["run", "distance, m", "period, s", "hip swing commanded", "hip swing measured",
              "ratio", "first-order servo", "knee angle (mean)", "torso drop",
              "Matsuoka conditions"]  # fmt: skip
    return _table(header, rows, "lrrrrrrrrl")


def significance_text(tests: list[tuple[str, float]]) -> str:
    """One or two sentences on which of the study's rank-sum tests fall below 0.05, and what
    that is worth with this many tests (Bonferroni)."""
    below = [(name, p) for name, p in tests if p < 0.05]
    n = len(tests)
    if not below:
        return (f"None of the {n} two-sided rank-sum tests between the settings (HS against the "
                "GA, the paper's against the classic pitch adjustment, the HS variants) is "
                "below p = 0.05.")  # fmt: skip
    listed = "; ".join(f"{name} (p = {p:.3f})" for name, p in below)
    return (f"Of the {n} two-sided rank-sum tests between the settings (HS against the GA, the "
            f"paper's against the classic pitch adjustment, the HS variants), {len(below)} "
            f"{'is' if len(below) == 1 else 'are'} below p = 0.05: {listed}. With {n} tests "
            f"about {0.05 * n:.1f} such p-values are expected by chance alone, and with 5 runs "
            f"against 5 no test can reach the Bonferroni level 0.05/{n} = {0.05 / n:.4f} "
            "(the smallest possible p is 0.008): 5 seeds are too few to rank these "
            "settings.")  # fmt: skip


def numbers(results: Results) -> dict[str, str]:
    """Values the prose quotes, computed from the result files."""
    v: dict[str, str] = {}
    for label, engine in _cells_present(results):
        key = f"{label}_{engine}".replace("-", "_")
        distance = results.values(label, engine)
        v[f"{key}_distance"] = f"{median(distance):.3f}"
        v[f"{key}_max"] = f"{max(distance):.3f}"
        v[f"{key}_speed"] = f"{median(results.values(label, engine, 'speed')):.3f}"
        v[f"{key}_wall"] = f"{median(results.values(label, engine, 'wall_time')):.0f}"
        v[f"{key}_n"] = str(len(distance))
    study = results.study
    v["machine"] = study["machine"]
    v["code"] = study.get("code", "unknown")
    v["elapsed_min"] = f"{study['elapsed_s'] / 60:.0f}"
    v["runs_finished"] = str(study["runs_finished"])
    v["runs_in_grid"] = str(study["runs_in_grid"])
    v["cpu_hours"] = f"{sum(float(r['wall_time']) for r in results.runs) / 3600:.2f}"
    versions = study["versions"]
    v["versions"] = ", ".join(
        f"{k} {versions[k]}" for k in ("metaopt", "mujoco", "pybullet", "numpy", "python")
        if k in versions
    )  # fmt: skip
    tests: list[tuple[str, float]] = []
    for a, b, engine in (
        ("hs-paper", "hs-classic", "mujoco"), ("hs-paper", "hs-classic", "pybullet"),
        ("hs-ihs", "hs-classic", "mujoco"), ("hs-ghs", "hs-classic", "mujoco"),
        ("hs-ihs", "hs-paper", "mujoco"), ("hs-ghs", "hs-paper", "mujoco"),
        ("hs-ihs", "hs-ghs", "mujoco"),
        ("hs-paper", "ga", "mujoco"), ("hs-paper", "ga", "pybullet"),
        ("hs-classic", "ga", "mujoco"), ("hs-classic", "ga", "pybullet"),
    ):  # fmt: skip
        key = f"p_{a}_{b}_{engine}".replace("-", "_")
        p = p_value(
            results.values(a, engine, "best_fitness"), results.values(b, engine, "best_fitness")
        )
        v[key] = _p(p)
        tests.append((f"`{a}` against `{b}` on {ENGINE_NAMES[engine]}", p))
    for engine in ENGINES:
        ga750 = results.best_at("ga", engine, 750)
        v[f"ga_750_{engine}"] = f"{median(ga750):.3f}" if ga750 else "–"
        for label in ("hs-paper", "hs-classic"):
            hs = results.values(label, engine, "best_fitness")
            key = f"p_{label}_ga750_{engine}".replace("-", "_")
            p = p_value(hs, ga750)
            v[key] = _p(p)
            tests.append((f"`{label}` against the GA at 750 evaluations on "
                          f"{ENGINE_NAMES[engine]}", p))  # fmt: skip
    v["significance"] = significance_text([t for t in tests if not math.isnan(t[1])])
    for label, engine in _cells_present(results):
        chosen = [t for t in results.transfer if t["label"] == label and t["engine"] == engine]
        key = f"{label}_{engine}".replace("-", "_")
        ratios = [
            float(t["replay_distance"]) / float(t["found_distance"])
            for t in chosen
            if float(t["found_distance"]) > 0.05
        ]
        v[f"{key}_transfer_ratio"] = f"{median(ratios):.2f}" if ratios else "–"
        v[f"{key}_transfer_falls"] = str(sum(int(t["replay_fell"]) for t in chosen))
    falls = [t for t in results.transfer if int(t["replay_fell"])]
    kind_of = {g["run"]: gait_kind(g) for g in results.gaits}
    for kind in ("static", "slow", "rhythmic"):
        v[f"transfer_falls_{kind}"] = str(sum(kind_of.get(t["run"]) == kind for t in falls))
    v["transfer_falls"] = str(len(falls))
    v["transfer_total"] = str(len(results.transfer))
    for engine in ENGINES:
        chosen = [t for t in results.transfer if t["engine"] == engine]
        change = [float(t["replay_distance"]) - float(t["found_distance"]) for t in chosen]
        v[f"transfer_change_{engine}"] = f"{median(change):+.3f}" if change else "–"
        v[f"transfer_falls_{engine}"] = str(sum(int(t["replay_fell"]) for t in chosen))
        v[f"transfer_n_{engine}"] = str(len(chosen))
    kinds = [gait_kind(g) for g in results.gaits]
    for kind in ("static", "slow", "rhythmic"):
        v[f"{kind}_n"] = str(kinds.count(kind))
    v["gaits_n"] = str(len(kinds))
    best = max(results.runs, key=lambda r: float(r["distance"]))
    gait = next(g for g in results.gaits if g["run"] == best["run"])
    v["best_run"] = best["run"]
    v["best_distance"] = f"{float(best['distance']):.3f}"
    v["best_speed"] = f"{float(best['speed']):.3f}"
    v["best_period"] = f"{float(gait['period']):.2f}"
    v["best_knee"] = f"{float(gait['knee_mean']):.0f}"
    v["best_drop"] = f"{100 * float(gait['torso_drop']):.1f}"
    v["best_hip_target"] = f"{float(gait['hip_target_swing']):.1f}"
    v["best_hip_swing"] = f"{float(gait['hip_swing']):.1f}"
    v["all_median_distance"] = f"{median([float(r['distance']) for r in results.runs]):.3f}"
    v["all_max_distance"] = f"{float(best['distance']):.3f}"
    v["paper_ratio"] = f"{5.3 / float(best['distance']):.0f}"
    rhythmic = [g for g in results.gaits if gait_kind(g) == "rhythmic"]
    ratio = [float(g["hip_swing"]) / float(g["hip_target_swing"]) for g in rhythmic]
    v["servo_ratio"] = f"{median(ratio):.2f}" if ratio else "–"
    v["servo_pass_paper"] = f"{servo_pass(0.1):.2f}"
    bounds = results.bounds
    for name in ("median", "p90", "max"):
        for joint in ("y", "hip", "knee"):
            v[f"{joint}_swing_{name}"] = f"{bounds[f'{joint}_swing_{name}']:.1f}"
    v["oscillating_percent"] = f"{100 * bounds['oscillating_fraction']:.0f}"
    v["bounds_samples"] = str(bounds["samples"])
    step = LEG_LENGTH * math.radians(bounds["hip_swing_p90"])
    v["step_cm"] = f"{100 * step:.1f}"
    v["steps_needed"] = f"{0.44 / step:.0f}"
    v["paper_step_cm"] = f"{100 * 0.44 * 0.1 / 2:.1f}"
    return v


class _Missing(dict):
    """format_map's mapping: a value not computed (a cell not run) reads as a dash."""

    def __missing__(self, key: str) -> str:
        return "–"


def build_report(out: Path = OUT) -> str:
    """docs/paper-reproduction.md from the result files in ``out`` alone."""
    results = Results(out)
    tables = {
        "table_setup": setup_table(results),
        "table_results": results_table(results),
        "table_convergence": convergence_table(results),
        "table_hs_ga": hs_vs_ga_table(results),
        "table_pitch_mujoco": pairwise_table(results, ["hs-paper", "hs-classic"], "mujoco"),
        "table_pitch_pybullet": pairwise_table(results, ["hs-paper", "hs-classic"], "pybullet"),
        "table_variants": pairwise_table(
            results, ["hs-classic", "hs-paper", "hs-ihs", "hs-ghs"], "mujoco"
        ),
        "table_transfer": transfer_table(results),
        "table_wall": wall_table(results),
        "table_gaits": gait_table(results),
        "table_gait_kinds": gait_summary_table(results),
        "table_rhythmic": rhythmic_table(results),
        "table_runs": runs_table(results),
    }
    tables["figures"] = figures_section(out / "figures")
    return TEMPLATE.format_map(_Missing(**tables, **numbers(results)))


#: What each kind of figure file shows: (file name suffix, caption after the run's name).
FIGURE_CAPTIONS = (
    ("-convergence.png", "best fitness so far and the trailing mean fitness against "
                         "evaluations (the paper's Figs. 4 and 5)"),
    ("-joint_angles.png", "hip, knee and ankle angles of the best gait, commanded and measured "
                          "(Figs. 6-8)"),
    ("-drift.png", "lateral drift Y of the torso during the best gait (Fig. 9)"),
    ("-torso_height.png", "torso height during the best gait (Fig. 10)"),
)  # fmt: skip


def figures_section(folder: Path) -> str:
    """The Figures section: every PNG and MP4 in folder, with what it shows."""
    if not folder.is_dir():
        return "No figures yet: `python scripts/paper_study.py --export` draws them."
    link = f"paper-reproduction/{folder.name}"
    parts = []
    for engine in ENGINES:
        name = f"convergence-{engine}.png"
        if (folder / name).exists():
            parts.append(
                f"**Convergence on {ENGINE_NAMES[engine]}**: each setting's best fitness so "
                "far, median over its seeds with the interquartile band (the y axis starts "
                "after the first random candidates, which all fall).\n\n"
                f"![{name}]({link}/{name})"
            )
    for png in sorted(folder.glob("*.png")):
        for suffix, caption in FIGURE_CAPTIONS:
            if png.name.endswith(suffix):
                run = png.name[: -len(suffix)]
                parts.append(f"**{run}**: {caption}.\n\n![{png.name}]({link}/{png.name})")
    videos = [f"[{video.name}]({link}/{video.name})" for video in sorted(folder.glob("*.mp4"))]
    if videos:
        parts.append(
            "Videos of the study's best walk on each engine (its best fitness over all runs on "
            "that engine; 480x360, 25 frames per simulated second, `metaopt replay RUN "
            f"--video`): {', '.join(videos)}."
        )
    return "\n\n".join(parts)


def setup_table(results: Results) -> str:
    """The settings of the study: name, optimizer, explicit parameters, budget, engines."""
    rows = []
    for setting in SETTINGS.values():
        engines = [e for e in ENGINES if results.select(setting.label, e)]
        seeds = {e: ",".join(r["seed"] for r in results.select(setting.label, e)) for e in engines}
        rows.append([
            f"`{setting.label}`", f"`{setting.optimizer}`",
            f"`{settings_text(setting)}`", str(setting.budget), setting.meaning,
            "; ".join(f"{ENGINE_NAMES[e]} ({seeds[e]})" for e in engines) or "not run",
        ])  # fmt: skip
    header = ["name", "optimizer", "settings", "evaluations", "what", "engines (seeds)"]
    return _table(header, rows, "llllll")


TEMPLATE = """\
<!-- Generated by `python scripts/paper_study.py --report-only` from the files in
docs/paper-reproduction/; edit the template in scripts/paper_study.py, not this file. -->

# Reproducing the paper's study

The paper (Yazdi and Toroghi Haghighat) tuned a two-neuron Matsuoka CPG for a simulated NAO with
Harmony Search (750 trials) and a GA (10 generations of 200) and reports that HS made the robot
walk **5.3 m in 12 s (0.44 m/s)** and the GA **4.2 m (0.35 m/s)**. This page runs that study
again with metaopt: both optimizers, the paper's budgets, 5 seeds each, on MuJoCo and on
PyBullet, plus the Harmony Search variants, and puts the measured numbers beside the paper's.

> **Measured with the old engines.** Every run on this page was made before issue 14 corrected
> the engines: PyBullet then simulated friction 0.5 on the robot's links (not 1) and joint
> motors that held 40 N·m (not 10); MuJoCo a velocity actuator of kv 20 at 4 sub-steps that
> chattered at its torque limit ([nao-walk: physics backends](nao-walk.md#physics-backends)).
> The study was not re-run; every figure below is of the **old engines**. Replayed on the
> corrected engines, the stored HS gait of the paper's controller walks 0.18 m on MuJoCo
> (0.84 m before) and 0.39 m on PyBullet (0.71 m before).

**In short.** Nothing here comes near the paper. Over all {runs_finished} runs the median best
distance in 12 s is {all_median_distance} m and the longest is {all_max_distance} m
({best_run}), {paper_ratio} times shorter than the paper's 5.3 m. {significance}
{static_n} of the {gaits_n} best
"gaits" do not step at all: they win their few centimetres by crouching or leaning forward. The
reasons, in [Why the numbers differ](#why-the-numbers-differ-from-the-paper), are mostly in the
task as the paper specifies it (Table 2's bounds leave the legs a few degrees of swing, nothing
shifts the weight sideways) and in the simulator the paper used, not in the optimizers.

Everything on this page is generated from the small result files in docs/paper-reproduction/
(`runs.csv`, `convergence/*.csv`, `transfer.csv`, `gaits.csv`, `swing-bounds.json`,
`study.json`, and the figures and videos in `figures/`) by `scripts/paper_study.py`:

```bash
python scripts/paper_study.py --run          # run (or resume) every unfinished run, 2 at a time
python scripts/paper_study.py --export       # result files from the run store, then this page
python scripts/paper_study.py --report-only  # this page from the committed result files alone
```

The run store (every evaluation of every run, some tens of MB) is `/tmp/paper-study.db`, not kept in
the repository; a run is skipped when the store already holds it finished, so the study can be
stopped and continued. `tests/test_paper_study.py` checks that this page is exactly what
`--report-only` builds from the committed files and that the files agree with each other.

## The study

{table_setup}

* Problem: `nao-walk` with its defaults: 15 s episodes with a 3 s lock phase (so 12 s of
  walking), control at 50 Hz, the `robust` fitness (forward distance minus |drift|, at least
  1 m below standing still for a fall; see [nao-walk](nao-walk.md)), no noise (deterministic
  episodes), 4 physics sub-steps per 20 ms.
* Each run is serial (one evaluation at a time, sync mode), so it depends only on its seed; two
  runs went at a time in separate processes on {machine}.
* Code: commit `{code}`; {versions}.
* **Which HS is the paper's.** §4.2.2 says a pitch-adjusted value "is set to a number in range
  from lower band to upper band", i.e. a fresh uniform value: that is `hs-paper`
  (`pitch_adjust=resample`). The classic rule of Geem et al. (2001), a step of at most
  `bandwidth` = 1% of the range, is `hs-classic`. The paper does not give HMS, HMCR or PAR, so
  both use metaopt's defaults (20, 0.9, 0.3). `hs-ihs` and `hs-ghs` use the defaults of
  [Optimizers](optimizers.md) with their schedules over the 750 evaluations.
* "Distance" is the forward progress of the torso centre over the 12 s of walking of each run's
  best evaluation; a cell shows the median over seeds with the interquartile range (Q1–Q3) in
  brackets. p-values are two-sided Mann–Whitney U (rank-sum) tests on the runs' best fitness;
  with 5 runs against 5 the smallest possible is 0.008.

## Results beside the paper

{table_results}

The paper's rows are its single reported runs (distance and mean speed of the best walk, the
time on its Pentium IV). "best fell" counts runs whose best evaluation fell (the robust fitness
makes that rare). Speeds are distance over the 12 s.

Median best fitness so far after a number of evaluations (the paper's Figs. 4 and 5 plot this
curve; `convergence/*.csv` has each run's, per 25 evaluations, with the block mean):

{table_convergence}

The mean fitness of a block (in the convergence files) stays far below zero throughout: most
candidates fall, and every fall costs at least 1 m under the robust fitness. The paper's Fig. 4
shows a mean close to the best after a few hundred trials, which would need a population in
which most candidates walk.

## HS against the GA

The paper's claim is that HS beats the GA (5.3 m against 4.2 m) with fewer evaluations. Here,
per engine, each HS setting's best fitness (750 evaluations) against the GA's after the same
750 evaluations and after its full 2000:

{table_hs_ga}

On MuJoCo the GA after 750 evaluations has a median of
{ga_750_mujoco} against {hs_paper_mujoco_distance} m and {hs_classic_mujoco_distance} m for the
two HS settings (distances; fitness in the table); after 2000 it reaches
{ga_mujoco_distance} m, and no p-value is below 0.05: the spread within each optimizer (one
`hs-classic` seed found {hs_classic_mujoco_max} m, the other four at most 0.13 m) is larger
than any difference between them. On PyBullet the classic HS after 750 evaluations is ahead of
the GA after the same 750 (p = {p_hs_classic_ga750_pybullet}) but not of the GA after its 2000
(p = {p_hs_classic_ga_pybullet}), which is the shape of the paper's claim (HS gets there with
fewer evaluations) at a hundredth of its distances, and a single p-value among many (see the
summary). So this study neither confirms nor refutes the paper's ranking.

## The paper's pitch adjustment against the classic one

MuJoCo:

{table_pitch_mujoco}

PyBullet:

{table_pitch_pybullet}

The paper's rule re-draws a pitch-adjusted value anywhere in its range. With PAR 0.3 and HMCR
0.9 that replaces about 2.7 of the 10 variables per harmony, and another 1 of 10 comes from
random selection, so a new harmony is closer to a random point than to a small variation of a
remembered one: once the memory holds standing robots, the search behaves much like random
search among them (its best is found early: see "found at evaluation" in
[Every run](#every-run)). The classic rule keeps improving late in the budget (on MuJoCo every
`hs-classic` best is found after evaluation 700) because its steps are small, but a step of 1%
of the range is too small to leave the plateau of robots that stand or shuffle: on MuJoCo one
of five seeds found a shuffle that goes further than 0.15 m. The classic rule has the higher
median on both engines; the rank-sum p is {p_hs_paper_hs_classic_mujoco} on MuJoCo and
{p_hs_paper_hs_classic_pybullet} on PyBullet.

## Harmony Search variants (MuJoCo)

{table_variants}

IHS (bandwidth shrinking from 5% to 0.001% of the range, PAR rising) has the best median, and
GHS (values copied from the best harmony) the narrowest spread, but no pair differs
significantly (smallest p = {p_hs_ihs_hs_paper_mujoco}, IHS against the paper's rule). GHS
copies variables of the best harmony across dimensions whose ranges differ, so its memory
collapses onto the best posture: four of its five best gaits are static (next section). In the
longer searches reported in [nao-walk](nao-walk.md#a-gait-found-by-harmony-search) (2000–4000
evaluations, memory 30), IHS with a wide early bandwidth was the only setting that found a gait
of 0.84 m; at 750 evaluations the variants are not yet apart.

## Across engines

Each run's best candidate, evaluated again on the other engine (`metaopt.replay.replay_best`
with `backend` changed; the same 10 parameters and a fresh episode):

{table_transfer}

Found on MuJoCo and replayed on PyBullet the median change is {transfer_change_mujoco} m
({transfer_falls_mujoco} of {transfer_n_mujoco} fall); found on PyBullet and replayed on MuJoCo
it is {transfer_change_pybullet} m ({transfer_falls_pybullet} of {transfer_n_pybullet} fall).
Of the {transfer_falls} falls on replay, {transfer_falls_static} are static postures,
{transfer_falls_slow} slow and {transfer_falls_rhythmic} rhythmic: a crouch or a lean that
balances on one engine's contacts tips over on the other's, so even "standing still" does not
transfer reliably, and a rhythmic gait keeps, gains or loses distance from run to run. The
optimizer exploits the engine it is run on, as
the paper's search exploited rcssserver3d's: a distance measured in one simulator is a property
of the controller and of that simulator together.

## What the best gaits do

Each run's best candidate was run again with a recorded trajectory (`gaits.csv`). Left hip
swing and period are measured after the first 2 s of walking. *static*: the hip swings less
than 1°, the robot takes a posture and keeps it; *slow*: it moves more but without a rhythm
(one slow change of posture); *rhythmic*: a period of at most 3 s.

{table_gait_kinds}

{static_n} of the {gaits_n} best candidates are static and {slow_n} slow: their "distance" is
the torso centre moving forward as the robot crouches (knees near their −130° limit, the torso
up to 11 cm lower) or leans, which the fitness counts as progress. Only {rhythmic_n} step in a
rhythm:

{table_rhythmic}

"ratio" is the measured hip swing over the commanded one; "first-order servo" is what a
velocity servo with gain 10/s (nao-walk's `servo_gain`) passes of a sine at that period. The
fast rhythms reach the joints at about half their commanded swing (median ratio
{servo_ratio}). The best walker, {best_run}, is the crouched shuffle described in
[nao-walk](nao-walk.md#a-gait-found-by-harmony-search): a period of {best_period} s, knees at
{best_knee}° on average, the torso {best_drop} cm below standing, the hip commanded through
{best_hip_target}° but moving {best_hip_swing}°. It walks {best_distance} m in 12 s
({best_speed} m/s).

The 10 parameters of the best run of the paper's two optimizers on each engine:

{table_gaits}

## Wall time

{table_wall}

"ms per evaluation" is the mean time of one episode in the worker (falls end early, so it grows
as a search finds robots that stay up). The whole study took {elapsed_min} minutes of wall time
on two processes ({cpu_hours} hours of run time in all) on {machine}; the run times vary with
the load from other work on the machine. The paper needed 2 hours for 750 HS trials and 7 hours
for the GA's 2000: about 9.6 and 12.6 s per 15 s trial, close to real time, as rcssserver3d
runs. Here a 15 s episode takes tens of milliseconds on MuJoCo and a few hundred on PyBullet,
so the paper's whole HS experiment takes about a minute on MuJoCo. The store keeps a resumed
run's wall time for its last session only ([Comparing](comparing.md)); two GA runs on MuJoCo
were resumed after the machine restarted, and for them (for every serial run, where it is
larger) the wall time here is the sum of the run's evaluation times.

## Why the numbers differ from the paper

1. **Table 2's bounds leave the legs a few degrees of swing.** The hip command is
   `w11 · y + b1` with w11 in [−4, 1] degrees per unit, the knee `w12 · y + b2` with w12 in
   [−5, 0], where y = max(x, 0) is an oscillator output. Drawing {bounds_samples} oscillating
   parameter sets uniformly from the box (Matsuoka's conditions hold for only
   {oscillating_percent}% of it; `swing-bounds.json`), y swings by {y_swing_median} peak to peak
   (median; 90th percentile {y_swing_p90}, largest {y_swing_max}). With the largest |w11| = 4
   that is a hip swing of {hip_swing_median}° (90th percentile {hip_swing_p90}°, at most
   {hip_swing_max}°), and a knee swing of {knee_swing_median}° ({knee_swing_p90}°,
   {knee_swing_max}°) with |w12| = 5. A hip swing of {hip_swing_p90}° moves the foot of a 0.22 m
   leg by about {step_cm} cm per step, so 0.44 m/s needs about {steps_needed} steps a second.
   Parameter sets outside Matsuoka's regime (beta or gamma negative) give larger outputs, but
   they diverge to a joint limit and stay there or switch between limits, which is no gait.
2. **The paper's own gait period says the same.** The paper reports a gait period of 0.1 s for
   its best walk: at 0.44 m/s that is {paper_step_cm} cm per step, a ten-per-second shuffle of a
   few degrees, consistent with point 1. A walk like that depends on how the joint servos and
   the contacts handle a 10 Hz vibration. Here the joints are velocity servos with
   v = 10/s · (target − angle), as an rcssserver3d agent must do it (the server takes only
   velocities; the paper does not say its gain); such a servo passes {servo_pass_paper} of a
   0.1 s sine's swing. A higher gain would pass more (`--set servo_gain=...`; not tried here).
3. **Nothing shifts the weight sideways.** Only the six hip, knee and ankle *pitch* joints move;
   hip and ankle roll are held at 0. Without a lateral weight shift a foot can only leave the
   ground briefly, so the gaits that move are shuffles and crouches, not steps. The paper's
   controller has the same limitation; its simulator let the shuffle slide.
4. **The simulator.** rcssserver3d (ODE, one 20 ms step, `dWorldStep`) had **infinite friction
   with force-dependent slip** (5·10⁻³ m/s per newton: a foot pushing with 20 N slides at
   0.1 m/s), stiff ERP/CFM contacts and no position servo. Here both engines have μ = 1,
   MuJoCo soft contacts, 4 physics sub-steps per 20 ms (one step made the standing robot rock
   in both engines; [nao-walk](nao-walk.md#physics-backends)). A vibrating shuffle that advances
   by slip in ODE has no such mechanism here (neither engine models force-dependent slip). A
   ground that hardly slides (μ = 100 on PyBullet; MuJoCo stands on at most μ = 3) is tried in
   [Walking faster than the paper](faster-walk.md#a-ground-like-the-papers).
5. **The fitness.** Eq. 9 as printed divides the progress of a robot that falls by the time
   left, which rewards falling just before the end and, for negative progress, falling early.
   This study uses the monotone `robust` fitness (a fall costs at least 1 m). The reported
   distances do not depend on the formula, but the search does: under eq. 9 a lunge at the end
   pays. `--set fitness=paper` reproduces the printed formula.
6. **Noise.** The paper's simulator was noisy and it resampled candidates; these episodes are
   deterministic, and on MuJoCo a good gait's deterministic distance is an optimistic outlier of
   a chaotic system ([nao-walk](nao-walk.md#noise-set-noise)). That would lower our numbers
   further, not raise them.
7. **Parameters the paper leaves out.** HMS, HMCR and PAR, the GA's operators and rates, the
   servo gain, the initial state of the oscillator and the feedback's units are not given;
   metaopt's choices are documented in [nao-walk](nao-walk.md) and [Optimizers](optimizers.md).
   The GA runs here predate issue 17, which changed the GA's crossover (SBX now crosses each
   gene with probability 1/2 and swaps genes between the children, as Deb's own code does);
   `survival=elites` keeps its generational scheme and the default `mutations=1` its rate of
   0.1 for these 10 variables, but a GA run made now differs from the stored ones.
8. **Budget.** 750 evaluations are few for this landscape: almost every random candidate falls,
   and the first walker appears late if at all. The longer searches in
   [nao-walk](nao-walk.md#a-gait-found-by-harmony-search) reached 0.84 m (IHS, 4000
   evaluations, memory 30, HMCR 0.95), still a sixth of the paper's distance.

What this reproduction shows, then: with the controller, bounds and budgets the paper specifies,
and physics close to its simulator's robot but not to its contact model, neither optimizer makes
the NAO walk; the searches find postures and crouched shuffles of centimetres to decimetres. The
paper's 5.3 m is not reproduced, and its HS-over-GA ranking cannot be confirmed with 5 seeds.

## Figures

{figures}

## Every run

{table_runs}
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, default=DEFAULT_DB)
    parser.add_argument("--run", action="store_true", help="run the unfinished cells")
    parser.add_argument("--export", action="store_true", help="write the result files")
    parser.add_argument("--report-only", action="store_true", help="rebuild the document")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--pybullet-ga-seeds", type=int, default=len(SEEDS))
    parser.add_argument("--no-transfer", action="store_true", help="export without replays")
    parser.add_argument("--only", default="", help="comma-separated engines to run")
    args = parser.parse_args(argv)
    everything = not (args.run or args.export or args.report_only)
    cells = grid(SEEDS[: args.pybullet_ga_seeds])
    if args.only:
        cells = [c for c in cells if c.engine in args.only.split(",")]
    if args.run or everything:
        run_grid(args.db, cells, args.workers)
    if args.export or everything:
        export(args.db, grid(), transfer=not args.no_transfer)
        write_study_record(args.db, grid())
        export_gaits(args.db, grid())
        export_figures(args.db, grid())
        bounds = json.dumps(swing_bounds(), indent=2)
        (OUT / "swing-bounds.json").write_text(bounds + "\n")
    if args.report_only or args.export or everything:
        DOC.write_text(build_report(OUT))
        print(f"wrote {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
