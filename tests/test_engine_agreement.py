"""Every installed physics engine passes the engine agreement suite (metaopt.testing), one test
per check: what it simulates, measured from it, agrees with physics and the robot's description.

Generated from the plugin registry, so a newly installed engine is checked without touching
this file; an engine whose library is missing on this machine is skipped with the reason.
"""

from __future__ import annotations

import pytest

from metaopt.plugins import registry
from metaopt.testing import ConformanceError, engine_checks

ENGINES = list(registry().physics_backends)
#: Measured disagreements an engine is known to have, with why (strict: fixed ones show up).
KNOWN_DISAGREEMENTS = {
    ("ode", "motor_response"): "the 400 N push on the 0.2 kg forearm also loads the shoulder "
    "roll far over its 10 N·m motor, and within ODE's one 20 ms step the arm spins past its "
    "stops (shoulder roll -124°, 209 rad/s), so the elbow reads 3.56 N·m that step; at "
    "substeps=2 it reads 10.0 (docs/nao-walk.md, ODE)",
}


def _marks(name: str, check: str) -> list:
    reason = KNOWN_DISAGREEMENTS.get((name, check))
    return [pytest.mark.xfail(strict=True, reason=reason)] if reason else []


def _missing_library(name: str) -> str | None:
    """Why the engine cannot run here (its plugin's BackendInfo.unavailable), or None when it
    can: read from the registry, not by building an engine before every check."""
    reason = registry().physics_backends[name].unavailable
    return f"{name} cannot run here: {reason}" if reason else None


@pytest.mark.parametrize(
    ("name", "check"),
    [pytest.param(name, check, id=f"{name}-{check}", marks=_marks(name, check))
     for name in ENGINES for check in engine_checks(name)],
)  # fmt: skip
def test_engine_agrees(name: str, check: str) -> None:
    reason = _missing_library(name)
    if reason:
        pytest.skip(reason)
    engine_checks(name)[check]()


def test_a_breach_names_the_figure_and_its_tolerance() -> None:
    """An engine whose contacts ignore the friction it was given is caught."""
    from metaopt.physics import BackendInfo

    mujoco = registry().physics_backend("mujoco")

    def slippery(robot, settings):
        sim = mujoco.factory(robot, settings)
        sim.model.geom_friction[:, 0] = 0.5
        sim.set_ground_friction = lambda mu: None  # ignores what it is given
        return sim

    with pytest.raises(ConformanceError, match=r"ground friction read back: measured 0\.5"):
        engine_checks(BackendInfo("slippery", "test", slippery))["ground_friction"]()
