"""ODE physics backend, configured as rcssserver3d 0.6.x configures ODE (nao-model.md §3, §5).

One dWorldStep (the exact LCP step) per control period, world CFM 1e-5 and ERP 0.2, contact
surface layer 1 mm, at most 4 contacts per robot geom and the ground; robot-ground contacts
with friction mu (the server's: infinite) and force-dependent slip, soft ERP 0.4 and CFM 1e-4,
no bounce; robot parts never collide with each other; drag -0.01 v and -0.01 w on every body
before each step; every joint an ODE hinge with the server's motor and stop parameters.
Deviation: auto-disable stays off (a disabled body's state is not part of what save_state can
restore, and the walk never rests). The state (every body's pose and velocities, motor targets,
applied forces, time) is saved and restored bit for bit: through ODE's setters, the quaternion
and rotation matrix then written back as saved (the setter renormalises).
ODE cannot draw: render() shows ODE's pose through the MuJoCo model of the same robot.
"""

from __future__ import annotations

import ctypes
import dataclasses
import math
from typing import Any

import numpy as np

from metaopt.physics import (
    PhysicsBackend,
    PhysicsSettings,
    RobotDescription,
    Shape,
    Vec3,
    check_root_height,
    instability_error,
    servo_velocities,
)
from metaopt_problems.physics.ode_backend import DEFAULT_SUBSTEPS
from metaopt_problems.physics.ode_binding import (
    ALLOCATE_COLLISION_DATA,
    CONTACT_APPROX1,
    CONTACT_SLIP1,
    CONTACT_SLIP2,
    CONTACT_SOFT_CFM,
    CONTACT_SOFT_ERP,
    PARAM_BOUNCE,
    PARAM_CFM,
    PARAM_FMAX,
    PARAM_FUDGE_FACTOR,
    PARAM_HI_STOP,
    PARAM_LO_STOP,
    PARAM_STOP_CFM,
    PARAM_STOP_ERP,
    PARAM_VEL,
    Contact,
    ContactGeom,
    JointFeedback,
    Mass,
    ode,
)

GRAVITY = -9.81
WORLD_CFM = 1e-5
WORLD_ERP = 0.2  # not set by the server: ODE's default
SURFACE_LAYER = 0.001
MAX_CONTACTS = 4  # per colliding geom pair
#: Robot-ground contact softness: the average of the robot's (0.6) and the ground's (0.2)
#: soft ERP, and the robot's soft CFM (the ground's is never switched on).
SOFT_ERP = 0.4
SOFT_CFM = 1e-4
#: Drag on every robot body, N per m/s and N·m per rad/s (dragcontroller.rsg).
DRAG = 0.01
#: The hinge template every joint is built from (nao-model.md §3).
JOINT_CFM = 1e-8
STOP_ERP = 0.8
STOP_CFM = 1e-8
FUDGE_FACTOR = 1e-5
STOP_BOUNCE = 1.0


def _quaternion(axis: Vec3, angle: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation by angle about axis."""
    half = 0.5 * angle
    return np.array([math.cos(half), *(math.sin(half) * np.asarray(axis, float))])


def _multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion product a * b (w, x, y, z)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])  # fmt: skip


def _matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def rest_pose(robot: RobotDescription) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each body's centre and orientation quaternion with every joint at its rest angle and the
    root upright at start_height (forward kinematics over the hinge tree)."""
    root = robot.root
    start = np.add(root.center, (0.0, 0.0, robot.start_height))
    pose = {root.name: (start, np.array([1.0, 0.0, 0.0, 0.0]))}
    for body in robot.bodies[1:]:
        hinge = robot.hinge_of(body.name)
        parent = robot.body(body.parent)
        p_position, p_quaternion = pose[parent.name]
        quaternion = _multiply(p_quaternion, _quaternion(hinge.axis, hinge.rest))
        anchor = p_position + _matrix(p_quaternion) @ np.subtract(hinge.anchor, parent.center)
        position = anchor + _matrix(quaternion) @ np.subtract(body.center, hinge.anchor)
        pose[body.name] = (position, quaternion)
    return pose


def _reach(shape: Shape) -> float:
    """The farthest any point of a shape lies from its centre, m."""
    if shape.kind == "box":
        return 0.5 * math.hypot(*shape.size)
    if shape.kind == "sphere":
        return shape.size[0]
    return shape.size[0] + 0.5 * shape.size[1]


def _view(pointer: Any, size: int, writable: bool = False) -> np.ndarray:
    """A live numpy view of ODE-owned doubles (a body's position, velocity ...)."""
    view = np.ctypeslib.as_array(pointer, shape=(size,))
    view.flags.writeable = writable
    return view


class OdeBackend(PhysicsBackend):
    """The robot in its own ODE world; velocity targets go to the hinge motors once per control
    period, as the server's agent protocol does."""

    restores_exactly = True

    def __init__(self, robot: RobotDescription, settings: PhysicsSettings) -> None:
        """Build the world, the robot's bodies, geoms and hinges (construction pose, then the
        rest pose) and the contact templates, and reset."""
        super().__init__(robot, settings)
        self._ode = lib = ode()
        lib.dAllocateODEDataForThread(ALLOCATE_COLLISION_DATA)  # ODE's per-thread data
        self._substeps = settings.substeps or DEFAULT_SUBSTEPS
        self._h = settings.timestep(DEFAULT_SUBSTEPS)
        self._world = world = lib.dWorldCreate()
        lib.dWorldSetGravity(world, 0.0, 0.0, GRAVITY)
        lib.dWorldSetCFM(world, WORLD_CFM)
        lib.dWorldSetERP(world, WORLD_ERP)
        lib.dWorldSetContactSurfaceLayer(world, SURFACE_LAYER)
        lib.dWorldSetAutoDisableFlag(world, 0)
        self._contacts = lib.dJointGroupCreate(0)
        self._plane = lib.dCreatePlane(None, 0.0, 0.0, 1.0, 0.0)
        self._index = {body.name: i for i, body in enumerate(robot.bodies)}
        self._bodies = [self._create_body(body.mass, body.inertia) for body in robot.bodies]
        # Built in the construction pose (every hinge angle 0 there), then moved to rest.
        for body, handle in zip(robot.bodies, self._bodies, strict=True):
            lib.dBodySetPosition(handle, body.center[0], body.center[1], body.center[2])
        self._geoms = [self._create_geom(body.shape, self._bodies[i])
                       for i, body in enumerate(robot.bodies) if body.collides]  # fmt: skip
        self._geom_body = [i for i, body in enumerate(robot.bodies) if body.collides]
        self._joints = [self._create_hinge(h) for h in robot.hinges]
        self._hinge_feedback = (JointFeedback * len(robot.hinges))()
        for joint, feedback in zip(self._joints, self._hinge_feedback, strict=True):
            lib.dJointSetFeedback(joint, ctypes.byref(feedback))
        child = [self._index[h.child] for h in robot.hinges]
        self._child = child
        # Anchor relative to the child's centre and axis, in the child's construction frame.
        self._anchor_arm = np.array([np.subtract(h.anchor, robot.body(h.child).center)
                                     for h in robot.hinges])  # fmt: skip
        self._axis = np.array([h.axis for h in robot.hinges], dtype=float)
        self._position = [_view(lib.dBodyGetPosition(b), 3) for b in self._bodies]
        # Writable: restore_state puts back the exact bits (below).
        self._quaternion = [_view(lib.dBodyGetQuaternion(b), 4, True) for b in self._bodies]
        self._rotation = [_view(lib.dBodyGetRotation(b), 12, True) for b in self._bodies]
        self._linear = [_view(lib.dBodyGetLinearVel(b), 3) for b in self._bodies]
        self._angular = [_view(lib.dBodyGetAngularVel(b), 3) for b in self._bodies]
        self._child_rotation = np.zeros((len(child), 12))  # child frames as the last step began
        # Contact templates: one block of MAX_CONTACTS per robot geom, surface values preset;
        # dCollide writes the points into them. Contact-joint feedback is kept for the
        # contact bodies (their normal forces).
        self._templates = [(Contact * MAX_CONTACTS)() for _ in self._geoms]
        self._points = [
            ctypes.cast(ctypes.byref(block, Contact.geom.offset), ctypes.POINTER(ContactGeom))
            for block in self._templates
        ]
        self._contact_pointers = [[ctypes.pointer(c) for c in block] for block in self._templates]
        self._contact_feedback = [(JointFeedback * MAX_CONTACTS)() for _ in self._geoms]
        self._feedback_pointers = [[ctypes.pointer(f) for f in block]
                                   for block in self._contact_feedback]  # fmt: skip
        feet = {self._index[name]: k for k, name in enumerate(robot.contact_bodies)}
        self._geom_foot = [feet.get(i, -1) for i in self._geom_body]
        self._touching: list[tuple[int, int, int]] = []  # (foot, geom, contact) of the last step
        self._stride = ctypes.sizeof(Contact)
        # Force and torque accumulators ODE adds to in a step and zeroes after it, written
        # directly (as dBodySetForce/Torque would), with drag and applied forces per body.
        self._accumulators = [_view(lib.dBodyGetForce(b), 3, True) for b in self._bodies]
        self._accumulators += [_view(lib.dBodyGetTorque(b), 3, True) for b in self._bodies]
        self._velocities = self._linear + self._angular  # same order as the accumulators
        self._applied = np.zeros((2 * len(self._bodies), 3))  # forces, then (zero) torques
        # A geom whose centre is higher above the ground than its farthest point cannot touch it.
        self._reach = [_reach(body.shape) for body in robot.bodies if body.collides]
        self._geom_position = [self._position[i] for i in self._geom_body]
        n = len(robot.hinges)
        self._command = np.zeros(n)
        self._angles = np.zeros(n)
        self._angles_view = self._angles.view()
        self._angles_view.flags.writeable = False
        self._steps = 0
        self._readings: tuple[np.ndarray, np.ndarray] | None = None
        #: the feet's normal forces summed over the control period's physics steps but the last
        self._contact_earlier = np.zeros(len(robot.contact_bodies))
        self._puppet: Any = None
        pose = rest_pose(robot)
        for body, handle in zip(robot.bodies, self._bodies, strict=True):
            position, quaternion = pose[body.name]
            lib.dBodySetPosition(handle, *position.tolist())
            lib.dBodySetQuaternion(handle, (ctypes.c_double * 4)(*quaternion.tolist()))
        self._initial = self.save_state()
        self.reset()

    def _create_body(self, mass: float, inertia: Vec3) -> int:
        lib, parameters = self._ode, Mass()
        lib.dMassSetParameters(ctypes.byref(parameters), mass, 0.0, 0.0, 0.0, *inertia,
                               0.0, 0.0, 0.0)  # fmt: skip
        handle = lib.dBodyCreate(self._world)
        lib.dBodySetMass(handle, ctypes.byref(parameters))
        return handle

    def _create_geom(self, shape, body: int) -> int:
        lib = self._ode
        if shape.kind == "box":
            geom = lib.dCreateBox(None, *shape.size)
        elif shape.kind == "sphere":
            geom = lib.dCreateSphere(None, shape.size[0])
        else:  # capsule along z, as ODE's
            geom = lib.dCreateCapsule(None, shape.size[0], shape.size[1])
        lib.dGeomSetBody(geom, body)
        return geom

    def _create_hinge(self, hinge) -> int:
        """An ODE hinge with the server's motor and stop parameters. The child is ODE's first
        body, so the angle grows as the child turns positively about the axis (the
        description's convention)."""
        lib = self._ode
        joint = lib.dJointCreateHinge(self._world, None)
        lib.dJointAttach(joint, self._bodies[self._index[hinge.child]],
                         self._bodies[self._index[hinge.parent]])  # fmt: skip
        lib.dJointSetHingeAnchor(joint, *hinge.anchor)
        lib.dJointSetHingeAxis(joint, *hinge.axis)
        for parameter, value in (
            (PARAM_LO_STOP, hinge.lower),
            (PARAM_HI_STOP, hinge.upper),
            (PARAM_FMAX, self.settings.max_joint_torque),
            (PARAM_CFM, JOINT_CFM),
            (PARAM_STOP_ERP, STOP_ERP),
            (PARAM_STOP_CFM, STOP_CFM),
            (PARAM_FUDGE_FACTOR, FUDGE_FACTOR),
            (PARAM_BOUNCE, STOP_BOUNCE),
            (PARAM_VEL, 0.0),
        ):
            lib.dJointSetHingeParam(joint, parameter, value)
        return joint

    # --- state ---------------------------------------------------------------------------

    def reset(self) -> None:
        self.restore_state(self._initial)
        self.set_ground_friction(self.settings.friction)

    def save_state(self) -> Any:
        bodies = np.array([
            np.concatenate((p, q, v, w, r))
            for p, q, v, w, r in zip(self._position, self._quaternion, self._linear,
                                     self._angular, self._rotation, strict=True)
        ])  # fmt: skip
        targets = np.array([self._ode.dJointGetHingeParam(j, PARAM_VEL) for j in self._joints])
        readings = (self.contact_forces().copy(), self.joint_torques().copy())
        return bodies, targets, self._applied.copy(), self._steps, readings

    def restore_state(self, state: Any) -> None:
        bodies, targets, forces, self._steps, readings = state
        lib, quaternion = self._ode, (ctypes.c_double * 4)()
        for k, (handle, row) in enumerate(zip(self._bodies, bodies.tolist(), strict=True)):
            lib.dBodySetPosition(handle, *row[0:3])
            quaternion[:] = row[3:7]
            lib.dBodySetQuaternion(handle, quaternion)
            # dBodySetQuaternion renormalises, which can change the last bit; put the saved
            # quaternion and the rotation ODE had derived from it back as they were.
            self._quaternion[k][:] = row[3:7]
            self._rotation[k][:] = row[13:25]
            lib.dBodySetLinearVel(handle, *row[7:10])
            lib.dBodySetAngularVel(handle, *row[10:13])
        for joint, target in zip(self._joints, targets.tolist(), strict=True):
            lib.dJointSetHingeParam(joint, PARAM_VEL, target)
        self._applied[:] = forces
        self._readings = readings
        self._read_angles()

    # --- stepping ------------------------------------------------------------------------

    def step(self, joint_targets: np.ndarray) -> None:
        """One control period: motor targets set once, then the physics steps; raises
        EvaluationError when the root has left the finite world (ODE flags nothing itself)."""
        servo_velocities(joint_targets, self._angles, self.settings, self._command)
        set_param = self._ode.dJointSetHingeParam
        for joint, velocity in zip(self._joints, self._command.tolist()):
            set_param(joint, PARAM_VEL, velocity)
        self._contact_earlier[:] = 0.0
        for _ in range(self._substeps - 1):
            self._physics_step()
            self._contact_earlier += self._contact_now()
        # joint_torques needs the child frames as the last physics step begins (only that
        # step's feedback is read): taken once per control period, not every physics step.
        for k, row in enumerate(self._child):
            self._child_rotation[k] = self._rotation[row]
        self._physics_step()
        self._steps += 1
        self._readings = None
        self._read_angles()
        check_root_height("ODE", self._position[0][2], self.time())

    def _physics_step(self) -> None:
        """Drag and applied forces, ground contacts, one dWorldStep (the server's order)."""
        lib, world, group = self._ode, self._world, self._contacts
        drag = np.concatenate(self._velocities).reshape(-1, 3)
        drag *= -DRAG
        drag += self._applied
        if not np.isfinite(drag).all():  # dWorldStep would abort the whole process on it
            raise instability_error("ODE", (self._steps + 1) * self.settings.control_period)
        for accumulator, load in zip(self._accumulators, drag):
            accumulator[:] = load
        collide, create, attach = lib.dCollide, lib.dJointCreateContact, lib.dJointAttach
        set_feedback, plane, stride = lib.dJointSetFeedback, self._plane, self._stride
        touching = self._touching
        touching.clear()
        for g, geom in enumerate(self._geoms):
            if self._geom_position[g][2] > self._reach[g]:
                continue
            count = collide(geom, plane, MAX_CONTACTS, self._points[g], stride)
            if not count:
                continue
            body, foot = self._bodies[self._geom_body[g]], self._geom_foot[g]
            contacts, feedback = self._contact_pointers[g], self._feedback_pointers[g]
            for c in range(count):
                joint = create(world, group, contacts[c])
                attach(joint, body, None)
                if foot >= 0:
                    set_feedback(joint, feedback[c])
                    touching.append((foot, g, c))
        lib.dWorldStep(world, self._h)
        lib.dJointGroupEmpty(group)

    def _read_angles(self) -> None:
        angle = self._ode.dJointGetHingeAngle
        self._angles[:] = [angle(joint) for joint in self._joints]

    # --- reading -------------------------------------------------------------------------

    def joint_angles(self) -> np.ndarray:
        return self._angles_view

    def joint_velocities(self) -> np.ndarray:
        rate = self._ode.dJointGetHingeAngleRate
        return np.array([rate(joint) for joint in self._joints])

    def joint_torques(self) -> np.ndarray:
        """Torque about each hinge's axis that the joint applied to its child during the last
        physics step (motor and, at a limit, the stop), from ODE's joint feedback: the
        feedback torque about the child's centre, less the moment of the hinge's linear
        constraint force, taken along the axis."""
        if self._readings is not None:
            return self._readings[1]
        torques = np.zeros(len(self._joints))
        for k, feedback in enumerate(self._hinge_feedback):
            rotation = self._child_rotation[k].reshape(3, 4)[:, :3]
            arm = rotation @ self._anchor_arm[k]
            force = np.frombuffer(feedback.f1, count=3)
            torque = np.frombuffer(feedback.t1, count=3) - np.cross(arm, force)
            torques[k] = torque @ (rotation @ self._axis[k])
        return torques

    def root_position(self) -> np.ndarray:
        return self._position[0]

    def root_rotation(self) -> np.ndarray:
        return self._rotation[0].reshape(3, 4)[:, :3]

    def body_position(self, name: str) -> np.ndarray:
        return self._position[self._index[name]].copy()

    def body_mass(self, name: str) -> float:
        return self._mass(name).mass

    def body_inertia(self, name: str) -> Vec3:
        inertia = self._mass(name).I
        return (inertia[0], inertia[5], inertia[10])

    def _mass(self, name: str) -> Mass:
        mass = Mass()
        self._ode.dBodyGetMass(self._bodies[self._index[name]], ctypes.byref(mass))
        return mass

    def contact_forces(self) -> np.ndarray:
        """Normal force of the ground on each contact body, the mean over the control period's
        physics steps (one at the server's settings)."""
        if self._readings is not None:
            return self._readings[0]
        return (self._contact_earlier + self._contact_now()) / self._substeps

    def _contact_now(self) -> np.ndarray:
        """Normal force of the ground on each contact body during the last physics step, from
        the contact joints' feedback."""
        forces = np.zeros(len(self.robot.contact_bodies))
        for foot, g, c in self._touching:
            normal = self._templates[g][c].geom.normal
            force = self._contact_feedback[g][c].f1
            forces[foot] += force[0] * normal[0] + force[1] * normal[1] + force[2] * normal[2]
        return forces

    def time(self) -> float:
        return self._steps * self.settings.control_period

    # --- changing the world --------------------------------------------------------------

    def set_ground_friction(self, mu: float) -> None:
        """mu = inf: the server's contact (no Coulomb limit, only force-dependent slip); a
        finite mu is a Coulomb coefficient (ODE's dContactApprox1: the friction force limit is
        mu times the normal force)."""
        mode = CONTACT_SOFT_ERP | CONTACT_SOFT_CFM
        slip = self.settings.slip
        if slip > 0:
            mode |= CONTACT_SLIP1 | CONTACT_SLIP2
        if math.isfinite(mu):
            mode |= CONTACT_APPROX1
        for block in self._templates:
            for contact in block:
                surface = contact.surface
                surface.mode, surface.mu = mode, mu
                surface.soft_erp, surface.soft_cfm = SOFT_ERP, SOFT_CFM
                surface.slip1 = surface.slip2 = slip

    def ground_friction(self) -> float:
        return self._templates[0][0].surface.mu

    def apply_force(self, body: str, force: Vec3) -> None:
        self._applied[self._index[body]] = force

    def push_root(self, velocity: Vec3) -> None:
        set_velocity = self._ode.dBodySetLinearVel
        for body, v in zip(self._bodies, self._linear, strict=True):
            set_velocity(body, *(v + velocity).tolist())

    # --- drawing -------------------------------------------------------------------------

    def render(self, width: int, height: int, camera_target: Vec3) -> np.ndarray:
        """ODE's pose drawn by the MuJoCo model of the same robot (ODE has no renderer)."""
        if self._puppet is None:
            from metaopt_problems.physics.mujoco_engine import MujocoBackend

            self._puppet = MujocoBackend(
                self.robot, dataclasses.replace(self.settings, friction=1.0)
            )
        qpos = self._puppet.data.qpos
        qpos[0:3] = self._position[0]
        qpos[3:7] = self._quaternion[0]
        qpos[7 : 7 + len(self._angles)] = self._angles
        return self._puppet.render(width, height, camera_target)

    def close(self) -> None:
        if self._puppet is not None:
            self._puppet.close()
            self._puppet = None
        if self._world is not None:
            lib = self._ode
            lib.dJointGroupDestroy(self._contacts)
            for geom in [*self._geoms, self._plane]:
                lib.dGeomDestroy(geom)
            lib.dWorldDestroy(self._world)
            self._world = None

    def __del__(self) -> None:
        if getattr(self, "_world", None) is not None:
            self.close()
