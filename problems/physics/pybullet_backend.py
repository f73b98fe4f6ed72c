"""Announces the PyBullet physics backend (the `pybullet` plugin).

The engine itself lives in pybullet_engine.py and is imported on first use, so listing plugins
does not load PyBullet.
"""

from __future__ import annotations

from metaopt import hookimpl
from metaopt.physics import BackendInfo, PhysicsBackend, PhysicsSettings, RobotDescription

#: Physics steps per 20 ms control period by default (0.01 s steps). With SOLVER_ITERATIONS
#: the 10 N·m motors converge: a joint held below its limit stays within 0.6° of its target
#: while the robot stands on one leg (4 steps of 50 iterations, the old setting, left 4.4°),
#: at the old cost per control period (docs/nao-walk.md).
DEFAULT_SUBSTEPS = 2
#: Constraint-solver iterations per physics step (PyBullet's default is 50).
SOLVER_ITERATIONS = 200
#: Bullet clamps a contact's friction coefficient (the product of the two bodies') to this
#: (btManifoldResult::calculateCombinedFriction): asking for 20 simulates 10.
MAX_FRICTION = 10.0


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
