"""Warm starts: a run's first candidates drawn around known points (a found gait, other runs'
bests) instead of the optimizer's random first ones, so a search can refine, in a harder
setting, what an easier one found, or choose among what several easier ones found."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from metaopt.errors import ConfigError
from metaopt.space import Space

#: Seeds the start points' generator apart from the optimizer's (which the run seed seeds), so
#: a warm start leaves the optimizer's own random stream as it is.
START_STREAM = 0x5741524D


def check_start(space: Space, point: Sequence[float]) -> None:
    """ConfigError naming what is wrong with a start point for this space (the spread is a
    run setting, checked with the others: RunSettings.check)."""
    if len(point) != space.dim:
        raise ConfigError(
            f"the start point has {len(point)} values but the problem has {space.dim} "
            f"variables ({', '.join(space.names)}); start from a candidate of the same problem "
            "and controller"
        )
    values = np.asarray(point, dtype=float)
    if not space.contains(values):
        outside = [
            f"{name}={value:g} not in [{low:g}, {high:g}]"
            for name, value, low, high in zip(space.names, values, space.lower, space.upper)
            if not low <= value <= high
        ]
        raise ConfigError(
            f"the start point lies outside the problem's bounds: {'; '.join(outside)}"
        )


def fitted_start(
    label: str, names: Sequence[str], point: Sequence[float], space: Space
) -> list[float]:
    """``point``, whose variables are ``names``, as a start point of ``space`` in its order:
    variables the point lacks take their neutral value (Variable.neutral), so a candidate of a
    smaller variant of a problem starts a larger one at the very point it was found.
    ConfigError, naming ``label``, when the point has a variable the space lacks or lacks one
    with no neutral value."""
    given = dict(zip(names, (float(value) for value in point)))
    neutral = {v.name: v.neutral for v in space.variables if v.neutral is not None}
    if set(given) - set(space.names) or set(space.names) - set(given) - set(neutral):
        lacking = f" (it may lack only {', '.join(neutral)}: they have a neutral value)"
        raise ConfigError(
            f"{label} has the variables {', '.join(names)}; this run's problem has "
            f"{', '.join(space.names)} (e.g. another controller): start from a candidate of "
            f"the same variables{lacking if neutral else ''}"
        )
    return [given[name] if name in given else neutral[name] for name in space.names]


def start_points(
    space: Space, points: Sequence[Sequence[float]], spread: float, count: int, seed: int
) -> np.ndarray:
    """``count`` candidates, shape (count, dim): the given points themselves, then points drawn
    uniformly within ±spread of each variable's range around them in turn (the first, the
    second, ..., the first again), clipped to the bounds. The same (points, spread, count,
    seed) always gives the same candidates; one point gives what it gave before several could
    be given."""
    centers = np.asarray(points, dtype=float).reshape(-1, space.dim)
    rng = np.random.default_rng([seed, START_STREAM])
    drawn = max(count - len(centers), 0)
    offsets = (2.0 * rng.random((drawn, space.dim)) - 1.0) * spread * space.width
    around = space.repair(centers[np.arange(drawn) % len(centers)] + offsets, "clip")
    return np.concatenate([centers, around])[:count]
