"""Parallel scaling of nao-walk with Harmony Search, and each executor's per-evaluation overhead.

Prints, for HS on nao-walk with a fixed budget: wall time, evaluations per second and CPU time
(this process and its finished children) for
  * serial;
  * 2 local processes, sync mode (batches of 4: results identical to serial with --batch 4);
  * 2 local processes, async mode (a new candidate whenever a worker is free);
  * a 2-worker Dask LocalCluster, sync and async;
and the speedups over serial; then the per-evaluation overhead of each executor with a trivial
problem (sphere), over the bare cost of evaluating it in-process. The machine's load average
is printed before and after: the figures mean something only on a quiet machine.
Targets (issue 4, quiet 2-core machine): async >= 1.8x serial; Dask overhead <= 5 ms/eval.

    python benchmarks/parallel_scaling.py [--budget 300] [--trivial-budget 400]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

from metaopt.executors.base import Executor, SerialExecutor
from metaopt.plugins import registry
from metaopt.running import RunSettings, RunSpec, run
from metaopt.storage.run_store import RunStore


def _executor(name: str) -> Executor:
    return SerialExecutor() if name == "serial" else registry().executor(name).factory(2, None)


def timed_run(problem: str, budget: int, executor: str, settings: RunSettings) -> dict:
    """Wall and CPU seconds of one run (executor start-up excluded from the wall time)."""
    plugins = registry()
    spec = RunSpec("hs", problem, budget, 1, settings=settings)
    cpu_before = os.times()
    start = time.perf_counter()
    pool = _executor(executor)
    startup = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as folder, RunStore(f"{folder}/bench.db") as store:
        result = run(spec, plugins.optimizer("hs"), plugins.problem(problem), store, None, pool)
    cpu_after = os.times()
    cpu = sum(cpu_after[:4]) - sum(cpu_before[:4])
    return {"wall": result.wall_time, "startup": startup, "cpu": cpu, "evals": result.evaluations}


def load() -> str:
    with open("/proc/loadavg") as handle:
        return " ".join(handle.read().split()[:3])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=300)
    parser.add_argument("--trivial-budget", type=int, default=400)
    args = parser.parse_args()
    print(f"cores: {os.cpu_count()}, load average before: {load()}")
    print(f"nao-walk, hs, budget {args.budget} (15 s episodes)")
    header = f"{'configuration':<24}{'wall s':>9}{'eval/s':>9}{'cpu s':>9}{'speedup':>9}"
    print(f"{header}{'startup s':>11}")
    configurations = [
        ("serial", "serial", RunSettings()),
        ("2 processes, sync", "process", RunSettings(mode="sync", batch=4)),
        ("2 processes, async", "process", RunSettings(mode="async")),
        ("dask 2 workers, sync", "dask", RunSettings(mode="sync", batch=4)),
        ("dask 2 workers, async", "dask", RunSettings(mode="async")),
    ]  # fmt: skip
    serial_wall = None
    for label, executor, settings in configurations:
        m = timed_run("nao-walk", args.budget, executor, settings)
        serial_wall = serial_wall or m["wall"]
        print(f"{label:<24}{m['wall']:>9.2f}{m['evals'] / m['wall']:>9.1f}{m['cpu']:>9.2f}"
              f"{serial_wall / m['wall']:>8.2f}x{m['startup']:>11.2f}")  # fmt: skip
    print(f"\nper-evaluation overhead, sphere (10-D), budget {args.trivial_budget}, async")
    bare = timed_run("sphere", args.trivial_budget, "serial", RunSettings())
    bare_per_eval = bare["wall"] / bare["evals"]
    print(f"{'serial (reference)':<24}{bare_per_eval * 1e3:>9.3f} ms/eval")
    for executor in ("process", "dask"):
        m = timed_run("sphere", args.trivial_budget, executor, RunSettings(mode="async"))
        overhead = m["wall"] / m["evals"] - bare_per_eval
        print(f"{executor:<24}{overhead * 1e3:>9.3f} ms/eval overhead")
    print(f"load average after: {load()}")
    print("targets: async >= 1.8x serial; dask overhead <= 5 ms per evaluation")


if __name__ == "__main__":
    main()
