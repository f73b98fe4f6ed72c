"""The optimizer checks: an optimizer driven through ask/tell as the run loop drives it, on
the kit's spaces, with failed (+inf) evaluations, a JSON state round trip, determinism per seed
and a bowl it must learn to minimize."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any

import numpy as np

from metaopt.optimizer import Optimizer, OptimizerInfo
from metaopt.plugins import registry
from metaopt.space import Space
from metaopt.testing.common import (
    Check,
    ConformanceError,
    build,
    check_binds,
    check_declared_params,
    check_declares_budget,
    resolve_given,
    run_all,
    same,
)

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


def check_optimizer(
    optimizer: str | OptimizerInfo, params: Mapping[str, Any] | None = None
) -> None:
    """Run every optimizer check; raise ConformanceError listing each breach."""
    run_all(_optimizer_info(optimizer).name, optimizer_checks(optimizer, params))


def optimizer_checks(
    optimizer: str | OptimizerInfo, params: Mapping[str, Any] | None = None
) -> dict[str, Check]:
    """The optimizer checks by name, each a callable raising ConformanceError on a breach.

    ``params`` overrides declared parameters (validated like ``--set``).
    """
    info = _optimizer_info(optimizer)
    harness = _OptimizerHarness(info, dict(params or {}))
    return {
        "declared_params": partial(check_declared_params, info.params, info.name),
        "declares_budget": partial(check_declares_budget, info.params),
        "factory_keywords": harness.check_factory_keywords,
        "ask_tell_shapes": harness.check_ask_tell_shapes,
        "tell_inf": harness.check_tell_inf,
        "state_round_trip": harness.check_state_round_trip,
        "recommendation": harness.check_recommendation,
        "deterministic": harness.check_deterministic,
        "minimizes": harness.check_minimizes,
    }


def _optimizer_info(optimizer: str | OptimizerInfo) -> OptimizerInfo:
    return registry().optimizer(optimizer) if isinstance(optimizer, str) else optimizer


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
        values = resolve_given(self.info.params, self.given, self.info.name)
        return build(self.info.factory, (space, seed), values, Optimizer)

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
        values = resolve_given(self.info.params, self.given, self.info.name)
        space = SPACES[MAIN_SPACE]
        check_binds(self.info.factory, (space, 0), values)
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
            if not all(same(a, b) for a, b in zip(before, reference)):
                raise ConformanceError(
                    "two runs with the same seed differ, so no state can resume one; see the "
                    "'deterministic' check"
                )
            resumed = self.resume(optimizer, stop)
            after = self.drive(resumed, sizes[stop:], sum(sizes[:stop]), "resumed run")
            for step, (got, expected) in enumerate(zip(after, reference[stop:])):
                if not same(got, expected):
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
            if not same(a, b):
                raise ConformanceError(
                    f"two optimizers built with seed 7 and told the same fitnesses differ at "
                    f"ask #{step + 1} ({_first_difference(a, b)}); draw every random number "
                    "from self.rng, never from np.random.*, random.* or the clock"
                )
        other = self.drive(self.build(space, 8), sizes, 0, "seed 8")
        if all(same(a, b) for a, b in zip(first, other)):
            raise ConformanceError(
                "seeds 7 and 8 gave the same candidates; use the seed given to the factory "
                "(super().__init__(space, seed) makes self.rng from it)"
            )

    def check_recommendation(self) -> None:
        """``recommendation()`` is None or one point inside the space, and an optimizer rebuilt
        from the JSON state recommends the same (``RUN:recommended`` rebuilds it so)."""
        space = SPACES[MAIN_SPACE]
        optimizer = self.build(space, 0)
        sizes = self.sizes(optimizer, 3)
        stop = len(sizes)  # asks made before the recommendation is read
        self.drive(optimizer, sizes, 0, "run")
        point = _recommended(optimizer, f"after {stop} asks")
        if point is not None and (point.shape != (space.dim,) or not space.contains(point)):
            raise ConformanceError(
                f"recommendation() after {stop} asks returned shape {point.shape} at "
                f"{point.tolist()}, outside the space or not one point of {space.dim} "
                "variables; return one point inside the bounds (space.repair) or None"
            )
        again = _recommended(self.resume(optimizer, stop), "after load_state_dict")
        if (point is None) != (again is None) or (point is not None and not same(point, again)):
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
