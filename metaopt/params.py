"""Declared plugin parameters: name, type, default, range, meaning; parsing and validation."""

from __future__ import annotations

import difflib
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from typing import Any

from metaopt.errors import ConfigError

_TYPES: dict[type, str] = {int: "int", float: "float", str: "str", bool: "bool"}
_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}
#: the largest float: a whole number written with a fraction or an exponent is read up to it
_FLOAT_MAX = Decimal(sys.float_info.max)


@dataclass(frozen=True)
class Param:
    """One parameter a plugin accepts.

    ``low``/``high`` bound numbers (inclusive unless ``low_open``/``high_open``), ``choices``
    restricts strings. ``default`` must itself be valid. A float is finite unless ``infinite``
    (e.g. a friction of inf = no sliding limit); NaN never is a value.
    """

    name: str
    type: type
    default: Any
    help: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] | None = None
    infinite: bool = False

    def __post_init__(self) -> None:
        if self.type not in _TYPES:
            raise TypeError(f"Param {self.name!r}: type must be one of {list(_TYPES.values())}")

    @property
    def type_name(self) -> str:
        """'int', 'float', 'str' or 'bool'."""
        return _TYPES[self.type]

    def accepted(self) -> str:
        """Human text of the accepted values, e.g. 'a float in [0, 1]'."""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.type is bool:
            return "true or false"
        finite = self.type is float and not self.infinite
        if self.low is None and self.high is None:
            return f"any {'finite ' if finite else ''}{self.type_name}"
        # an unbounded side is open: inf itself is a value only of an ``infinite`` parameter
        closed_low = self.infinite if self.low is None else not self.low_open
        closed_high = self.infinite if self.high is None else not self.high_open
        left, right = "[" if closed_low else "(", "]" if closed_high else ")"
        low = "-inf" if self.low is None else _fmt(self.low)
        high = "inf" if self.high is None else _fmt(self.high)
        return f"an {self.type_name} in {left}{low}, {high}{right}".replace("an float", "a float")

    def range_text(self) -> str:
        """Compact range for tables: '[0, 1]', 'a|b|c' or ''."""
        if self.choices:
            return "|".join(self.choices)
        if self.low is None and self.high is None:
            return ""
        return self.accepted().split(" in ", 1)[1]

    def parse(self, text: str, owner: str) -> Any:
        """Convert command-line text to a valid value, or raise ConfigError."""
        try:
            if self.type is bool:
                lowered = text.strip().lower()
                if lowered not in _TRUE | _FALSE:
                    raise ValueError
                value: Any = lowered in _TRUE
            elif self.type is int:
                value = _exact_int(text)
            else:
                value = self.type(text)
        except ValueError:
            raise ConfigError(
                f"{owner} parameter {self.name!r}: cannot read {text!r}; expected {self.accepted()}"
            ) from None
        return self.validate(value, owner)

    def validate(self, value: Any, owner: str) -> Any:
        """Check a Python value against type and range; return it normalised."""
        bad = ConfigError(
            f"{owner} parameter {self.name!r} = {value!r} is invalid; expected {self.accepted()}"
        )
        if self.type is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if self.type is int and isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, self.type) or (self.type is int and isinstance(value, bool)):
            raise bad
        if self.choices is not None and value not in self.choices:
            raise bad
        if self.type in (int, float):
            if value != value or (abs(value) == math.inf and not self.infinite):
                raise bad  # NaN, or inf where the parameter takes only finite values
            if self.low is not None and (value < self.low or (self.low_open and value == self.low)):
                raise bad
            if self.high is not None and (
                value > self.high or (self.high_open and value == self.high)
            ):
                raise bad
        return value


def _exact_int(text: str) -> int:
    """``text`` as an int, exactly (read through a float, 2**53 + 1 became 2**53): its digits,
    or a whole number written as a float ('1e3', '10.0') within float range; else ValueError."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        number = Decimal(text)
    except InvalidOperation:
        raise ValueError from None
    if not number.is_finite() or abs(number) > _FLOAT_MAX or number != number.to_integral_value():
        raise ValueError
    return int(number)


def _fmt(number: float | int) -> str:
    """A bound, compact ('1e+06'), or exact where compact would round it (2**63 - 1 read as
    9.22337e+18 would name a bound that is not the one checked)."""
    compact = f"{number:g}"
    return compact if float(compact) == number else str(number)


def close_matches(name: str, known: Sequence[str]) -> list[str]:
    """Up to three of ``known`` that look like ``name``, ignoring case, closest first."""
    by_lower = {k.lower(): k for k in known}
    close = difflib.get_close_matches(name.lower(), list(by_lower), n=3, cutoff=0.5)
    return [by_lower[c] for c in close]


def suggest(name: str, known: Sequence[str]) -> str:
    """' Did you mean ...?' for close matches (ignoring case), or ''."""
    close = close_matches(name, known)
    return f" Did you mean {' or '.join(map(repr, close))}?" if close else ""


def resolve(params: Sequence[Param], given: Mapping[str, Any], owner: str) -> dict[str, Any]:
    """Defaults overlaid with validated given values; unknown names raise ConfigError."""
    declared = {p.name: p for p in params}
    for name in given:
        if name not in declared:
            accepted = ", ".join(declared) or "none"
            raise ConfigError(
                f"{owner} has no parameter {name!r}.{suggest(name, list(declared))} "
                f"Accepted: {accepted}"
            )
    values = {}
    for p in params:
        values[p.name] = p.validate(given[p.name], owner) if p.name in given else p.default
    return values
