"""The search space: a box of named, bounded real variables, and the one place repair lives."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from metaopt.errors import ConfigError
from metaopt.params import Param

REPAIR_METHODS = ("clip", "reflect")


def repair_param(
    meaning: str = "how values pushed past a bound come back: clip or reflect",
) -> Param:
    """The ``repair`` parameter an optimizer declares to let users choose Space.repair's method."""
    return Param("repair", str, "clip", meaning, choices=REPAIR_METHODS)


@dataclass(frozen=True)
class Variable:
    """One real decision variable with closed bounds [lower, upper]; ``neutral``, when given, is
    the value at which the variable leaves the problem as it was without it (e.g. a feedback
    gain of 0), so a start point of a problem that lacks it can take that value."""

    name: str
    lower: float
    upper: float
    description: str = ""
    neutral: float | None = None


class Space:
    """An ordered box of real variables; candidates are 1-D float arrays in this order."""

    def __init__(self, variables: Sequence[Variable]) -> None:
        if not variables:
            raise ConfigError("a space needs at least one variable")
        names = [v.name for v in variables]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ConfigError(f"variable names must be unique; repeated: {', '.join(duplicates)}")
        for v in variables:
            if not (np.isfinite(v.lower) and np.isfinite(v.upper)):
                raise ConfigError(
                    f"variable {v.name!r} has bounds [{v.lower}, {v.upper}]; "
                    "bounds must be finite numbers"
                )
            if not v.lower < v.upper:
                raise ConfigError(
                    f"variable {v.name!r} has lower bound {v.lower} >= upper bound {v.upper}; "
                    "lower must be strictly below upper"
                )
            if v.neutral is not None and not v.lower <= v.neutral <= v.upper:
                raise ConfigError(
                    f"variable {v.name!r} has neutral value {v.neutral} outside its bounds "
                    f"[{v.lower}, {v.upper}]; a neutral value must lie within them"
                )
        self.variables: tuple[Variable, ...] = tuple(variables)
        self.names: tuple[str, ...] = tuple(names)
        self.lower: np.ndarray = np.array([v.lower for v in variables], dtype=float)
        self.upper: np.ndarray = np.array([v.upper for v in variables], dtype=float)
        self.lower.flags.writeable = False
        self.upper.flags.writeable = False

    @classmethod
    def from_bounds(
        cls, lower: Iterable[float], upper: Iterable[float], names: Iterable[str] | None = None
    ) -> Space:
        """Build a space from bound sequences; names default to x0, x1, ..."""
        lower, upper = list(lower), list(upper)
        if len(lower) != len(upper):
            raise ConfigError(f"got {len(lower)} lower bounds but {len(upper)} upper bounds")
        names = list(names) if names is not None else [f"x{i}" for i in range(len(lower))]
        if len(names) != len(lower):
            raise ConfigError(f"got {len(names)} names for {len(lower)} bounds")
        return cls([Variable(n, float(lo), float(hi)) for n, lo, hi in zip(names, lower, upper)])

    @property
    def dim(self) -> int:
        """Number of variables."""
        return len(self.variables)

    @property
    def width(self) -> np.ndarray:
        """upper - lower, per variable."""
        return self.upper - self.lower

    def contains(self, x: np.ndarray) -> bool:
        """True when every row of x (or x itself) lies inside the bounds."""
        x = np.asarray(x, dtype=float)
        return bool(np.all((x >= self.lower) & (x <= self.upper)))

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n points drawn uniformly inside the box, shape (n, dim)."""
        return self.lower + rng.random((n, self.dim)) * self.width

    def repair(self, x: np.ndarray, method: str = "clip") -> np.ndarray:
        """Bring out-of-bound values back inside: 'clip' to the bound or 'reflect' off it.

        Works on one candidate or a batch (last axis = variables) and returns a new array.
        """
        x = np.asarray(x, dtype=float)
        if method == "clip":
            return x.clip(self.lower, self.upper)
        if method == "reflect":
            # Fold onto a period of 2*width; robust to values many widths away.
            offset = np.mod(x - self.lower, 2.0 * self.width)
            folded = np.where(offset > self.width, 2.0 * self.width - offset, offset)
            return np.clip(self.lower + folded, self.lower, self.upper)
        raise ConfigError(
            f"unknown repair method {method!r}; accepted: {', '.join(REPAIR_METHODS)}"
        )

    def as_dict(self, x: np.ndarray) -> dict[str, float]:
        """A candidate as {variable name: value}."""
        return {name: float(value) for name, value in zip(self.names, np.asarray(x))}

    def to_json(self) -> list[dict]:
        """Plain-JSON description (stored with each run)."""
        return [
            {"name": v.name, "lower": v.lower, "upper": v.upper, "description": v.description}
            | ({} if v.neutral is None else {"neutral": v.neutral})
            for v in self.variables
        ]

    @classmethod
    def from_json(cls, data: list[dict]) -> Space:
        """Inverse of to_json."""
        return cls([Variable(**item) for item in data])

    def __repr__(self) -> str:
        return f"Space(dim={self.dim}, names={list(self.names)[:4]}{'...' if self.dim > 4 else ''})"
