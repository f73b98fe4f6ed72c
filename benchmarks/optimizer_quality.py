"""metaopt's HS, GA and CMA-ES against popular Python implementations, classic and bbob.

Every optimizer minimizes the same functions through the same evaluation counter: each call of f
counts, the best value of the first ``budget`` calls is the result, and the call after the budget
raises, which stops any optimizer at exactly the budget. Each optimizer runs with its library's
defaults (or its documentation's example settings where it has no defaults); metaopt's run with
theirs. The grid: functions x dimensions x budgets x seeds (bbob: instance 1 for every seed).

The peers are installed, at the pinned versions below, into a virtual environment of this
script's own, created on first use (``--peers-env``, default ~/.cache/metaopt/optimizer-quality-
peers; it needs PyPI once). Every run goes to a worker subprocess (``--jobs`` at once): metaopt's
in this interpreter, the peers' in theirs, which imports metaopt's problem code from this checkout.
Results are cached one per line in ``--results`` (JSON), so an interrupted grid resumes; the
report prints per-function medians, how often each metaopt optimizer's median beats each peer's,
and mean ranks.

    python benchmarks/optimizer_quality.py --quick                  # a few minutes
    python benchmarks/optimizer_quality.py --seeds 5 --jobs 2       # the full grid
    python benchmarks/optimizer_quality.py --suites bbob --dims 10 --budgets 10000 \\
        --optimizers hs,mealpy-hs,pyharmonysearch --functions 1,3,15
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import random
import subprocess
import sys
import threading
import venv
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from functools import cache
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PEERS_ENV = Path.home() / ".cache" / "metaopt" / "optimizer-quality-peers"
#: The peers and what else their worker needs (numpy, and metaopt's problems' imports).
PEER_PACKAGES = (
    "pymoo==0.6.1.5",
    "deap==1.4.3",
    "pyharmonysearch==1.4.4",
    "mealpy==3.0.1",
    "niapy==2.5.2",
    "cma==4.5.0",
    "numpy<2",
    "pluggy>=1.3",
    "coco-experiment>=2.6",
)
CLASSIC = ("sphere", "rastrigin", "rosenbrock", "ackley", "griewank", "schwefel")
BBOB = tuple(str(f) for f in range(1, 25))
SUITE_DIMS = {"classic": (10, 30), "bbob": (10, 20)}
#: Values below this count as solved (COCO's final target): such medians tie.
SOLVED = 1e-8
#: Each metaopt optimizer (run here) and the peers its medians are counted against (run in their
#: environment): the default grid is all of them, metaopt's first.
PEERS_OF = {
    "hs": ("pyharmonysearch", "mealpy-hs", "niapy-hs"),
    "ga": ("pymoo-ga", "deap-ga"),
    "cmaes": ("pycma",),
}
DEFAULT_OPTIMIZERS = (*PEERS_OF, *(peer for peers in PEERS_OF.values() for peer in peers))


class BudgetSpent(Exception):
    """The counter was called once more than the budget allows."""


class Counted:
    """f with a call counter: keeps the best of the first ``budget`` calls, then raises."""

    def __init__(self, function: Callable[[np.ndarray], float], budget: int) -> None:
        self.function, self.budget = function, budget
        self.calls, self.best = 0, math.inf

    def __call__(self, x: Iterable[float]) -> float:
        if self.calls >= self.budget:
            raise BudgetSpent
        self.calls += 1
        value = self.function(np.asarray(x, dtype=float))
        if value < self.best:
            self.best = value
        return value


@dataclass(frozen=True)
class Task:
    """One run: an optimizer (label, optional metaopt parameters) on one function."""

    optimizer: str
    suite: str
    function: str
    dim: int
    budget: int
    seed: int

    @property
    def key(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)


# -- the functions ----------------------------------------------------------------------------


@cache
def _load(name: str, path: Path):
    """A module of this checkout by file (the peers' environment has no metaopt installed)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    spec = importlib.util.spec_from_file_location(name, path)
    module = sys.modules[name] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def objective(suite: str, function: str, dim: int):
    """(f - f_opt as a function of x, lower bounds, upper bounds) of a classic or bbob function."""
    if suite == "classic":
        functions = _load("quality_functions", ROOT / "problems" / "functions.py")
        spec = next(s for s in functions.FUNCTIONS if s.name == function)
        return spec.function, np.full(dim, spec.lower), np.full(dim, spec.upper)
    bbob = _load("quality_bbob", ROOT / "problems" / "bbob.py")
    problem = bbob.BBOBProblem(int(function), dim, 1)
    return (lambda x: problem.evaluate(x, 0).fitness), problem.space.lower, problem.space.upper


# -- the optimizers ----------------------------------------------------------------------------


def run_metaopt(name: str, f: Counted, lower, upper, seed: int, params: dict) -> None:
    """metaopt's optimizer by ask/tell, with the budget it is told like every optimizer."""
    import metaopt

    optimizer = metaopt.create_optimizer(
        name, list(zip(lower, upper)), seed=seed, budget=f.budget, **params
    )
    while f.calls < f.budget:
        batch = optimizer.ask(min(optimizer.batch_size, f.budget - f.calls))
        optimizer.tell(batch, np.array([f(x) for x in batch]))


def run_pyharmonysearch(f: Counted, lower, upper, seed: int) -> None:
    """pyHarmonySearch with its README example's settings (it has no defaults): HMS 100,
    HMCR 0.75, PAR 0.5, MPAP 0.25; max_imp makes the budget exact."""
    from pyharmonysearch import ObjectiveFunctionInterface
    from pyharmonysearch.harmony_search import HarmonySearch

    class Objective(ObjectiveFunctionInterface):
        def get_fitness(self, vector):
            return f(vector)

        def get_value(self, i, j=None):
            return random.uniform(lower[i], upper[i])

        def get_lower_bound(self, i):
            return lower[i]

        def get_upper_bound(self, i):
            return upper[i]

        def is_variable(self, i):
            return True

        def is_discrete(self, i):
            return False

        def get_num_parameters(self):
            return len(lower)

        def use_random_seed(self):
            return True

        def get_random_seed(self):
            return seed

        def get_max_imp(self):
            return f.budget - 100

        def get_hmcr(self):
            return 0.75

        def get_par(self):
            return 0.5

        def get_hms(self):
            return 100

        def get_mpai(self):
            return 2

        def get_mpap(self):
            return 0.25

        def maximize(self):
            return False

    HarmonySearch(Objective()).run()


def run_mealpy_hs(f: Counted, lower, upper, seed: int) -> None:
    """mealpy's OriginalHS with its defaults (population 100, HMCR 0.95, PAR 0.05)."""
    from mealpy import HS, FloatVar

    problem = {
        "obj_func": f,
        "bounds": FloatVar(lb=list(lower), ub=list(upper)),
        "minmax": "min",
        "log_to": None,
    }
    HS.OriginalHS(epoch=100000).solve(problem, seed=seed)


def run_niapy_hs(f: Counted, lower, upper, seed: int) -> None:
    """NiaPy's HarmonySearch with its defaults (memory 30, r_accept 0.7, r_pa 0.35)."""
    from niapy.algorithms.basic import HarmonySearch
    from niapy.problems import Problem
    from niapy.task import Task as NiaTask

    class Objective(Problem):
        def __init__(self):
            super().__init__(len(lower), lower, upper)

        def _evaluate(self, x):
            return f(x)

    HarmonySearch(seed=seed).run(NiaTask(problem=Objective(), max_evals=10 * f.budget))


def run_pymoo_ga(f: Counted, lower, upper, seed: int) -> None:
    """pymoo's GA with its defaults (population 100, tournament, SBX, polynomial mutation)."""
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.core.problem import Problem
    from pymoo.optimize import minimize

    class Objective(Problem):
        def __init__(self):
            super().__init__(n_var=len(lower), n_obj=1, xl=lower, xu=upper)

        def _evaluate(self, x, out, *args, **kwargs):
            out["F"] = np.array([f(row) for row in x])

    minimize(Objective(), GA(), ("n_eval", 10 * f.budget), seed=seed, verbose=False)


def run_deap_ga(f: Counted, lower, upper, seed: int) -> None:
    """DEAP's eaSimple with the real-valued operators of its examples: population 100, SBX
    (eta 20, rate 0.9), bounded polynomial mutation (eta 20, 1/D per gene), tournament 3."""
    from deap import algorithms, base, creator, tools

    random.seed(seed)
    if not hasattr(creator, "QualityMin"):
        creator.create("QualityMin", base.Fitness, weights=(-1.0,))
        creator.create("QualityIndividual", list, fitness=creator.QualityMin)
    low, up, dim = list(lower), list(upper), len(lower)
    toolbox = base.Toolbox()
    toolbox.register(
        "individual",
        lambda: creator.QualityIndividual(random.uniform(a, b) for a, b in zip(low, up)),
    )
    toolbox.register("population", tools.initRepeat, list, toolbox.individual)
    toolbox.register("evaluate", lambda individual: (f(individual),))
    toolbox.register("mate", tools.cxSimulatedBinaryBounded, eta=20.0, low=low, up=up)
    toolbox.register(
        "mutate", tools.mutPolynomialBounded, eta=20.0, low=low, up=up, indpb=1.0 / dim
    )
    toolbox.register("select", tools.selTournament, tournsize=3)
    algorithms.eaSimple(
        toolbox.population(100), toolbox, cxpb=0.9, mutpb=1.0, ngen=10**7, verbose=False
    )


def run_pycma(f: Counted, lower, upper, seed: int) -> None:
    """Hansen's cma with its defaults (population 4 + 3 ln D, no restarts: it stops on its own
    criteria), from a uniform random point of the unit cube mapped onto the box, initial step 0.3
    of each range and cma's own bound handling (BoundTransform): metaopt's cmaes's setting."""
    import cma

    width = upper - lower
    options = {"bounds": [0.0, 1.0], "seed": seed + 1, "verbose": -9, "maxfevals": f.budget}
    strategy = cma.CMAEvolutionStrategy(np.random.default_rng(seed).random(len(lower)), 0.3,
                                        options)  # fmt: skip
    strategy.optimize(lambda unit: f(lower + np.asarray(unit) * width))


PEER_RUNNERS = {
    "pyharmonysearch": run_pyharmonysearch,
    "mealpy-hs": run_mealpy_hs,
    "niapy-hs": run_niapy_hs,
    "pymoo-ga": run_pymoo_ga,
    "deap-ga": run_deap_ga,
    "pycma": run_pycma,
}


def split_label(label: str) -> tuple[str, dict]:
    """'hs' or 'hs:pitch_adjust=ghs+hms=30' -> ('hs', {...}); values parsed as JSON if they can."""
    name, _, rest = label.partition(":")
    params = {}
    for item in filter(None, rest.split("+")):
        key, _, value = item.partition("=")
        try:
            params[key] = json.loads(value)
        except json.JSONDecodeError:
            params[key] = value
    return name, params


def run_task(task: Task) -> dict:
    """Run one task; its best value (f - f_opt) and how many evaluations it used."""
    function, lower, upper = objective(task.suite, task.function, task.dim)
    counted = Counted(function, task.budget)
    name, params = split_label(task.optimizer)
    try:
        if name in PEER_RUNNERS:
            PEER_RUNNERS[name](counted, lower, upper, task.seed)
        else:
            run_metaopt(name, counted, lower, upper, task.seed, params)
    except BudgetSpent:
        pass
    return {**asdict(task), "best": counted.best, "evaluations": counted.calls}


def worker() -> None:
    """Run the tasks given one per stdin line; print each result as a JSON line."""
    import warnings

    warnings.filterwarnings("ignore")
    for line in sys.stdin:
        result = run_task(Task(**json.loads(line)))
        print(json.dumps(result), flush=True)


# -- the grid and its environments -------------------------------------------------------------


def peers_python(env: Path) -> Path:
    """The peers' interpreter, creating their environment on first use."""
    python = env / "bin" / "python"
    if not python.exists():
        print(f"creating the peers' environment in {env} (once) ...", file=sys.stderr)
        venv.EnvBuilder(with_pip=True).create(env)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", *PEER_PACKAGES], check=True)
    return python


def _feed(stdin, text: str) -> None:
    """Write a worker's tasks and close its input, so that it ends after the last."""
    stdin.write(text)
    stdin.close()


def run_tasks(tasks: list[Task], python: Path, jobs: int, results: Path) -> None:
    """Run tasks on jobs worker processes of this interpreter, appending results as they come."""
    if not tasks:
        return
    chunks = [tasks[i::jobs] for i in range(jobs) if tasks[i::jobs]]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}

    def run_chunk(chunk: list[Task]) -> None:
        process = subprocess.Popen(
            [str(python), __file__, "--worker"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
        )  # fmt: skip
        # The tasks are fed from a thread of their own: written here before the results are
        # read, a chunk larger than the pipes hold left the worker blocked on a full stdout and
        # this thread on a full stdin, both for ever.
        tasks_text = "".join(json.dumps(asdict(t)) + "\n" for t in chunk)
        feeder = threading.Thread(target=_feed, args=(process.stdin, tasks_text))
        feeder.start()
        with results.open("a") as out:
            for line in process.stdout:
                out.write(line)
                out.flush()
        feeder.join()
        if process.wait():
            raise RuntimeError(f"a worker of {python} failed (exit {process.returncode})")

    with ThreadPoolExecutor(len(chunks)) as pool:
        list(pool.map(run_chunk, chunks))


# -- the report --------------------------------------------------------------------------------


def medians(rows: list[dict]) -> dict[tuple, float]:
    """(suite, dim, budget, function, optimizer) -> median best over seeds."""
    grouped: dict[tuple, list[float]] = {}
    for row in rows:
        key = (row["suite"], row["dim"], row["budget"], row["function"], row["optimizer"])
        grouped.setdefault(key, []).append(max(row["best"], SOLVED))
    return {key: float(np.median(values)) for key, values in grouped.items()}


def ranks(values: list[float]) -> list[float]:
    """Ranks (1 = best), ties sharing the mean of their places."""
    order = sorted(range(len(values)), key=values.__getitem__)
    result = [0.0] * len(values)
    place = 0
    while place < len(order):
        end = place
        while end + 1 < len(order) and values[order[end + 1]] == values[order[place]]:
            end += 1
        for index in order[place : end + 1]:
            result[index] = (place + end) / 2 + 1
        place = end + 1
    return result


def report(rows: list[dict], optimizers: list[str]) -> str:
    """Per (suite, D, budget): medians per function, then wins and mean ranks."""
    table = medians(rows)
    seeds = sorted({row["seed"] for row in rows})
    lines = [f"seeds {seeds[0]}..{seeds[-1]}; medians of f - f_opt (below {SOLVED:g}: {SOLVED:g})"]
    cells = sorted({(k[0], k[1], k[2]) for k in table})
    for suite, dim, budget in cells:
        functions = sorted({k[3] for k in table if k[:3] == (suite, dim, budget)}, key=_order)
        present = [o for o in optimizers if any((*k[:3], k[4]) == (suite, dim, budget, o)
                                                for k in table)]  # fmt: skip
        # Only functions every optimizer has finished on are compared (an unfinished grid).
        complete = [f for f in functions
                    if all((suite, dim, budget, f, o) in table for o in present)]  # fmt: skip
        heading = f"## {suite}, D = {dim}, {budget} evaluations"
        if len(complete) < len(functions):
            heading += f" ({len(complete)} of {len(functions)} functions finished by all)"
        functions = complete
        if not functions:
            continue
        lines += ["", heading, ""]
        lines.append("| function | " + " | ".join(present) + " |")
        lines.append("|---" * (len(present) + 1) + "|")
        rank_sum = dict.fromkeys(present, 0.0)
        for function in functions:
            values = [table.get((suite, dim, budget, function, o), math.nan) for o in present]
            lines.append(f"| {function} | " + " | ".join(f"{v:.3g}" for v in values) + " |")
            for o, r in zip(present, ranks(values)):
                rank_sum[o] += r
        lines.append(
            "| mean rank | " + " | ".join(f"{rank_sum[o] / len(functions):.2f}" for o in present)
            + " |"
        )  # fmt: skip
        for ours, peers in PEERS_OF.items():
            mine = [o for o in present if split_label(o)[0] == ours]
            for label in mine:
                for peer in (p for p in peers if p in present):
                    better = sum(
                        table[(suite, dim, budget, fn, label)]
                        < table[(suite, dim, budget, fn, peer)]
                        for fn in functions
                    )
                    worse = sum(
                        table[(suite, dim, budget, fn, label)]
                        > table[(suite, dim, budget, fn, peer)]
                        for fn in functions
                    )
                    lines.append(
                        f"- {label} vs {peer}: better median on {better}, worse on {worse}, "
                        f"of {len(functions)}"
                    )
    return "\n".join(lines)


def _order(function: str) -> tuple:
    return (0, int(function), "") if function.isdigit() else (1, CLASSIC.index(function), "")


def grid(args: argparse.Namespace) -> list[Task]:
    tasks = []
    for suite in args.suites.split(","):
        functions = CLASSIC if suite == "classic" else BBOB
        if args.functions:
            functions = [f for f in args.functions.split(",") if f in functions]
        dims = [int(d) for d in args.dims.split(",")] if args.dims else SUITE_DIMS[suite]
        for dim in dims:
            for function in functions:
                for budget in (int(b) for b in args.budgets.split(",")):
                    for seed in range(1, args.seeds + 1):
                        for optimizer in args.optimizers.split(","):
                            tasks.append(Task(optimizer, suite, function, dim, budget, seed))
    return tasks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument(
        "--quick", action="store_true", help="D 10, 10000 evaluations, 3 seeds, 12 functions"
    )
    parser.add_argument("--suites", default="classic,bbob")
    parser.add_argument("--dims", default="", help="e.g. 10,20 [classic 10,30; bbob 10,20]")
    parser.add_argument("--budgets", default="10000,20000")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--functions", default="", help="names or bbob numbers (default: all)")
    parser.add_argument("--optimizers", default=",".join(DEFAULT_OPTIMIZERS),
                        help="labels; metaopt's take parameters: hs:hmcr=0.9+hms=30")  # fmt: skip
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--results", type=Path, default=Path("optimizer_quality.jsonl"))
    parser.add_argument("--peers-env", type=Path, default=PEERS_ENV)
    parser.add_argument("--report-only", action="store_true", help="report the cached results")
    args = parser.parse_args()
    if args.worker:
        worker()
        return
    if args.quick:
        args.dims, args.budgets, args.seeds = "10", "10000", 3
        args.functions = ",".join((*CLASSIC, "1", "3", "8", "10", "15", "21"))
    tasks = grid(args)
    done = set()
    if args.results.exists():
        done = {Task(**{k: r[k] for k in Task.__dataclass_fields__}).key
                for r in map(json.loads, args.results.read_text().splitlines())}  # fmt: skip
    todo = [t for t in tasks if t.key not in done]
    print(f"{len(tasks)} runs, {len(todo)} to do", file=sys.stderr)
    if not args.report_only:
        ours = [t for t in todo if split_label(t.optimizer)[0] not in PEER_RUNNERS]
        theirs = [t for t in todo if split_label(t.optimizer)[0] in PEER_RUNNERS]
        run_tasks(ours, Path(sys.executable), args.jobs, args.results)
        if theirs:
            run_tasks(theirs, peers_python(args.peers_env), args.jobs, args.results)
    wanted = {t.key for t in tasks}
    rows = [r for r in map(json.loads, args.results.read_text().splitlines())
            if Task(**{k: r[k] for k in Task.__dataclass_fields__}).key in wanted]  # fmt: skip
    short = [r for r in rows if r["evaluations"] != r["budget"]]
    if short:
        print(f"note: {len(short)} runs stopped before their budget", file=sys.stderr)
    print(report(rows, args.optimizers.split(",")))


if __name__ == "__main__":
    main()
