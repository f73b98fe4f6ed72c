"""Errors that metaopt reports to the user as one clear line."""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable
from pathlib import Path
from typing import Any, TypeVar


class MetaoptError(Exception):
    """Base class of every error metaopt raises on purpose."""


class ConfigError(MetaoptError):
    """Bad user input: an unknown name, an ill-typed or out-of-range value, bad bounds.

    The message names what was wrong and what is accepted; the CLI prints it and exits with 2.
    """


class StoreError(MetaoptError):
    """The run store cannot be opened or does not hold what was asked for."""


class EvaluationError(MetaoptError):
    """A problem could not evaluate one candidate (NaN, unstable simulation, ...).

    The run loop records the evaluation as failed with this message and goes on.
    """


class RunFailed(MetaoptError):
    """A run stopped without a result: its evaluations all failed (the message gives the first
    error). Not bad command-line input as such, so the CLI exits with 1, not 2."""

    exit_code = 1


class SettingWarning(UserWarning):
    """Settings that run but hardly as meant (a budget smaller than an initial population); the
    CLI prints it as one 'Warning:' line."""


_Item = TypeVar("_Item")


def _itself(item: Any) -> Hashable:
    """An item as once_each compares it: a file by where it resolves to."""
    return item.resolve() if isinstance(item, Path) else item


def once_each(
    items: Iterable[_Item],
    refusal: Callable[[_Item], str],
    key: Callable[[_Item], Hashable] = _itself,
) -> None:
    """ConfigError with ``refusal(item)`` for the first item whose ``key`` was seen before:
    counted twice, it would pass for two independent samples."""
    seen: set[Hashable] = set()
    for item in items:
        found = key(item)
        if found in seen:
            raise ConfigError(refusal(item))
        seen.add(found)
