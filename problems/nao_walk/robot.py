"""The classic rcssserver3d NAO (0.6.x, 2008-2011), described once for every physics engine.

Numbers are those of shared/nao-model.md §2-§4: 23 bodies (primitive solids), 22 hinges, a free
torso, no self-collision, ten collider-less mass spheres. Frame: x forward, y left, z up, origin
at the torso centre in the construction pose (all joints 0, arms pointing forward). Joint names
are the server's perceptor names; NAO_NAMES maps them to the real robot's.
"""

from __future__ import annotations

import math

from metaopt.physics import Body, Hinge, RobotDescription, Shape

#: Server perceptor name -> real NAO (Aldebaran) joint name.
NAO_NAMES: dict[str, str] = {
    "hj1": "HeadYaw", "hj2": "HeadPitch",
    "laj1": "LShoulderPitch", "laj2": "LShoulderRoll", "laj3": "LElbowYaw", "laj4": "LElbowRoll",
    "raj1": "RShoulderPitch", "raj2": "RShoulderRoll", "raj3": "RElbowYaw", "raj4": "RElbowRoll",
    "llj1": "LHipYawPitch", "llj2": "LHipRoll", "llj3": "LHipPitch",
    "llj4": "LKneePitch", "llj5": "LAnklePitch", "llj6": "LAnkleRoll",
    "rlj1": "RHipYawPitch", "rlj2": "RHipRoll", "rlj3": "RHipPitch",
    "rlj4": "RKneePitch", "rlj5": "RAnklePitch", "rlj6": "RAnkleRoll",
}  # fmt: skip

#: Torso centre height at reset: the server's AgentRadius (feet start 15 mm above the ground).
START_HEIGHT = 0.40
#: Floor to top of head with all joints 0 (nao-model.md §4).
STANDING_HEIGHT = 0.605
#: Shoulder pitch rest angle: arms hang down instead of pointing forward.
ARMS_DOWN = -math.pi / 2

PITCH = (0.0, -1.0, 0.0)  # the axis of every pitch hinge (hips, knees, ankles, shoulders, head)
ROLL = (1.0, 0.0, 0.0)
YAW = (0.0, 0.0, 1.0)


def _box(x: float, y: float, z: float) -> Shape:
    return Shape("box", (x, y, z))


def _sphere(radius: float) -> Shape:
    return Shape("sphere", (radius,))


def _side(prefix: str, sign: float) -> tuple[list[Body], list[Hinge]]:
    """One arm and one leg; sign +1 for the left side (+y), -1 for the right."""
    p, s = prefix, sign
    bodies = [
        Body(f"{p}shoulder", "torso", _sphere(0.01), 0.07, (0.0, s * 0.098, 0.075), False),
        Body(f"{p}upperarm", f"{p}shoulder", _box(0.08, 0.07, 0.06), 0.15,
             (0.02, s * 0.108, 0.075), True),
        Body(f"{p}elbow", f"{p}upperarm", _sphere(0.01), 0.035, (0.09, s * 0.098, 0.084), False),
        Body(f"{p}lowerarm", f"{p}elbow", _box(0.11, 0.05, 0.05), 0.20,
             (0.14, s * 0.098, 0.084), True),
        Body(f"{p}hip1", "torso", _sphere(0.01), 0.09, (-0.01, s * 0.055, -0.115), False),
        Body(f"{p}hip2", f"{p}hip1", _sphere(0.01), 0.125, (-0.01, s * 0.055, -0.115), False),
        Body(f"{p}thigh", f"{p}hip2", _box(0.07, 0.07, 0.14), 0.275,
             (0.0, s * 0.055, -0.155), True),
        Body(f"{p}shank", f"{p}thigh", _box(0.07, 0.08, 0.11), 0.225,
             (0.005, s * 0.055, -0.28), True),
        Body(f"{p}ankle", f"{p}shank", _sphere(0.01), 0.125, (-0.005, s * 0.055, -0.335), False),
        Body(f"{p}foot", f"{p}ankle", _box(0.16, 0.08, 0.03), 0.20,
             (0.025, s * 0.055, -0.37), True),
    ]  # fmt: skip
    shoulder, elbow = (0.0, s * 0.098, 0.075), (0.09, s * 0.098, 0.084)
    hip = (-0.01, s * 0.055, -0.115)
    knee = (-0.005, s * 0.055, -0.235)
    ankle = (-0.005, s * 0.055, -0.335)
    a, leg = f"{p}aj", f"{p}lj"

    def mirrored(lower: float, upper: float) -> tuple[float, float]:
        """Limits (degrees) given for the left side; the right side's are mirrored."""
        return (lower, upper) if s > 0 else (-upper, -lower)

    def hinge(name: str, parent: str, child: str, anchor, axis, limits, rest=0.0) -> Hinge:
        lower, upper = (math.radians(v) for v in limits)
        return Hinge(name, parent, child, anchor, axis, lower, upper, rest)

    hip_yaw_axis = (0.0, 0.7071067811865476, -s * 0.7071067811865476)
    hinges = [
        hinge(f"{a}1", "torso", f"{p}shoulder", shoulder, PITCH, (-120, 120), ARMS_DOWN),
        hinge(f"{a}2", f"{p}shoulder", f"{p}upperarm", shoulder, YAW, mirrored(-1, 95)),
        hinge(f"{a}3", f"{p}upperarm", f"{p}elbow", elbow, ROLL, (-120, 120)),
        hinge(f"{a}4", f"{p}elbow", f"{p}lowerarm", elbow, YAW, mirrored(-90, 1)),
        hinge(f"{leg}1", "torso", f"{p}hip1", hip, hip_yaw_axis, (-90, 1)),
        hinge(f"{leg}2", f"{p}hip1", f"{p}hip2", hip, ROLL, mirrored(-25, 45)),
        hinge(f"{leg}3", f"{p}hip2", f"{p}thigh", hip, PITCH, (-25, 100)),
        hinge(f"{leg}4", f"{p}thigh", f"{p}shank", knee, PITCH, (-130, 1)),
        hinge(f"{leg}5", f"{p}shank", f"{p}ankle", ankle, PITCH, (-45, 75)),
        hinge(f"{leg}6", f"{p}ankle", f"{p}foot", ankle, ROLL, mirrored(-45, 25)),
    ]
    return bodies, hinges


def nao() -> RobotDescription:
    """The classic rcssserver3d NAO: 4.6071 kg, 0.605 m, 22 hinges (head, arms, legs)."""
    bodies = [
        Body("torso", None, _box(0.10, 0.10, 0.18), 1.2171, (0.0, 0.0, 0.0), True),
        Body("neck", "torso", Shape("capsule", (0.015, 0.08)), 0.05, (0.0, 0.0, 0.09), True),
        Body("head", "neck", _sphere(0.065), 0.35, (0.0, 0.0, 0.155), True),
    ]
    hinges = [
        Hinge("hj1", "torso", "neck", (0.0, 0.0, 0.09), YAW, -math.radians(120),
              math.radians(120)),
        Hinge("hj2", "neck", "head", (0.0, 0.0, 0.15), PITCH, -math.radians(45),
              math.radians(45)),
    ]  # fmt: skip
    left_bodies, left_hinges = _side("l", 1.0)
    right_bodies, right_hinges = _side("r", -1.0)
    arms = [b for b in left_bodies + right_bodies if not b.name.endswith(_LEG_PARTS)]
    legs = [b for b in left_bodies + right_bodies if b.name.endswith(_LEG_PARTS)]
    joints = hinges + [h for h in left_hinges + right_hinges if "aj" in h.name]
    joints += [h for h in left_hinges + right_hinges if "lj" in h.name]
    return RobotDescription(
        name="nao",
        bodies=tuple(bodies + arms + legs),
        hinges=tuple(joints),
        contact_bodies=("lfoot", "rfoot"),
        start_height=START_HEIGHT,
    )


_LEG_PARTS = ("hip1", "hip2", "thigh", "shank", "ankle", "foot")
