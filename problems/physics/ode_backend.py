"""Announces the ODE physics backend (the `ode` plugin): rcssserver3d's own engine.

The engine lives in ode_engine.py and is imported on first use. Announcing it only looks for
the ODE library (Debian: libode8); where it is missing the backend is listed as unavailable
with the command that installs it.
"""

from __future__ import annotations

import math

from metaopt import hookimpl
from metaopt.physics import BackendInfo, PhysicsBackend, PhysicsSettings, RobotDescription

#: One dWorldStep per 20 ms control period, as the server steps ODE.
DEFAULT_SUBSTEPS = 1


def create(robot: RobotDescription, settings: PhysicsSettings) -> PhysicsBackend:
    """An ODE simulation of robot, configured as rcssserver3d 0.6.x configures ODE."""
    from metaopt_problems.physics.ode_engine import OdeBackend

    return OdeBackend(robot, settings)


def _missing() -> str:
    """Why ODE cannot run here, with the command that fixes it ('' when it can)."""
    from metaopt_problems.physics.ode_binding import OdeUnavailable, ode

    try:
        ode()
    except OdeUnavailable as error:
        return str(error)
    return ""


def _library_file() -> str:
    """The ODE library file that runs (ode_binding.library_file)."""
    from metaopt_problems.physics.ode_binding import library_file

    return library_file()


@hookimpl
def metaopt_physics_backends() -> list[BackendInfo]:
    """Announce the ODE engine."""
    return [
        BackendInfo(
            name="ode",
            summary="ODE as rcssserver3d runs it: one 20 ms dWorldStep, infinite friction "
            "with force-dependent slip, exact save/restore",
            factory=create,
            default_substeps=DEFAULT_SUBSTEPS,
            default_friction=math.inf,
            unavailable=_missing(),
            version=_library_file,
        )
    ]
