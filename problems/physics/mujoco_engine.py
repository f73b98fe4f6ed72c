"""MuJoCo physics backend: builds an MJCF model from a RobotDescription and drives it.

Each hinge gets a velocity actuator (force = KV * (command - joint speed), limited to
±max_joint_torque), the nearest MuJoCo has to the ODE hinge motor of rcssserver3d (a constraint
reaching its target speed within the step with at most 10 N·m); how near is measured in
docs/nao-walk.md ("Motors") by benchmarks/motor_model.py. The state (time, qpos, qvel, act,
ctrl, warm start, applied forces) is saved and restored with mj_getState/mj_setState, which
reproduces a run bit for bit. Each foot's normal force is read by a touch sensor after every
physics step and reported as its mean over the control period.
render() draws offscreen with mujoco.Renderer (headless OpenGL: EGL, else OSMesa).
"""

from __future__ import annotations

import ctypes.util
import os
import sys
from typing import Any
from xml.sax.saxutils import quoteattr

# MuJoCo picks its OpenGL platform when first imported; an explicit MUJOCO_GL wins. EGL works
# without a display or GPU through Mesa's software renderer (Debian: libegl1 libgl1-mesa-dri).
# Only an installed library is chosen: MUJOCO_GL=osmesa without libOSMesa breaks the import.
if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ:
    for _platform, _library in (("egl", "EGL"), ("osmesa", "OSMesa")):
        if ctypes.util.find_library(_library):
            os.environ["MUJOCO_GL"] = _platform
            break

import mujoco
import numpy as np

from metaopt.errors import MetaoptError
from metaopt.physics import (
    CAMERA_AZIMUTH,
    CAMERA_DISTANCE,
    CAMERA_ELEVATION,
    CAMERA_FOVY,
    ROBOT_RGBA,
    Body,
    PhysicsBackend,
    PhysicsSettings,
    RobotDescription,
    Shape,
    Vec3,
    format_vector,
    instability_error,
    servo_velocities,
)
from metaopt_problems.physics.mujoco_backend import DEFAULT_SUBSTEPS

#: Velocity-servo gain, N·m per rad/s. MuJoCo integrates the actuator implicitly only while
#: its force is inside the force range; a clamped force acts explicitly for the whole step, so
#: a joint overshoots its target by up to 10 N·m * timestep / inertia and chatters at the limit
#: unless KV * timestep / ARMATURE stays near 2.5 or below. The old KV 20 at 0.005 s steps (5)
#: chattered: the head commanded 3 rad/s alternated 2.4 and 4.9 rad/s, and some joint sat at
#: the limit on 89-94 % of a fast gait's control steps. KV 40 at 0.00125 s steps (2.5) reaches
#: a commanded speed within a control period without chatter and holds a joint twice as stiffly
#: as before; fewer substeps bring the chatter back (docs/nao-walk.md, "Motors").
KV = 40.0
#: Rotor inertia added to every hinge, kg·m² (the server has none). Without it the servo and
#: the tiny mass-carrier spheres (I ~ 5e-6) are unstable (KV >= 200 at 4 substeps) or rock the
#: standing robot by 1-2.5° (KV 5-2000, 4-40 substeps); measured in docs/nao-walk.md.
ARMATURE = 0.02
#: How far each foot's touch site reaches past its geom, m: a soft contact's point lies within
#: half the penetration (millimetres) of the surfaces, so the site holds every contact of the foot.
TOUCH_MARGIN = 0.01
_STATE = mujoco.mjtState.mjSTATE_INTEGRATION
#: The warnings mj_step raises when it finds a non-finite or huge qpos, qvel or qacc; it then
#: resets the data (mj_resetData, which zeroes every counter) and counts the warning again.
_UNSTABLE = [
    int(mujoco.mjtWarning.mjWARN_BADQACC),
    int(mujoco.mjtWarning.mjWARN_BADQVEL),
    int(mujoco.mjtWarning.mjWARN_BADQPOS),
]


def _size(shape: Shape) -> list[float]:
    """MuJoCo's size of a shape: half edges (box), radius (sphere), radius and half the
    cylinder length (capsule); the description gives full lengths. Geoms and sites share it."""
    if shape.kind == "box":
        return [s / 2 for s in shape.size]
    if shape.kind == "sphere":
        return list(shape.size)
    return [shape.size[0], shape.size[1] / 2]


def _geom(body: Body, with_collision: bool) -> str:
    """The geom of body: colliding with the floor (group 0) or a mass carrier drawn only
    (group 1)."""
    shape = body.shape
    collide = 'contype="1" conaffinity="0"' if with_collision else 'contype="0" conaffinity="0"'
    group = 0 if with_collision else 1
    return (
        f'<geom type="{shape.kind}" size="{format_vector(_size(shape))}" {collide} '
        f'group="{group}"/>'
    )


def _touch_site(body: Body) -> str:
    """A site TOUCH_MARGIN larger than body's geom all round, for its touch sensor."""
    size = format_vector(s + TOUCH_MARGIN for s in _size(body.shape))
    return f'<site name={quoteattr("touch_" + body.name)} type="{body.shape.kind}" size="{size}"/>'


def mjcf(robot: RobotDescription, settings: PhysicsSettings) -> str:
    """The MJCF text of robot on a ground plane (generated, never edited by hand)."""
    children: dict[str, list] = {}
    for body in robot.bodies[1:]:
        children.setdefault(body.parent, []).append(body)

    def body_xml(body: Body, parent_center: Vec3) -> str:
        """The MJCF of body and its subtree, placed relative to its parent's centre."""
        pos = [c - p for c, p in zip(body.center, parent_center, strict=True)]
        parts = [f'<body name={quoteattr(body.name)} pos="{format_vector(pos)}">']
        if body.parent is None:
            parts.append('<freejoint name="root"/>')
        else:
            h = robot.hinge_of(body.name)
            anchor = [a - c for a, c in zip(h.anchor, body.center, strict=True)]
            parts.append(
                f'<joint name={quoteattr(h.name)} pos="{format_vector(anchor)}" '
                f'axis="{format_vector(h.axis)}" range="{h.lower:.10g} {h.upper:.10g}"/>'
            )
        parts.append(f'<inertial pos="0 0 0" mass="{body.mass:.10g}" '
                     f'diaginertia="{format_vector(body.inertia)}"/>')  # fmt: skip
        parts.append(_geom(body, body.collides))
        if body.name in robot.contact_bodies:
            parts.append(_touch_site(body))
        parts += [body_xml(child, body.center) for child in children.get(body.name, [])]
        parts.append("</body>")
        return "\n".join(parts)

    root = robot.root
    actuators = "\n".join(
        f'<velocity name={quoteattr(h.name)} joint={quoteattr(h.name)} kv="{KV}" '
        f'forcerange="{-settings.max_joint_torque} {settings.max_joint_torque}"/>'
        for h in robot.hinges
    )
    touch = "\n".join(
        f"<touch name={quoteattr('touch_' + name)} site={quoteattr('touch_' + name)}/>"
        for name in robot.contact_bodies
    )
    mu = settings.friction
    return f"""<mujoco model={quoteattr(robot.name)}>
<compiler angle="radian" autolimits="true"/>
<option timestep="{settings.timestep(DEFAULT_SUBSTEPS):.10g}" integrator="implicitfast"
        gravity="0 0 -9.81"/>
<default><joint armature="{ARMATURE}" limited="true"/>
<geom friction="{mu} 0.005 0.0001" rgba="{format_vector(ROBOT_RGBA)}"/></default>
<visual><headlight ambient="0.6 0.6 0.6" diffuse="0.5 0.5 0.5" specular="0 0 0"/></visual>
<asset>
<texture name="sky" type="skybox" builtin="gradient" rgb1="1 1 1" rgb2="0.85 0.9 1"
         width="64" height="64"/>
<texture name="grid" type="2d" builtin="checker" rgb1="0.94 0.94 0.94" rgb2="0.64 0.73 0.95"
         width="64" height="64"/>
<material name="grid" texture="grid" texrepeat="2 2" texuniform="true"/>
</asset>
<worldbody>
<geom name="floor" type="plane" size="0 0 1" contype="0" conaffinity="1" material="grid"
      rgba="1 1 1 1"/>
{body_xml(root, (0.0, 0.0, -robot.start_height))}
</worldbody>
<actuator>
{actuators}
</actuator>
<sensor>
{touch}
</sensor>
</mujoco>"""


class MujocoBackend(PhysicsBackend):
    """The robot in MuJoCo; velocity commands are written to data.ctrl once per control period."""

    restores_exactly = True

    def __init__(self, robot: RobotDescription, settings: PhysicsSettings) -> None:
        """Compile the robot's MJCF, keep live views of the data it reads, and reset."""
        super().__init__(robot, settings)
        self.model = mujoco.MjModel.from_xml_string(mjcf(robot, settings))
        self.data = mujoco.MjData(self.model)
        self._substeps = settings.substeps or DEFAULT_SUBSTEPS
        n = len(robot.hinges)
        self._angles = self.data.qpos[7 : 7 + n]
        self._angles_view = self._angles.view()
        self._angles_view.flags.writeable = False
        self._command = np.zeros(n)
        self._root_position = self.data.qpos[0:3]
        self._root_quaternion = self.data.qpos[3:7]
        self._rotation = np.zeros(9)
        #: mj_step's warning counters (a live view), of which _UNSTABLE flag an instability
        self._warnings = self.data.warning.number
        #: each foot's touch sensor in sensordata (the sensors are the feet's, in order)
        self._touch = self.data.sensordata[: len(robot.contact_bodies)]
        #: the feet's normal forces, the mean over the last control period's physics steps
        self._contact_mean = np.zeros(len(robot.contact_bodies))
        self._renderer: mujoco.Renderer | None = None
        self._camera = mujoco.MjvCamera()
        self._camera.distance = CAMERA_DISTANCE
        self._camera.azimuth = CAMERA_AZIMUTH
        self._camera.elevation = CAMERA_ELEVATION
        self.model.vis.global_.fovy = CAMERA_FOVY
        self.reset()

    def reset(self) -> None:
        """The rest pose at t = 0; mj_resetData also zeroes the warning counters."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[2] = self.robot.start_height
        self._angles[:] = self.robot.rest_angles
        self._contact_mean[:] = 0.0
        self.set_ground_friction(self.settings.friction)

    def step(self, joint_targets: np.ndarray) -> None:
        """One control period; raises EvaluationError when mj_step flags a bad qpos, qvel or
        qacc (counted from zero each period: its automatic reset leaves a counter at 1)."""
        servo_velocities(joint_targets, self._angles, self.settings, self._command)
        self.data.ctrl[:] = self._command
        warnings = self._warnings
        warnings[_UNSTABLE] = 0
        start = self.data.time  # the automatic reset puts data.time back to 0
        mean = self._contact_mean
        mean[:] = 0.0
        for _ in range(self._substeps):
            mujoco.mj_step(self.model, self.data)
            mean += self._touch
        mean /= self._substeps
        if warnings[_UNSTABLE].any():
            raise instability_error("MuJoCo", start + self.settings.control_period)

    def joint_angles(self) -> np.ndarray:
        return self._angles_view

    # The root is read from qpos, not xpos/xmat: after mj_step those still hold the pose from
    # before the last integration, so a restored state would read differently.
    def root_position(self) -> np.ndarray:
        return self._root_position

    def root_rotation(self) -> np.ndarray:
        mujoco.mju_quat2Mat(self._rotation, self._root_quaternion)
        return self._rotation.reshape(3, 3)

    def body_position(self, name: str) -> np.ndarray:
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.xpos[self.model.body(name).id].copy()

    def contact_forces(self) -> np.ndarray:
        return self._contact_mean.copy()

    def time(self) -> float:
        return self.data.time

    def joint_velocities(self) -> np.ndarray:
        return self.data.qvel[6 : 6 + len(self.robot.hinges)].copy()

    def joint_torques(self) -> np.ndarray:
        # One actuator per hinge, in joint order; the force after the force-range clamp.
        return self.data.actuator_force.copy()

    def body_mass(self, name: str) -> float:
        return float(self.model.body_mass[self.model.body(name).id])

    def body_inertia(self, name: str) -> Vec3:
        moments = self.model.body_inertia[self.model.body(name).id]
        return (float(moments[0]), float(moments[1]), float(moments[2]))

    def ground_friction(self) -> float:
        """The sliding coefficient of the robot's ground contacts now; without any, the one a
        contact of a foot would get (MuJoCo takes the larger of the two geoms' coefficients)."""
        if self.data.ncon:
            return float(max(self.data.contact[i].friction[0] for i in range(self.data.ncon)))
        foot = self.model.body(self.robot.contact_bodies[0]).id
        geoms = self.model.geom_bodyid == foot
        floor = self.model.geom("floor").id
        return float(max(self.model.geom_friction[geoms, 0].max(),
                         self.model.geom_friction[floor, 0]))  # fmt: skip

    def apply_force(self, body: str, force: Vec3) -> None:
        # xfrc_applied acts at the body's centre of mass and is part of mjSTATE_INTEGRATION.
        self.data.xfrc_applied[self.model.body(body).id, :3] = force

    # A contact takes the larger of its two geoms' coefficients, and the robot's geoms touch
    # only the floor, so every geom gets mu.
    def set_ground_friction(self, mu: float) -> None:
        self.model.geom_friction[:, 0] = mu
        mujoco.mj_forward(self.model, self.data)  # the contacts now carry the new coefficient

    def push_root(self, velocity: Vec3) -> None:
        self.data.qvel[0:3] += velocity  # the free joint's linear velocity is in world axes
        mujoco.mj_forward(self.model, self.data)

    def save_state(self) -> Any:
        state = np.empty(mujoco.mj_stateSize(self.model, _STATE))
        mujoco.mj_getState(self.model, self.data, state, _STATE)
        return state, self._contact_mean.copy()

    def restore_state(self, state: Any) -> None:
        """Back to a saved state, with no instability counted (mj_setState keeps the warning
        counters, which are not part of the state)."""
        integration, self._contact_mean[:] = state
        mujoco.mj_setState(self.model, self.data, integration, _STATE)
        self._warnings[_UNSTABLE] = 0
        mujoco.mj_forward(self.model, self.data)

    def render(self, width: int, height: int, camera_target: Vec3) -> np.ndarray:
        renderer = self._renderer
        if renderer is None or (renderer.width, renderer.height) != (width, height):
            renderer = self._open_renderer(width, height)
        self._camera.lookat[:] = camera_target
        mujoco.mj_kinematics(self.model, self.data)  # poses from qpos (mj_step leaves xpos stale)
        renderer.update_scene(self.data, self._camera)
        return renderer.render()

    def _open_renderer(self, width: int, height: int) -> mujoco.Renderer:
        """An offscreen renderer of this size, shadows and reflections off (speed)."""
        self._close_renderer()
        globals_ = self.model.vis.global_
        globals_.offwidth, globals_.offheight = (
            max(globals_.offwidth, width),
            max(globals_.offheight, height),
        )
        try:
            renderer = mujoco.Renderer(self.model, height, width)
        except Exception as error:  # no headless OpenGL: one clear line, not a traceback
            platform = os.environ.get("MUJOCO_GL", "unset")
            raise MetaoptError(
                f"MuJoCo cannot render offscreen (MUJOCO_GL={platform}: {error}); install "
                "Mesa's EGL (Debian: apt-get install libegl1 libgl1-mesa-dri) or render with "
                "--backend pybullet"
            ) from error
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        self._renderer = renderer
        return renderer

    def _close_renderer(self) -> None:
        """Free the offscreen renderer and its OpenGL context, if one is open."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def close(self) -> None:
        self._close_renderer()
