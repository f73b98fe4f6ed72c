"""Every installed physics engine passes the engine agreement suite (metaopt.testing), one test
per check: what it simulates, measured from it, agrees with physics and the robot's description.

Generated from the plugin registry, so a newly installed engine is checked without touching
this file; an engine whose library is missing on this machine is skipped with the reason.
"""

from __future__ import annotations

import pytest

from metaopt.engine_agreement import engine
from metaopt.errors import MetaoptError
from metaopt.plugins import registry
from metaopt.testing import ConformanceError, engine_checks

ENGINES = list(registry().physics_backends)


def _missing_library(name: str) -> str | None:
    """Why the engine cannot run here, or None when it can."""
    try:
        with engine(name):
            return None
    except (ImportError, OSError, MetaoptError) as error:
        return f"{name} cannot run here: {error}"


@pytest.mark.parametrize(
    ("name", "check"),
    [pytest.param(name, check, id=f"{name}-{check}") for name in ENGINES
     for check in engine_checks(name)],
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
