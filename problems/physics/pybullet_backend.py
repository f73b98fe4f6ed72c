"""Announces the PyBullet physics backend (the `pybullet` plugin).

The engine itself lives in pybullet_engine.py and is imported on first use, so listing plugins
does not load PyBullet.
"""

from __future__ import annotations

from metaopt import hookimpl
from metaopt.physics import BackendInfo, PhysicsBackend, PhysicsSettings, RobotDescription

#: Physics steps per 20 ms control period by default (0.005 s steps): the fewest at which the
#: NAO stands without jitter (docs/nao-walk.md).
DEFAULT_SUBSTEPS = 4
#: The largest ground friction coefficient offered (PyBullet has no unlimited friction).
MAX_FRICTION = 1000.0


def create(robot: RobotDescription, settings: PhysicsSettings) -> PhysicsBackend:
    """A PyBullet simulation of robot."""
    from metaopt_problems.physics.pybullet_engine import PybulletBackend

    return PybulletBackend(robot, settings)


@hookimpl
def metaopt_physics_backends() -> list[BackendInfo]:
    """Announce the PyBullet engine."""
    return [
        BackendInfo(
            name="pybullet",
            summary="PyBullet (Bullet multibody): constraint motors like ODE's",
            factory=create,
            default_substeps=DEFAULT_SUBSTEPS,
            max_friction=MAX_FRICTION,
        )
    ]
