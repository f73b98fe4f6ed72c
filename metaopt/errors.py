"""Errors that metaopt reports to the user as one clear line."""

from __future__ import annotations


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
