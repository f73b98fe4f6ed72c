"""What every check of the conformance kit shares: the error a breach raises, and the helpers
that resolve a plugin's declared parameters, call its factory and compare results bit for bit."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from metaopt.errors import ConfigError
from metaopt.params import Param, resolve

Check = Callable[[], None]


class ConformanceError(AssertionError):
    """A plugin breaks metaopt's contract; the message says what was breached and what to fix."""


def run_all(name: str, checks: Mapping[str, Check]) -> None:
    """Run every check of ``name``; one ConformanceError listing each breach, if any."""
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


def check_declared_params(params: Sequence[Param], owner: str) -> None:
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


def check_declares_budget(params: Sequence[Param]) -> None:
    """An optimizer declares the int parameter ``budget`` that generic code gives every one."""
    if not any(p.name == "budget" and p.type is int for p in params):
        raise ConformanceError(
            "it declares no int parameter 'budget'; add metaopt.budget_param() to its params "
            "(metaopt run, metaopt.minimize and create_optimizer set it to the evaluations the "
            "optimizer will be told; one without a schedule accepts it and may ignore it)"
        )


def resolve_given(params: Sequence[Param], given: Mapping[str, Any], owner: str) -> dict[str, Any]:
    """The declared parameters' values with ``given`` over their defaults, as ``--set`` makes
    them; ConformanceError where the kit was given invalid ones."""
    try:
        return resolve(params, given, owner)
    except ConfigError as error:
        raise ConformanceError(f"the parameters given to the kit are invalid: {error}") from None


def check_binds(factory: Callable[..., Any], args: tuple, values: Mapping[str, Any]) -> None:
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


def build(factory: Callable[..., Any], args: tuple, values: Mapping[str, Any], kind: type) -> Any:
    """``factory(*args, **values)``, which must return a ``kind``; ConformanceError otherwise."""
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


def same(a: Any, b: Any) -> bool:
    """Equal, bit for bit for floats, NaN equal to NaN."""
    return bool(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True))
