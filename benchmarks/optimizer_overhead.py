"""Per-evaluation overhead of the optimizers and of the whole run loop, in microseconds.

For hs, ga and random with a trivial objective (sum of x), budget 20,000, D = 10 and D = 30:
  (a) the optimizer's own cost: ask + tell only;
  (b) the whole `metaopt run` loop: seeding, evaluation, SQLite storage of every evaluation,
      and the rich progress display (rendered to /dev/null);
  (c) the bare cost of calling the objective alone.
Targets (issue 2): (a) <= 5 us for hs and ga at D = 10; (b) <= 20 us.

    python benchmarks/optimizer_overhead.py [--budget 20000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
from rich.console import Console

from metaopt import Evaluation, Problem, ProblemInfo, Space
from metaopt.params import resolve
from metaopt.plugins import registry
from metaopt.reporting.display import RichProgress
from metaopt.running import RunSpec, run
from metaopt.storage.run_store import EvaluationCounts, RunStore

OPTIMIZERS = ("hs", "ga", "random")


class SumOfX(Problem):
    """The cheapest honest objective: sum(x) over [-1, 1]^D."""

    def __init__(self, dim: int) -> None:
        self.space = Space.from_bounds([-1.0] * dim, [1.0] * dim)

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        return Evaluation(float(x.sum()))


def optimizer_cost(name: str, dim: int, budget: int) -> float:
    """(a): microseconds per evaluation spent inside ask and tell."""
    info = registry().optimizer(name)
    params = resolve(info.params, {"budget": budget} if _has_budget(info) else {}, name)
    problem = SumOfX(dim)
    optimizer = info.factory(problem.space, 1, **params)
    spent, done = 0.0, 0
    while done < budget:
        tick = time.perf_counter()
        batch = optimizer.ask(min(optimizer.batch_size, budget - done))
        spent += time.perf_counter() - tick
        fitnesses = batch.sum(axis=1)
        tick = time.perf_counter()
        optimizer.tell(batch, fitnesses)
        spent += time.perf_counter() - tick
        done += len(batch)
    return spent / budget * 1e6


def _has_budget(info) -> bool:
    return any(p.name == "budget" for p in info.params)


def run_loop_cost(name: str, dim: int, budget: int) -> float:
    """(b): microseconds per evaluation of the whole run loop, storage and progress included."""
    info = ProblemInfo("sum", "sum of x", factory=lambda: SumOfX(dim))
    with tempfile.TemporaryDirectory() as folder, open(os.devnull, "w") as sink:
        console = Console(file=sink, force_terminal=True, width=120)
        with RunStore(os.path.join(folder, "bench.db")) as store:
            tick = time.perf_counter()
            with RichProgress(console, name) as progress:
                result = run(RunSpec(name, "sum", budget, 1), registry().optimizer(name), info,
                             store, progress)  # fmt: skip
            elapsed = time.perf_counter() - tick
            assert store.evaluation_counts(result.run_id) == EvaluationCounts(budget, 0, 0)
    return elapsed / budget * 1e6


def function_cost(dim: int, budget: int) -> float:
    """(c): microseconds per call of the objective alone."""
    problem = SumOfX(dim)
    points = problem.space.sample(np.random.default_rng(0), budget)
    tick = time.perf_counter()
    for x in points:
        problem.evaluate(x, 0)
    return (time.perf_counter() - tick) / budget * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=3, help="best of N (noisy machine)")
    args = parser.parse_args()
    print(f"budget {args.budget}, best of {args.repeats}; microseconds per evaluation")
    print(f"{'optimizer':<10}{'D':>4}{'(a) ask+tell':>15}{'(b) run loop':>15}{'(c) function':>15}")
    for dim in (10, 30):
        bare = min(function_cost(dim, args.budget) for _ in range(args.repeats))
        for name in OPTIMIZERS:
            own = min(optimizer_cost(name, dim, args.budget) for _ in range(args.repeats))
            whole = min(run_loop_cost(name, dim, args.budget) for _ in range(args.repeats))
            print(f"{name:<10}{dim:>4}{own:>15.2f}{whole:>15.2f}{bare:>15.2f}")
    print("targets: (a) <= 5 us for hs and ga at D = 10; (b) <= 20 us")


if __name__ == "__main__":
    main()
