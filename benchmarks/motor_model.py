"""How each engine's joint motors behave, measured from the engines (docs/nao-walk.md, "Motors").

For each physics backend prints
  * saturation: replaying stored fast gaits (their recorded evaluation), the fraction of the
    walking phase's control steps (up to a fall) on which some joint's motor torque read back
    is at the limit (within 1 %), and the fraction of joint-steps at it; and the gait's speed
    (over the time it walked), drift and fall;
  * response: the head's yaw joint commanded 3 rad/s from rest, sampled every physics step
    (control period = one physics step): the time until it turns at 90 % of that;
  * standing: 3 s with every joint held at rest: largest torso tilt after the first second,
    torso height, largest joint error.

    python benchmarks/motor_model.py [--backends mujoco,pybullet] [--gaits stride_mujoco,...]

--backends defaults to every engine that can run here.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from metaopt.physics.agreement import engine
from metaopt.plugins import registry
from metaopt_problems.nao_walk.stored_gaits import (
    gait_problem,
    gait_seed,
    gait_vector,
    load_gait,
)

#: Stored gaits replayed by default: the fastest on MuJoCo, and the both-engine one.
GAITS = ("stride_mujoco", "stride_both_restarts")
COMMAND = 3.0


def saturation(backend: str, gait_name: str) -> dict[str, float]:
    """Torque-limit fractions over the walking phase's control steps (up to a fall; the lock
    phase left out) of a stored gait's recorded episode on backend, with its own metrics."""
    record = load_gait(gait_name)
    problem = gait_problem(record["problem_params"], backend)
    try:
        # the world its evaluation walks in
        walk, disturbance, push = problem.walked(gait_seed(record))
        runner = walk.runner
        sim = runner.backend
        limit = 0.99 * sim.settings.max_joint_torque
        at_limit: list[np.ndarray] = []

        def read_torques(_: int) -> None:
            """After each walking control step: which joints' motors are at the limit."""
            at_limit.append(np.abs(sim.joint_torques()) >= limit)

        gait = walk.gait(gait_vector(record))
        result = runner.run(gait, disturbance=disturbance, on_step=read_torques, push=push)
    finally:
        problem.close()
    walking = np.array(at_limit)
    return {
        "steps_at_limit": float(walking.any(axis=1).mean()),
        "joint_steps_at_limit": float(walking.mean()),
        "steps": float(len(walking)),
        "speed": result.speed,
        "drift": result.drift,
        "fell": float(result.fell),
    }


def response_time(backend: str) -> float:
    """Seconds until the head's yaw joint turns at 90 % of COMMAND, sampled every physics step."""
    info = registry().physics_backend(backend)
    step = 0.02 / info.default_substeps
    with engine(info, control_period=step, substeps=1) as sim:
        for _ in range(round(0.5 / step)):
            sim.step(sim.robot.rest_angles)
        head = sim.robot.joint_index("hj1")
        for k in range(1, 200):
            targets = sim.robot.rest_angles
            # keep the servo's command at COMMAND: target = angle + COMMAND / gain
            targets[head] = sim.joint_angles()[head] + COMMAND / sim.settings.servo_gain
            sim.step(targets)
            if sim.joint_velocities()[head] >= 0.9 * COMMAND:
                return k * step
    return math.inf


def standing(backend: str) -> dict[str, float]:
    """Tilt, height and joint error over 3 s of standing with every joint held."""
    with engine(backend) as sim:
        tilts = []
        for _ in range(150):
            sim.step(sim.robot.rest_angles)
            tilts.append(math.degrees(math.acos(min(1.0, float(sim.root_rotation()[2, 2])))))
        return {
            "tilt_deg": max(tilts[50:]),
            "height": float(sim.root_position()[2]),
            "joint_error_deg": math.degrees(
                float(np.abs(sim.joint_angles() - sim.robot.rest_angles).max())
            ),
        }


def main() -> None:
    """Print each runnable engine's saturation, response and standing (engines that cannot run
    here are left out unless --backends names them)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    available = registry().available_physics_backends()
    parser.add_argument("--backends", default=",".join(available))
    parser.add_argument("--gaits", default=",".join(GAITS))
    args = parser.parse_args()
    for backend in args.backends.split(","):
        print(f"== {backend}")
        for gait in args.gaits.split(","):
            s = saturation(backend, gait)
            print(
                f"  {gait}: steps at the torque limit {s['steps_at_limit']:.1%}, joint-steps "
                f"{s['joint_steps_at_limit']:.1%}; speed {s['speed']:.3f} m/s, drift "
                f"{s['drift']:+.3f} m, fell {s['fell']:.0f} ({s['steps']:.0f} walking steps)"
            )
        print(f"  head yaw to 90 % of {COMMAND} rad/s: {response_time(backend) * 1000:.1f} ms")
        st = standing(backend)
        print(
            f"  standing 3 s: tilt {st['tilt_deg']:.3f} deg, torso height {st['height']:.4f} m, "
            f"joint error {st['joint_error_deg']:.3f} deg"
        )


if __name__ == "__main__":
    main()
