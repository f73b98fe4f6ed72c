"""The engine checks: the engine agreement suite (metaopt.physics.agreement) run as conformance
checks, each measuring a fresh simulation of the NAO on the engine."""

from __future__ import annotations

from functools import partial

from metaopt.physics import BackendInfo
from metaopt.physics.agreement import MEASUREMENTS, measure
from metaopt.testing.common import Check, ConformanceError, run_all


def check_engine(backend: str | BackendInfo) -> None:
    """Run every engine agreement check; raise ConformanceError listing each breach."""
    run_all(_backend_name(backend), engine_checks(backend))


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
