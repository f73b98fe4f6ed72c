"""PyBullet physics backend: builds a URDF from a RobotDescription and drives it.

Each hinge is driven with VELOCITY_CONTROL and a force limit, PyBullet's analogue of the ODE
hinge motor of rcssserver3d. A control period is ``substeps`` stepSimulation calls of
control_period / substeps each, not one call with numSubSteps: PyBullet sizes a motor's impulse
limit (and divides its reported torques and contact forces) by the time step it was given, so
with numSubSteps = 4 a 10 N·m motor held 40 N·m. Each foot's normal force is read after every
stepSimulation and reported as its mean over the control period. Every instance has its own
DIRECT client.
render() uses PyBullet's built-in software renderer (TinyRenderer: no OpenGL needed).
"""

from __future__ import annotations

import os
import sys
import tempfile
from types import ModuleType
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

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
    Vec3,
    check_root_height,
    format_vector,
    servo_velocities,
)
from metaopt_problems.physics.pybullet_backend import (
    DEFAULT_SUBSTEPS,
    MAX_FRICTION,
    SOLVER_ITERATIONS,
)


def _import_quietly() -> ModuleType:
    """Import PyBullet without the 'pybullet build time: ...' line its C code prints on the
    process's standard output at import: file descriptors 1 and 2 point at /dev/null meanwhile
    (Python's buffers are flushed first, so nothing of ours is lost)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            import pybullet

            return pybullet
    finally:
        for descriptor, copy in zip((1, 2), saved):
            os.dup2(copy, descriptor)
            os.close(copy)


pybullet = _import_quietly()


def _geometry(body: Body) -> str:
    """The URDF geometry of body's shape (URDF takes full box edges and capsule lengths)."""
    shape = body.shape
    if shape.kind == "box":
        return f'<box size="{format_vector(shape.size)}"/>'
    if shape.kind == "sphere":
        return f'<sphere radius="{shape.size[0]:.10g}"/>'
    return f'<capsule radius="{shape.size[0]:.10g}" length="{shape.size[1]:.10g}"/>'


def urdf(robot: RobotDescription) -> str:
    """The URDF text of robot (generated, never edited by hand).

    Each link's frame sits on the hinge that carries it (the root's at its centre), axes
    parallel to the world's in the construction pose.
    """
    origin = {robot.root.name: robot.root.center}
    for h in robot.hinges:
        origin[h.child] = h.anchor
    parts = [f"<robot name={quoteattr(robot.name)}>"]
    for body in robot.bodies:
        at = format_vector(c - o for c, o in zip(body.center, origin[body.name], strict=True))
        ixx, iyy, izz = body.inertia
        parts.append(
            f'<link name={quoteattr(body.name)}><inertial><origin xyz="{at}"/>'
            f'<mass value="{body.mass:.10g}"/><inertia ixx="{ixx:.10g}" iyy="{iyy:.10g}" '
            f'izz="{izz:.10g}" ixy="0" ixz="0" iyz="0"/></inertial>'
        )
        if body.collides:
            parts.append(
                f'<collision><origin xyz="{at}"/><geometry>{_geometry(body)}</geometry></collision>'
            )
        parts.append("</link>")
    for h in robot.hinges:
        offset = format_vector(a - o for a, o in zip(h.anchor, origin[h.parent], strict=True))
        parts.append(
            f'<joint name={quoteattr(h.name)} type="revolute">'
            f"<parent link={quoteattr(h.parent)}/><child link={quoteattr(h.child)}/>"
            f'<origin xyz="{offset}"/><axis xyz="{format_vector(h.axis)}"/>'
            f'<limit lower="{h.lower:.10g}" upper="{h.upper:.10g}" effort="10" velocity="10"/>'
            "</joint>"
        )
    parts.append("</robot>")
    return "\n".join(parts)


class PybulletBackend(PhysicsBackend):
    """The robot in its own PyBullet DIRECT client."""

    restores_exactly = True

    def __init__(self, robot: RobotDescription, settings: PhysicsSettings) -> None:
        """Connect a DIRECT client and build the robot in it; a failure on the way
        disconnects the client again (and re-raises)."""
        super().__init__(robot, settings)
        #: the ids of the Bullet states save_state made, freed by close()
        self._saved_states: list[int] = []
        self._client: int | None = pybullet.connect(pybullet.DIRECT)
        self._call = dict(physicsClientId=self._client)
        try:
            self._build(robot, settings)
        except BaseException:
            self.close()
            raise

    def _build(self, robot: RobotDescription, settings: PhysicsSettings) -> None:
        """The world and the robot in the connected client, then reset."""
        self._substeps = settings.substeps or DEFAULT_SUBSTEPS
        pybullet.setGravity(0, 0, -9.81, **self._call)
        pybullet.setTimeStep(settings.timestep(DEFAULT_SUBSTEPS), **self._call)
        pybullet.setPhysicsEngineParameter(numSolverIterations=SOLVER_ITERATIONS, **self._call)
        plane = pybullet.createCollisionShape(pybullet.GEOM_PLANE, **self._call)
        self._plane = pybullet.createMultiBody(0, plane, **self._call)
        with tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False) as file:
            file.write(urdf(robot))
        try:
            self._robot = pybullet.loadURDF(
                file.name, flags=pybullet.URDF_USE_INERTIA_FROM_FILE, **self._call
            )
        finally:
            os.unlink(file.name)
        link_of = {robot.root.name: -1}
        for index in range(pybullet.getNumJoints(self._robot, **self._call)):
            info = pybullet.getJointInfo(self._robot, index, **self._call)
            link_of[info[12].decode()] = index
        self._links = link_of
        self._joints = [link_of[h.child] for h in robot.hinges]
        self._feet = [link_of[name] for name in robot.contact_bodies]
        # PyBullet multiplies the two bodies' coefficients: the robot's are 1, so the
        # ground's (set_ground_friction) is the pair's. Friction gets its own call: given
        # together with the damping, it takes for the base only (the links kept 0.5).
        for link in link_of.values():
            pybullet.changeDynamics(self._robot, link, lateralFriction=1.0, **self._call)
            pybullet.changeDynamics(
                self._robot, link, linearDamping=0.0, angularDamping=0.0, **self._call
            )
            pybullet.changeVisualShape(self._robot, link, rgbaColor=ROBOT_RGBA, **self._call)
        n = len(robot.hinges)
        self._angles = np.zeros(n)
        self._angles_view = self._angles.view()  # what joint_angles gives: read-only, live
        self._angles_view.flags.writeable = False
        self._command = np.zeros(n)
        self._forces = [settings.max_joint_torque] * n
        self._steps = 0
        self._pose: tuple = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
        self._velocities = np.zeros(n)
        self._torques = np.zeros(n)
        #: External forces by link, re-applied before every stepSimulation (PyBullet clears
        #: them after each call).
        self._external: dict[int, Vec3] = {}
        self.reset()

    def reset(self) -> None:
        call = self._call
        pybullet.resetBasePositionAndOrientation(
            self._robot, (0.0, 0.0, self.robot.start_height), (0.0, 0.0, 0.0, 1.0), **call
        )
        pybullet.resetBaseVelocity(self._robot, (0, 0, 0), (0, 0, 0), **call)
        for joint, rest in zip(self._joints, self.robot.rest_angles, strict=True):
            pybullet.resetJointState(self._robot, joint, float(rest), 0.0, **call)
        self.set_ground_friction(self.settings.friction)
        self._steps = 0
        self._external = {}
        self._contact_mean = np.zeros(len(self._feet))
        self._read()

    def _read(self) -> None:
        """Refresh the cached joint angles and root pose after a change of state."""
        states = pybullet.getJointStates(self._robot, self._joints, **self._call)
        self._angles[:] = [s[0] for s in states]
        self._velocities[:] = [s[1] for s in states]
        self._torques[:] = [s[3] for s in states]
        self._pose = pybullet.getBasePositionAndOrientation(self._robot, **self._call)

    def step(self, joint_targets: np.ndarray) -> None:
        """One control period of substeps stepSimulation calls; raises EvaluationError when
        the root has left the finite world (Bullet flags nothing itself)."""
        servo_velocities(joint_targets, self._angles, self.settings, self._command)
        pybullet.setJointMotorControlArray(
            self._robot, self._joints, pybullet.VELOCITY_CONTROL,
            targetVelocities=self._command.tolist(), forces=self._forces, **self._call,
        )  # fmt: skip
        total = np.zeros(len(self._feet))
        for _ in range(self._substeps):
            for link, force in self._external.items():
                pybullet.applyExternalForce(
                    self._robot, link, force, self._center_of_mass(link), pybullet.WORLD_FRAME,
                    **self._call,
                )  # fmt: skip
            pybullet.stepSimulation(**self._call)
            total += self._contact_now()
        self._contact_mean = total / self._substeps
        self._steps += 1
        self._read()
        check_root_height("PyBullet", self._pose[0][2], self.time())

    def joint_angles(self) -> np.ndarray:
        """The measured angles as a live read-only view (the servo reads the buffer behind it)."""
        return self._angles_view

    def root_position(self) -> np.ndarray:
        return np.asarray(self._pose[0])

    def root_rotation(self) -> np.ndarray:
        return np.reshape(pybullet.getMatrixFromQuaternion(self._pose[1]), (3, 3))

    def body_position(self, name: str) -> np.ndarray:
        link = self._links[name]
        if link < 0:
            return self.root_position()
        return np.asarray(pybullet.getLinkState(self._robot, link, **self._call)[0])

    def contact_forces(self) -> np.ndarray:
        return self._contact_mean.copy()

    def _contact_now(self) -> np.ndarray:
        """Each foot's normal force in the last stepSimulation."""
        return np.array(
            [
                sum(c[9] for c in pybullet.getContactPoints(
                    self._robot, self._plane, foot, -1, **self._call))
                for foot in self._feet
            ]
        )  # fmt: skip

    def time(self) -> float:
        return self._steps * self.settings.control_period

    def joint_velocities(self) -> np.ndarray:
        return self._velocities.copy()

    def joint_torques(self) -> np.ndarray:
        # appliedJointMotorTorque: the motor's impulse in the last step over its length.
        return self._torques.copy()

    def body_mass(self, name: str) -> float:
        return float(pybullet.getDynamicsInfo(self._robot, self._links[name], **self._call)[0])

    def body_inertia(self, name: str) -> Vec3:
        info = pybullet.getDynamicsInfo(self._robot, self._links[name], **self._call)
        return (float(info[2][0]), float(info[2][1]), float(info[2][2]))

    def ground_friction(self) -> float:
        """The coefficient of a foot's ground contact: Bullet multiplies the two bodies'
        coefficients and clamps the product to MAX_FRICTION."""
        ground = pybullet.getDynamicsInfo(self._plane, -1, **self._call)[1]
        foot = self._links[self.robot.contact_bodies[0]]
        own = pybullet.getDynamicsInfo(self._robot, foot, **self._call)[1]
        return float(min(ground * own, MAX_FRICTION))

    def apply_force(self, body: str, force: Vec3) -> None:
        link = self._links[body]
        if any(force):
            self._external[link] = tuple(float(f) for f in force)
        else:
            self._external.pop(link, None)

    def _center_of_mass(self, link: int) -> Vec3:
        """World position of a link's centre of mass (the base's frame is at its centre)."""
        if link < 0:
            return pybullet.getBasePositionAndOrientation(self._robot, **self._call)[0]
        return pybullet.getLinkState(self._robot, link, **self._call)[0]

    def set_ground_friction(self, mu: float) -> None:
        pybullet.changeDynamics(self._plane, -1, lateralFriction=mu, **self._call)

    def push_root(self, velocity: Vec3) -> None:
        linear, angular = pybullet.getBaseVelocity(self._robot, **self._call)
        pushed = [v + dv for v, dv in zip(linear, velocity, strict=True)]
        pybullet.resetBaseVelocity(self._robot, pushed, angular, **self._call)

    def save_state(self) -> Any:
        """A snapshot; its Bullet in-memory state lives until close() (restorable until then)."""
        state_id = pybullet.saveState(**self._call)
        self._saved_states.append(state_id)
        return state_id, self._steps, dict(self._external), self._contact_mean.copy()

    def restore_state(self, state: Any) -> None:
        state_id, self._steps, external, contact_mean = state
        self._contact_mean = contact_mean.copy()
        self._external = dict(external)
        pybullet.restoreState(stateId=state_id, **self._call)
        self._read()

    def render(self, width: int, height: int, camera_target: Vec3) -> np.ndarray:
        # PyBullet's yaw 0 looks along +y where MuJoCo's azimuth 0 looks along +x.
        view = pybullet.computeViewMatrixFromYawPitchRoll(
            camera_target, CAMERA_DISTANCE, CAMERA_AZIMUTH - 90.0, CAMERA_ELEVATION, 0.0, 2
        )
        projection = pybullet.computeProjectionMatrixFOV(CAMERA_FOVY, width / height, 0.05, 50.0)
        _, _, rgba, _, _ = pybullet.getCameraImage(
            width, height, view, projection, renderer=pybullet.ER_TINY_RENDERER,
            flags=pybullet.ER_NO_SEGMENTATION_MASK, **self._call,
        )  # fmt: skip
        return np.reshape(rgba, (height, width, 4))[:, :, :3].astype(np.uint8)

    def close(self) -> None:
        """Free the saved states and disconnect the client, once: PyBullet reuses a freed
        client id, so neither a second close nor a later call may reach another backend's."""
        client, self._client = self._client, None
        self._call["physicsClientId"] = -1  # PyBullet: "Not connected to physics server"
        if client is None or not pybullet.isConnected(physicsClientId=client):
            return
        for state_id in self._saved_states:
            pybullet.removeState(state_id, physicsClientId=client)
        self._saved_states.clear()
        pybullet.disconnect(physicsClientId=client)

    def __del__(self) -> None:
        """Disconnect a client nobody closed (the ODE backend frees its world alike)."""
        if getattr(self, "_client", None) is not None:
            self.close()
