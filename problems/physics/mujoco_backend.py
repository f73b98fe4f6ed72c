"""Announces the MuJoCo physics backend (the `mujoco` plugin).

The engine itself lives in mujoco_engine.py and is imported on first use, so listing plugins
does not load MuJoCo.
"""

from __future__ import annotations

from metaopt import hookimpl
from metaopt.physics import BackendInfo, PhysicsBackend, PhysicsSettings, RobotDescription

#: Physics steps per 20 ms control period by default (0.00125 s steps): the fewest at which
#: the joint motors (mujoco_engine.KV) neither chatter at their torque limit nor give way
#: much more than a constraint motor (docs/nao-walk.md, "Motors"); 4 steps stand the robot.
DEFAULT_SUBSTEPS = 16
#: MuJoCo's default pyramidal friction cone softens a contact's normal direction as the
#: friction coefficient grows: from mu = 4 the standing NAO sinks and falls (docs/nao-walk.md).
MAX_FRICTION = 3.0


def create(robot: RobotDescription, settings: PhysicsSettings) -> PhysicsBackend:
    """A MuJoCo simulation of robot."""
    from metaopt_problems.physics.mujoco_engine import MujocoBackend

    return MujocoBackend(robot, settings)


@hookimpl
def metaopt_physics_backends() -> list[BackendInfo]:
    """Announce the MuJoCo engine."""
    return [
        BackendInfo(
            name="mujoco",
            summary="MuJoCo: soft contacts, implicit-fast integrator, exact save/restore",
            factory=create,
            default_substeps=DEFAULT_SUBSTEPS,
            max_friction=MAX_FRICTION,
        )
    ]
