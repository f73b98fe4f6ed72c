"""The conformance kit: checks that an optimizer or a problem keeps metaopt's contract.

Call it from a plugin's own pytest suite::

    from metaopt.testing import check_optimizer, check_problem

    def test_my_optimizer_conforms():
        check_optimizer("hill-climb")                  # a registered name, or an OptimizerInfo

    def test_my_problem_conforms():
        check_problem("bowl", params={"dim": 3})

or get one pytest test per check::

    CHECKS = optimizer_checks("hill-climb")

    @pytest.mark.parametrize("check", CHECKS)
    def test_conforms(check):
        CHECKS[check]()

A physics engine (a ``metaopt_physics_backends`` plugin) gets the engine agreement suite: what
it simulates, measured from it (friction, motors, mass, standing, free fall; see
metaopt.physics.agreement)::

    def test_my_engine_agrees():
        check_engine("my-engine")

A breach raises ConformanceError (an AssertionError) saying what was breached and how to fix it.
The kit holds a plugin to what the run loop and the run store rely on, and to a little more
that a sound plugin always satisfies: an optimizer declares ``budget`` (metaopt.budget_param()),
which generic code gives every optimizer; a problem must evaluate every point sampled uniformly in
its space to a finite fitness, and different seeds must make an optimizer propose different
candidates. A state must survive ``json.dumps`` with default settings, as the run store writes it
(so inf and nan are allowed), and a fresh optimizer loading it must continue bit for bit.
"""

from __future__ import annotations

import inspect
import json
import math
import numbers
import pickle
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from multiprocessing import get_context
from typing import Any

import numpy as np

from metaopt.errors import ConfigError
from metaopt.optimizer import Optimizer, OptimizerInfo
from metaopt.params import Param, resolve
from metaopt.physics import BackendInfo
from metaopt.physics.agreement import MEASUREMENTS, measure
from metaopt.plugins import registry
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense
from metaopt.seeding import EvaluationSeeds
from metaopt.space import Space

Check = Callable[[], None]


class ConformanceError(AssertionError):
    """A plugin breaks metaopt's contract; the message says what was breached and what to fix."""


# Spaces the optimizer checks run on: one variable, narrow and asymmetric bounds far from 0,
# and many variables of different widths. Bounds and widths are exact in binary floating point.
SPACES: dict[str, Space] = {
    "1-D [0, 1]": Space.from_bounds([0.0], [1.0]),
    "3-D narrow, asymmetric": Space.from_bounds([-7.0, 1.0, 100.0], [3.0, 1.0 + 2.0**-20, 100.5]),
    "30-D": Space.from_bounds([-1.0 - i for i in range(30)], [2.0 * (i + 1) for i in range(30)]),
}
#: The space of the state, determinism and tell-inf checks.
MAIN_SPACE = "3-D narrow, asymmetric"
#: Every FAIL_PERIOD-th evaluation of the driven runs (offset FAIL_OFFSET) is told as +inf.
FAIL_PERIOD, FAIL_OFFSET = 7, 3
#: Numbers of asks after which the state round trip stops and resumes.
STOP_POINTS = (0, 1, 5, 10)
#: The minimization check: evaluations, how many form the early reference, how many the late one.
MINIMIZE_BUDGET, EARLY, LATE = 300, 20, 100
#: Points each problem check evaluates: the space's centre and this many uniform samples.
PROBLEM_SAMPLES = 4


# ----------------------------------------------------------------------------------------------
# Public API


def check_optimizer(
    optimizer: str | OptimizerInfo, params: Mapping[str, Any] | None = None
) -> None:
    """Run every optimizer check; raise ConformanceError listing each breach."""
    _run_all(_optimizer_info(optimizer).name, optimizer_checks(optimizer, params))


def check_problem(
    problem: str | ProblemInfo,
    params: Mapping[str, Any] | None = None,
    *,
    in_subprocess: bool = False,
) -> None:
    """Run every problem check (with ``in_subprocess``, also the spawned-process one)."""
    checks = problem_checks(problem, params, in_subprocess=in_subprocess)
    _run_all(_problem_info(problem).name, checks)


def optimizer_checks(
    optimizer: str | OptimizerInfo, params: Mapping[str, Any] | None = None
) -> dict[str, Check]:
    """The optimizer checks by name, each a callable raising ConformanceError on a breach.

    ``params`` overrides declared parameters (validated like ``--set``).
    """
    info = _optimizer_info(optimizer)
    harness = _OptimizerHarness(info, dict(params or {}))
    return {
        "declared_params": partial(_check_declared_params, info.params, info.name),
        "declares_budget": partial(_check_declares_budget, info.params),
        "factory_keywords": harness.check_factory_keywords,
        "ask_tell_shapes": harness.check_ask_tell_shapes,
        "tell_inf": harness.check_tell_inf,
        "state_round_trip": harness.check_state_round_trip,
        "recommendation": harness.check_recommendation,
        "deterministic": harness.check_deterministic,
        "minimizes": harness.check_minimizes,
    }


def problem_checks(
    problem: str | ProblemInfo,
    params: Mapping[str, Any] | None = None,
    *,
    in_subprocess: bool = False,
) -> dict[str, Check]:
    """The problem checks by name; ``in_subprocess`` adds the (slower) spawned-process check."""
    info = _problem_info(problem)
    harness = _ProblemHarness(info, dict(params or {}))
    checks: dict[str, Check] = {
        "declared_params": partial(_check_declared_params, info.params, info.name),
        "factory_keywords": harness.check_factory_keywords,
        "interface": harness.check_interface,
        "evaluate": harness.check_evaluate,
        "key_metrics": harness.check_key_metrics,
        "pure": harness.check_pure,
    }
    if in_subprocess:
        checks["pure_in_subprocess"] = harness.check_pure_in_subprocess
    return checks


def check_engine(backend: str | BackendInfo) -> None:
    """Run every engine agreement check; raise ConformanceError listing each breach."""
    _run_all(_backend_name(backend), engine_checks(backend))


def engine_checks(backend: str | BackendInfo) -> dict[str, Check]:
    """The engine agreement checks by name (metaopt.physics.agreement.MEASUREMENTS), each
    measuring a fresh simulation of the NAO on the engine and raising ConformanceError when a
    figure is off its prediction by more than its tolerance."""
    return {name: partial(_check_agreement, backend, name) for name in MEASUREMENTS}


def _check_agreement(backend: str | BackendInfo, name: str) -> None:
    breaches = [figure.describe() for figure in measure(backend, name) if not figure.agrees]
    if breaches:
        raise ConformanceError(
            f"the engine {_backend_name(backend)!r} simulates something else: "
            + "; ".join(breaches)
        )


def _backend_name(backend: str | BackendInfo) -> str:
    return backend if isinstance(backend, str) else backend.name


# ----------------------------------------------------------------------------------------------
# Shared


def _optimizer_info(optimizer: str | OptimizerInfo) -> OptimizerInfo:
    return registry().optimizer(optimizer) if isinstance(optimizer, str) else optimizer


def _problem_info(problem: str | ProblemInfo) -> ProblemInfo:
    return registry().problem(problem) if isinstance(problem, str) else problem


def _run_all(name: str, checks: Mapping[str, Check]) -> None:
    breaches = []
    for check_name, check in checks.items():
        try:
            check()
        except ConformanceError as error:
            breaches.append(f"- {check_name}: {error}")
    if breaches:
        raise ConformanceError(
            f"{name!r} breaks {len(breaches)} of {len(checks)} checks:\n" + "\n".join(breaches)
        )


def _check_declared_params(params: Sequence[Param], owner: str) -> None:
    """Names are unique identifiers (they are keywords and --set names); defaults are valid."""
    names = [p.name for p in params]
    for p in params:
        if not p.name.isidentifier():
            raise ConformanceError(
                f"parameter name {p.name!r} is not a Python identifier; the factory takes "
                "parameters by keyword and --set NAME=VALUE names them: use letters, digits, _"
            )
        if names.count(p.name) > 1:
            raise ConformanceError(f"parameter {p.name!r} is declared twice; declare it once")
        try:
            p.validate(p.default, owner)
        except ConfigError:
            raise ConformanceError(
                f"parameter {p.name!r} has default {p.default!r}, which its own declaration "
                f"rejects (expected {p.accepted()}); change the default or the declared range"
            ) from None


def _check_declares_budget(params: Sequence[Param]) -> None:
    """An optimizer declares the int parameter ``budget`` that generic code gives every one."""
    if not any(p.name == "budget" and p.type is int for p in params):
        raise ConformanceError(
            "it declares no int parameter 'budget'; add metaopt.budget_param() to its params "
            "(metaopt run, metaopt.minimize and create_optimizer set it to the evaluations the "
            "optimizer will be told; one without a schedule accepts it and may ignore it)"
        )


def _resolve(params: Sequence[Param], given: Mapping[str, Any], owner: str) -> dict[str, Any]:
    try:
        return resolve(params, given, owner)
    except ConfigError as error:
        raise ConformanceError(f"the parameters given to the kit are invalid: {error}") from None


def _check_binds(factory: Callable[..., Any], args: tuple, values: Mapping[str, Any]) -> None:
    """The factory can take every declared parameter by keyword (when its signature shows)."""
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):  # builtins and some callables hide their signature
        return
    accepted = signature.parameters
    if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in accepted.values()):
        unknown = [
            name
            for name in values
            if name not in accepted or accepted[name].kind is inspect.Parameter.POSITIONAL_ONLY
        ]
        if unknown:
            raise ConformanceError(
                f"the factory takes no keyword argument for the declared parameter(s) "
                f"{', '.join(map(repr, unknown))}; give it one keyword argument per declared "
                "Param, with the same name"
            )
    try:
        signature.bind(*args, **values)
    except TypeError as error:
        raise ConformanceError(
            f"the factory cannot be called with the declared parameters by keyword: {error}; "
            "every argument besides space and seed must be a declared Param or have a default"
        ) from None


def _build(factory: Callable[..., Any], args: tuple, values: Mapping[str, Any], kind: type):
    call = "factory(space, seed, **params)" if args else "factory(**params)"
    try:
        built = factory(*args, **values)
    except Exception as error:
        raise ConformanceError(
            f"{call} raised {type(error).__name__}: {error}; it must build a ready "
            f"{kind.__name__} from the declared parameters' values"
        ) from None
    if not isinstance(built, kind):
        raise ConformanceError(
            f"{call} returned {type(built).__name__}, not a metaopt.{kind.__name__}; "
            f"subclass metaopt.{kind.__name__}"
        )
    return built


def _same(a: Any, b: Any) -> bool:
    """Equal, bit for bit for floats, NaN equal to NaN."""
    return bool(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True))


# ----------------------------------------------------------------------------------------------
# Optimizer checks


def _sphere(space: Space, batch: np.ndarray) -> np.ndarray:
    """A bowl whose minimum lies 30% of the way across every variable, in units of the width."""
    target = space.lower + 0.3 * space.width
    return (((batch - target) / space.width) ** 2).sum(axis=1)


def _told(space: Space, batch: np.ndarray, first: int) -> np.ndarray:
    """The bowl's values for evaluations first, first + 1, ...; now and then one failed (+inf)."""
    fitnesses = _sphere(space, batch)
    index = first + np.arange(len(batch))
    fitnesses[index % FAIL_PERIOD == FAIL_OFFSET] = math.inf
    return fitnesses


def _first_difference(a: np.ndarray, b: np.ndarray) -> str:
    if a.shape != b.shape:
        return f"shapes {a.shape} and {b.shape}"
    row, column = np.argwhere(a != b)[0]
    return f"row {row}, variable {column}: {float(a[row, column])!r} vs {float(b[row, column])!r}"


class _OptimizerHarness:
    """Builds the optimizer under test and drives it through ask/tell like the run loop."""

    def __init__(self, info: OptimizerInfo, given: dict[str, Any]) -> None:
        self.info = info
        self.given = given

    def build(self, space: Space, seed: int) -> Optimizer:
        values = _resolve(self.info.params, self.given, self.info.name)
        return _build(self.info.factory, (space, seed), values, Optimizer)

    def batch_size(self, optimizer: Optimizer) -> int:
        size = optimizer.batch_size
        if not isinstance(size, (int, np.integer)) or isinstance(size, bool) or size < 1:
            raise ConformanceError(
                f"batch_size is {size!r}; it must be a positive int (1 when in doubt)"
            )
        return int(size)

    def sizes(self, optimizer: Optimizer, rounds: int) -> list[int]:
        """Ask sizes: 1, 2, 7, batch_size and more than batch_size, rounds times over."""
        size = self.batch_size(optimizer)
        return [1, 2, 7, size, size + 3] * rounds

    def ask(self, optimizer: Optimizer, n: int, where: str) -> np.ndarray:
        try:
            batch = optimizer.ask(n)
        except Exception as error:
            raise ConformanceError(
                f"ask({n}) raised {type(error).__name__}: {error} ({where}); ask must serve any "
                "n >= 1, whatever batch_size is"
            ) from None
        space = optimizer.space
        if not isinstance(batch, np.ndarray) or batch.dtype.kind != "f":
            raise ConformanceError(
                f"ask({n}) returned {type(batch).__name__} of {getattr(batch, 'dtype', '?')} "
                f"({where}); return a float numpy array of shape (n, dim)"
            )
        if batch.shape != (n, space.dim):
            raise ConformanceError(
                f"ask({n}) returned shape {batch.shape}, expected ({n}, {space.dim}) ({where}); "
                "return exactly n candidates, one per row, whatever batch_size is"
            )
        if not np.isfinite(batch).all():
            raise ConformanceError(
                f"ask({n}) returned non-finite values ({where}); every candidate must be finite"
            )
        outside = ~((batch >= space.lower) & (batch <= space.upper))
        if outside.any():
            row, column = np.argwhere(outside)[0]
            raise ConformanceError(
                f"ask({n}) returned a candidate outside the space ({where}): variable "
                f"{column} = {float(batch[row, column])!r} not in [{float(space.lower[column])!r}, "
                f"{float(space.upper[column])!r}]; bring candidates inside with space.repair(x)"
            )
        return batch

    def tell(self, optimizer: Optimizer, batch: np.ndarray, fitnesses: np.ndarray, where: str):
        try:
            optimizer.tell(batch, fitnesses)
        except Exception as error:
            failed = int(np.isinf(fitnesses).sum())
            hint = (
                f"; {failed} of the {len(fitnesses)} fitnesses told were +inf: failed evaluations "
                "reach tell as +inf, treat them as worse than any finite fitness"
                if failed
                else ""
            )
            raise ConformanceError(
                f"tell raised {type(error).__name__}: {error} ({where}){hint}"
            ) from None

    def drive(
        self, optimizer: Optimizer, sizes: Sequence[int], first: int, where: str
    ) -> list[np.ndarray]:
        """Ask for each size and tell the kit's fitnesses; the batches asked, copied."""
        batches = []
        for step, n in enumerate(sizes):
            at = f"{where}, ask #{step + 1}"
            batch = self.ask(optimizer, n, at)
            batches.append(batch.copy())
            self.tell(optimizer, batch, _told(optimizer.space, batch, first), at)
            first += n
        return batches

    def resume(self, optimizer: Optimizer, stop: int) -> Optimizer:
        """A fresh optimizer (seed 0) loaded from ``optimizer``'s JSON state, taken after
        ``stop`` asks."""
        text = _state_json(optimizer, stop)
        resumed = self.build(optimizer.space, 0)
        try:
            resumed.load_state_dict(json.loads(text))
        except Exception as error:
            raise ConformanceError(
                f"load_state_dict raised {type(error).__name__}: {error} on the JSON state "
                f"taken after {stop} asks; it must accept what state_dict returned, read "
                "back from JSON (lists for arrays)"
            ) from None
        return resumed

    def check_factory_keywords(self) -> None:
        """factory(space, seed, **params) takes every declared parameter and builds an Optimizer."""
        values = _resolve(self.info.params, self.given, self.info.name)
        space = SPACES[MAIN_SPACE]
        _check_binds(self.info.factory, (space, 0), values)
        self.build(space, 0)

    def check_ask_tell_shapes(self) -> None:
        """Any n gives (n, dim) finite candidates inside the space, on every kit space."""
        for label, space in SPACES.items():
            optimizer = self.build(space, 0)
            self.drive(optimizer, self.sizes(optimizer, 3), 0, f"space {label}")

    def check_tell_inf(self) -> None:
        """Batches of failed (+inf) evaluations, first batch included, do not break it."""
        space = SPACES[MAIN_SPACE]
        optimizer = self.build(space, 0)
        for step, n in enumerate(self.sizes(optimizer, 2)):
            where = f"ask #{step + 1}, after +inf fitnesses"
            batch = self.ask(optimizer, n, where)
            fitnesses = _sphere(space, batch)
            failed = slice(None) if step % 3 == 0 else slice(step % 2, None, 2)
            fitnesses[failed] = math.inf  # the whole batch, or every other evaluation
            self.tell(optimizer, batch, fitnesses, where)

    def check_state_round_trip(self) -> None:
        """A fresh optimizer loading the JSON state continues exactly as the uninterrupted one."""
        space = SPACES[MAIN_SPACE]
        sizes = self.sizes(self.build(space, 0), 3)
        reference = self.drive(self.build(space, 0), sizes, 0, "uninterrupted run")
        for stop in STOP_POINTS:
            optimizer = self.build(space, 0)
            before = self.drive(optimizer, sizes[:stop], 0, f"run stopped after {stop} asks")
            if not all(_same(a, b) for a, b in zip(before, reference)):
                raise ConformanceError(
                    "two runs with the same seed differ, so no state can resume one; see the "
                    "'deterministic' check"
                )
            resumed = self.resume(optimizer, stop)
            after = self.drive(resumed, sizes[stop:], sum(sizes[:stop]), "resumed run")
            for step, (got, expected) in enumerate(zip(after, reference[stop:])):
                if not _same(got, expected):
                    raise ConformanceError(
                        f"resumed from the JSON state taken after {stop} asks, ask "
                        f"#{stop + step + 1} differs from the uninterrupted run "
                        f"({_first_difference(got, expected)}); "
                        "state_dict must hold everything later asks depend on, the generator "
                        "included (rng_state(self.rng)), and load_state_dict restore all of it"
                    )

    def check_deterministic(self) -> None:
        """The same seed gives the same candidates; another seed gives other candidates."""
        space = SPACES[MAIN_SPACE]
        sizes = self.sizes(self.build(space, 0), 2)
        first = self.drive(self.build(space, 7), sizes, 0, "seed 7")
        again = self.drive(self.build(space, 7), sizes, 0, "seed 7, again")
        for step, (a, b) in enumerate(zip(first, again)):
            if not _same(a, b):
                raise ConformanceError(
                    f"two optimizers built with seed 7 and told the same fitnesses differ at "
                    f"ask #{step + 1} ({_first_difference(a, b)}); draw every random number "
                    "from self.rng, never from np.random.*, random.* or the clock"
                )
        other = self.drive(self.build(space, 8), sizes, 0, "seed 8")
        if all(_same(a, b) for a, b in zip(first, other)):
            raise ConformanceError(
                "seeds 7 and 8 gave the same candidates; use the seed given to the factory "
                "(super().__init__(space, seed) makes self.rng from it)"
            )

    def check_recommendation(self) -> None:
        """``recommendation()`` is None or one point inside the space, and an optimizer rebuilt
        from the JSON state recommends the same (``RUN:recommended`` rebuilds it so)."""
        space = SPACES[MAIN_SPACE]
        optimizer = self.build(space, 0)
        stop = 3
        self.drive(optimizer, self.sizes(optimizer, stop), 0, "run")
        point = _recommended(optimizer, f"after {stop} asks")
        if point is not None and (point.shape != (space.dim,) or not space.contains(point)):
            raise ConformanceError(
                f"recommendation() after {stop} asks returned shape {point.shape} at "
                f"{point.tolist()}, outside the space or not one point of {space.dim} "
                "variables; return one point inside the bounds (space.repair) or None"
            )
        again = _recommended(self.resume(optimizer, stop), "after load_state_dict")
        if (point is None) != (again is None) or (point is not None and not _same(point, again)):
            raise ConformanceError(
                f"an optimizer rebuilt from the JSON state taken after {stop} asks recommends "
                f"{None if again is None else again.tolist()}, the original "
                f"{None if point is None else point.tolist()}; compute the recommendation "
                "from what state_dict holds"
            )

    def check_minimizes(self) -> None:
        """On a 5-D bowl, late candidates beat early ones: it learns, and lower is better."""
        space = Space.from_bounds([-3.0] * 5, [7.0] * 5)
        for seed in (1, 2, 3):
            optimizer = self.build(space, seed)
            fitnesses: list[float] = []
            while len(fitnesses) < MINIMIZE_BUDGET:
                n = min(self.batch_size(optimizer), MINIMIZE_BUDGET - len(fitnesses))
                where = f"seed {seed}, evaluation {len(fitnesses) + 1}"
                batch = self.ask(optimizer, n, where)
                values = _sphere(space, batch)
                self.tell(optimizer, batch, values, where)
                fitnesses.extend(values.tolist())
            early = float(np.median(fitnesses[:EARLY]))
            late = min(fitnesses[-LATE:])
            if not late < early:
                raise ConformanceError(
                    f"on a 5-D bowl (seed {seed}) the best of the last {LATE} of "
                    f"{MINIMIZE_BUDGET} evaluations ({late:.4g}) is no better than the median of "
                    f"the first {EARLY} ({early:.4g}); the optimizer must minimize (lower "
                    "fitness is better) and learn from what tell gives it"
                )


def _recommended(optimizer: Optimizer, where: str) -> np.ndarray | None:
    """What ``optimizer.recommendation()`` returns, as a float array (or None)."""
    try:
        point = optimizer.recommendation()
    except Exception as error:
        raise ConformanceError(
            f"recommendation() raised {type(error).__name__}: {error} ({where})"
        ) from None
    return None if point is None else np.asarray(point, dtype=float)


def _state_json(optimizer: Optimizer, stop: int) -> str:
    """The state as JSON text, as the run store writes it (json.dumps, default settings)."""
    try:
        state = optimizer.state_dict()
    except Exception as error:
        raise ConformanceError(
            f"state_dict raised {type(error).__name__}: {error} after {stop} asks"
        ) from None
    if not isinstance(state, dict):
        raise ConformanceError(f"state_dict returned {type(state).__name__}; return a dict")
    try:
        return json.dumps(state)
    except (TypeError, ValueError) as error:
        where, value = _first_non_json(state, "state")
        raise ConformanceError(
            f"state_dict is not plain JSON after {stop} asks: {where or 'state'} is "
            f"{type(value).__module__}.{type(value).__name__} ({error}); convert arrays with "
            ".tolist(), numpy numbers with float() or int(), the generator with rng_state(rng)"
        ) from None


def _first_non_json(value: Any, where: str) -> tuple[str, Any]:
    """The path and value of the first part json.dumps cannot write (or the whole value)."""
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                return f"{where} key {key!r}", key
            found = _first_non_json(item, f"{where}[{key!r}]")
            if found[0] != "":
                return found
        return "", None
    if isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            found = _first_non_json(item, f"{where}[{index}]")
            if found[0] != "":
                return found
        return "", None
    if value is None or isinstance(value, (str, int, float, bool)):
        return "", None
    return where, value


# ----------------------------------------------------------------------------------------------
# Problem checks


def _is_real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _evaluate_all(problem: Problem, points: np.ndarray, seeds: Sequence[int]) -> list[Evaluation]:
    results = []
    for x, seed in zip(points, seeds):
        argument = x.copy()
        try:
            result = problem.evaluate(argument, seed)
        except Exception as error:
            raise ConformanceError(
                f"evaluate(x, seed={seed}) raised {type(error).__name__}: {error} at x = "
                f"{x.tolist()}, a point inside the space; every point of the space should "
                "evaluate (raise EvaluationError only where it truly cannot)"
            ) from None
        if not _same(argument, x):
            raise ConformanceError(
                "evaluate changed the x it was given; work on a copy (the run loop stores x)"
            )
        results.append(result)
    return results


def _evaluate_fresh(
    factory: Callable[..., Problem], values: dict[str, Any], points: list, seeds: list
) -> list[tuple[float, dict[str, float]]]:
    """Build the problem and evaluate; runs in a spawned process for the subprocess check."""
    problem = factory(**values)
    try:
        results = [problem.evaluate(np.array(x), seed) for x, seed in zip(points, seeds)]
    finally:
        problem.close()
    return [(r.fitness, r.metrics) for r in results]


class _ProblemHarness:
    """Builds the problem under test and evaluates the kit's points on it."""

    def __init__(self, info: ProblemInfo, given: dict[str, Any]) -> None:
        self.info = info
        self.given = given

    def values(self) -> dict[str, Any]:
        return _resolve(self.info.params, self.given, self.info.name)

    def build(self) -> Problem:
        return _build(self.info.factory, (), self.values(), Problem)

    def points(self, problem: Problem) -> tuple[np.ndarray, list[int]]:
        """The space's centre and uniform samples, with seeds as a run would give them."""
        space = problem.space
        centre = (space.lower + 0.5 * space.width)[None, :]
        samples = space.sample(np.random.default_rng(2024), PROBLEM_SAMPLES)
        seeds = EvaluationSeeds(1)
        return np.vstack([centre, samples]), [seeds(i) for i in range(1 + PROBLEM_SAMPLES)]

    def evaluations(self) -> tuple[np.ndarray, list[int], list[Evaluation]]:
        """The kit's points evaluated on a fresh problem (closed after)."""
        problem = self.build()
        try:
            self.check_space(problem)
            points, seeds = self.points(problem)
            return points, seeds, _evaluate_all(problem, points, seeds)
        finally:
            problem.close()

    def check_space(self, problem: Problem) -> None:
        if not isinstance(getattr(problem, "space", None), Space):
            raise ConformanceError(
                f"problem.space is {type(getattr(problem, 'space', None)).__name__}; set it to "
                "a metaopt.Space in __init__ (e.g. Space.from_bounds(lower, upper))"
            )

    def check_factory_keywords(self) -> None:
        """factory(**params) takes every declared parameter and builds a Problem."""
        _check_binds(self.info.factory, (), self.values())
        self.build().close()

    def check_interface(self) -> None:
        """A Space, a Sense, key_metrics names, a finite optimum or None."""
        problem = self.build()
        try:
            self.check_space(problem)
            try:
                Sense(problem.sense)
            except ValueError:
                raise ConformanceError(
                    f"problem.sense is {problem.sense!r}; use Sense.MINIMIZE or Sense.MAXIMIZE"
                ) from None
            metrics = problem.key_metrics
            if isinstance(metrics, str) or not all(isinstance(m, str) for m in metrics):
                raise ConformanceError(
                    f"key_metrics is {metrics!r}; make it a tuple of metric names, "
                    "e.g. ('distance',)"
                )
            optimum = problem.optimum
            if optimum is not None and not (_is_real(optimum) and math.isfinite(optimum)):
                raise ConformanceError(
                    f"optimum is {optimum!r}; make it the known best fitness or None"
                )
        finally:
            problem.close()

    def check_evaluate(self) -> None:
        """Each kit point gives an Evaluation: finite float fitness, metrics of str -> float."""
        points, _, results = self.evaluations()
        for x, result in zip(points, results):
            at = f"at x = {x.tolist()}"
            if not isinstance(result, Evaluation):
                raise ConformanceError(
                    f"evaluate returned {type(result).__name__} {at}; return "
                    "metaopt.Evaluation(fitness, metrics)"
                )
            fitness = result.fitness
            if not _is_real(fitness):
                raise ConformanceError(
                    f"fitness is {type(fitness).__module__}.{type(fitness).__name__} "
                    f"{fitness!r} {at}; return a float (float(value))"
                )
            if not math.isfinite(fitness):
                raise ConformanceError(
                    f"fitness is {fitness!r} {at}, a point inside the space; return a finite "
                    "float (NaN and inf mark a failed evaluation)"
                )
            self.check_metrics(result.metrics, at)

    def check_metrics(self, metrics: Any, at: str) -> None:
        if not isinstance(metrics, dict):
            raise ConformanceError(
                f"metrics is {type(metrics).__name__} {at}; return a dict of name -> float"
            )
        for name, value in metrics.items():
            if not isinstance(name, str):
                raise ConformanceError(f"metric name {name!r} is not a str {at}")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConformanceError(
                    f"metric {name!r} is {type(value).__module__}.{type(value).__name__} "
                    f"{value!r} {at}; metric values must be Python floats (float(value)) so the "
                    "run store can write them as JSON"
                )

    def check_key_metrics(self) -> None:
        """Every name in key_metrics is among the metrics each evaluation returns."""
        problem = self.build()
        key_metrics = tuple(problem.key_metrics)
        problem.close()
        points, _, results = self.evaluations()
        for x, result in zip(points, results):
            missing = [m for m in key_metrics if m not in result.metrics]
            if missing:
                raise ConformanceError(
                    f"key_metrics names {missing} but evaluate returned only "
                    f"{sorted(result.metrics)} at x = {x.tolist()}; return every key metric, "
                    "or drop it from key_metrics"
                )

    def check_pure(self) -> None:
        """The same (x, seed) gives the same Evaluation again, in any order, on a fresh problem."""
        points, seeds, first = self.evaluations()
        problem = self.build()
        try:
            reverse = _evaluate_all(problem, points[::-1], seeds[::-1])[::-1]
            again = _evaluate_all(problem, points, seeds)
        finally:
            problem.close()
        for label, results in (("in reverse order", reverse), ("again", again)):
            for x, seed, a, b in zip(points, seeds, first, results):
                _require_same(a.fitness, a.metrics, b.fitness, b.metrics, x, seed, label)

    def check_pure_in_subprocess(self) -> None:
        """A problem built by the factory in a spawned process evaluates exactly the same."""
        points, seeds, here = self.evaluations()
        try:
            pickle.dumps(self.info.factory)
        except Exception as error:
            raise ConformanceError(
                f"the factory cannot be pickled ({type(error).__name__}: {error}); process "
                "executors send it to their workers: use a module-level class or function, or "
                "functools.partial of one"
            ) from None
        with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
            job = pool.submit(
                _evaluate_fresh, self.info.factory, self.values(), points.tolist(), seeds
            )
            try:
                there = job.result()
            except Exception as error:
                raise ConformanceError(
                    f"in a spawned process, building the problem with the factory and "
                    f"evaluating raised {type(error).__name__}: {error}; a fresh process must "
                    "import and build it from the factory alone (no state set up elsewhere)"
                ) from None
        for x, seed, a, (fitness, metrics) in zip(points, seeds, here, there):
            _require_same(a.fitness, a.metrics, fitness, metrics, x, seed, "in another process")


def _require_same(
    fitness: Any, metrics: dict, other_fitness: Any, other_metrics: dict, x, seed, label: str
) -> None:
    if not (_same(fitness, other_fitness) and _same_metrics(metrics, other_metrics)):
        raise ConformanceError(
            f"evaluate(x, seed={seed}) at x = {x.tolist()} gave fitness {fitness!r}, then "
            f"{other_fitness!r} {label} (metrics {metrics} vs {other_metrics}); evaluate must be "
            "a pure function of (x, seed): no counters, caches that change results, global "
            "random state or clock; draw noise from np.random.default_rng(seed)"
        )


def _same_metrics(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
