"""The NAO description: the numbers of shared/nao-model.md §2-§4, in one place."""

from __future__ import annotations

import math

import pytest

from metaopt.physics import Shape
from metaopt_problems.nao_walk.robot import NAO_NAMES, STANDING_HEIGHT, nao

SERVER_NAMES = (
    ["hj1", "hj2"]
    + [f"{s}aj{i}" for s in "lr" for i in range(1, 5)]
    + [f"{s}lj{i}" for s in "lr" for i in range(1, 7)]
)


def test_bodies_joints_and_mass() -> None:
    robot = nao()
    assert len(robot.bodies) == 23
    assert robot.joint_names == tuple(SERVER_NAMES)
    assert robot.total_mass == pytest.approx(4.6071, abs=1e-9)
    assert sum(not b.collides for b in robot.bodies) == 10
    assert set(NAO_NAMES) == set(robot.joint_names)
    assert NAO_NAMES["llj3"] == "LHipPitch" and NAO_NAMES["raj1"] == "RShoulderPitch"


def test_limits_and_rest_pose_in_radians() -> None:
    robot = nao()
    limits = {h.name: (math.degrees(h.lower), math.degrees(h.upper)) for h in robot.hinges}
    assert limits["llj3"] == pytest.approx((-25, 100))
    assert limits["rlj4"] == pytest.approx((-130, 1))
    assert limits["llj5"] == pytest.approx((-45, 75))
    assert limits["llj2"] == pytest.approx((-25, 45))
    assert limits["rlj2"] == pytest.approx((-45, 25))
    assert limits["raj2"] == pytest.approx((-95, 1))
    rest = dict(zip(robot.joint_names, robot.rest_angles, strict=True))
    assert rest["laj1"] == rest["raj1"] == pytest.approx(-math.pi / 2)
    assert sum(abs(v) for k, v in rest.items() if k not in ("laj1", "raj1")) == 0


def test_standing_height_and_centre_of_mass_from_geometry() -> None:
    robot = nao()
    top = max(b.center[2] + b.shape.half_height for b in robot.bodies)
    bottom = min(b.center[2] - b.shape.half_height for b in robot.bodies)
    assert top - bottom == pytest.approx(STANDING_HEIGHT, abs=1e-9)
    com = [sum(b.mass * b.center[i] for b in robot.bodies) / robot.total_mass for i in range(3)]
    assert com == pytest.approx([0.0163, 0.0, -0.0784], abs=1e-4)


def test_inertias_use_odes_formulas() -> None:
    robot = nao()
    assert robot.body("torso").inertia == pytest.approx((4.300e-3, 4.300e-3, 2.029e-3), rel=1e-3)
    assert robot.body("neck").inertia == pytest.approx((4.50e-5, 4.50e-5, 5.4e-6), rel=1e-3)
    assert robot.body("lfoot").inertia == pytest.approx((1.217e-4, 4.417e-4, 5.333e-4), rel=1e-3)
    with pytest.raises(ValueError):
        Shape("box", (1.0,))
