"""Reading ``--set NAME=VALUE`` options into optimizer and problem parameters."""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from typing import Any

from metaopt.errors import ConfigError, SettingWarning
from metaopt.optimizer import OptimizerInfo
from metaopt.params import Param, suggest
from metaopt.problem import ProblemInfo

_OPTIMIZER_PREFIXES = ("optimizer.", "o.")
_PROBLEM_PREFIXES = ("problem.", "p.")


def split_settings(
    pairs: Iterable[str], optimizer: OptimizerInfo, problem: ProblemInfo
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Parse NAME=VALUE strings into (optimizer params, problem params).

    A bare NAME goes to whichever plugin declares it; a name both declare must be qualified as
    ``optimizer.NAME`` or ``problem.NAME`` (or ``<plugin name>.NAME``).
    """
    optimizer_params: dict[str, Any] = {}
    problem_params: dict[str, Any] = {}
    optimizer_decl = {p.name: p for p in optimizer.params}
    problem_decl = {p.name: p for p in problem.params}
    given: dict[tuple[str, str], str] = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ConfigError(f"--set expects NAME=VALUE, got {pair!r} (e.g. --set hmcr=0.95)")
        target = _target(name, optimizer, problem, optimizer_decl, problem_decl)
        kind, bare = target
        declared, params, owner = (
            (optimizer_decl, optimizer_params, f"optimizer {optimizer.name!r}")
            if kind == "optimizer"
            else (problem_decl, problem_params, f"problem {problem.name!r}")
        )
        param: Param = declared[bare]
        params[bare] = param.parse(text.strip(), owner)  # a bad value is refused, unwarned
        _once(given, target, name, text.strip())
    return optimizer_params, problem_params


def parse_problem_settings(pairs: Iterable[str], problem: ProblemInfo) -> dict[str, Any]:
    """Parse NAME=VALUE strings into problem parameters only (for replays)."""
    declared = {p.name: p for p in problem.params}
    params: dict[str, Any] = {}
    given: dict[tuple[str, str], str] = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        if not sep or not name.strip():
            raise ConfigError(
                f"--set expects NAME=VALUE, got {pair!r} (e.g. --set backend=pybullet)"
            )
        written = name = name.strip()
        for prefix in (*_PROBLEM_PREFIXES, f"{problem.name}."):
            name = name.strip().removeprefix(prefix)
        _must_declare("problem", problem.name, name, declared)
        params[name] = declared[name].parse(text.strip(), f"problem {problem.name!r}")
        _once(given, ("problem", name), written, text.strip())
    return params


def _once(given: dict[tuple[str, str], str], target: tuple[str, str], name: str, text: str) -> None:
    """Note a parameter's value; one set before is replaced (the last value is used, so a
    script's defaults can be overridden by a later --set) with a SettingWarning saying so: a
    command that runs one setting takes one value (only metaopt compare makes a grid)."""
    if target in given:
        warnings.warn(
            f"--set {name} is given twice ({given[target]}, then {text}): the last, {text}, is "
            "used (a grid over values is metaopt compare's)",
            SettingWarning,
            stacklevel=3,
        )
    given[target] = text


def _target(
    name: str,
    optimizer: OptimizerInfo,
    problem: ProblemInfo,
    optimizer_decl: dict[str, Param],
    problem_decl: dict[str, Param],
) -> tuple[str, str]:
    for prefix in (*_OPTIMIZER_PREFIXES, f"{optimizer.name}."):
        if name.startswith(prefix):
            return _must_declare("optimizer", optimizer.name, name[len(prefix) :], optimizer_decl)
    for prefix in (*_PROBLEM_PREFIXES, f"{problem.name}."):
        if name.startswith(prefix):
            return _must_declare("problem", problem.name, name[len(prefix) :], problem_decl)
    in_optimizer, in_problem = name in optimizer_decl, name in problem_decl
    if in_optimizer and in_problem:
        raise ConfigError(
            f"both optimizer {optimizer.name!r} and problem {problem.name!r} have a parameter "
            f"{name!r}; write --set optimizer.{name}=... or --set problem.{name}=..."
        )
    if in_optimizer:
        return "optimizer", name
    if in_problem:
        return "problem", name
    everything = [*optimizer_decl, *problem_decl]
    raise ConfigError(
        f"neither optimizer {optimizer.name!r} nor problem {problem.name!r} has a parameter "
        f"{name!r}.{suggest(name, everything)} Optimizer parameters: "
        f"{', '.join(optimizer_decl) or 'none'}; problem parameters: "
        f"{', '.join(problem_decl) or 'none'}"
    )


def _must_declare(kind: str, plugin: str, name: str, declared: dict[str, Param]) -> tuple[str, str]:
    if name not in declared:
        raise ConfigError(
            f"{kind} {plugin!r} has no parameter {name!r}.{suggest(name, list(declared))} "
            f"Accepted: {', '.join(declared) or 'none'}"
        )
    return kind, name
