"""The `nao-walk` problem: tune the paper's Matsuoka CPG so the simulated NAO walks.

The decision vector is the CPG's 10 parameters (controller.cpg_space); evaluate runs one
15 s episode (episode.py) on the chosen physics backend and returns the fitness and metrics.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from metaopt import hookimpl
from metaopt.errors import ConfigError
from metaopt.params import Param
from metaopt.physics import PhysicsSettings
from metaopt.plugins import registry
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense

from .controller import MatsuokaCpg, cpg_space
from .episode import FITNESS_KINDS, Disturbance, EpisodeRunner, EpisodeSettings, Gait, fitness
from .robot import nao

PARAMS = (
    Param("backend", str, "mujoco", "physics engine (an installed physics backend plugin)"),
    Param("fitness", str, "robust", "robust (monotone, default) or paper (eq. 9 as printed)",
          choices=FITNESS_KINDS),
    Param("duration", float, 15.0, "simulated seconds per episode, lock phase included",
          low=0.0, high=600.0, low_open=True),
    Param("lock", float, 3.0, "seconds the robot stands with the controller off", low=0.0),
    Param("substeps", int, 0, "physics steps per 20 ms control period; 0 = the engine's default",
          low=0, high=100),
    Param("servo_gain", float, 10.0, "joint velocity command per radian of angle error, 1/s",
          low=0.0, low_open=True),
    Param("fall_height", float, 0.25, "fallen when the torso centre is lower than this, m",
          low=0.0),
    Param("fall_tilt", float, 60.0, "fallen when the torso tilts further than this, degrees",
          low=0.0, high=180.0, low_open=True),
    Param("noise", float, 0.0, "disturbance scale drawn from the evaluation's seed: friction, "
          "push, hip sensors (docs/nao-walk.md, Noise); 0 = deterministic", low=0.0, high=10.0),
)  # fmt: skip


class NaoWalk(Problem):
    """The paper's task on one physics backend. With noise 0 the seed is not used; with noise
    > 0 it draws the episode's Disturbance. Either way (x, seed) gives the same episode in any
    process."""

    sense = Sense.MAXIMIZE
    key_metrics = ("distance", "drift", "speed", "time_walked", "fell")

    def __init__(
        self,
        backend: str = "mujoco",
        fitness: str = "robust",
        duration: float = 15.0,
        lock: float = 3.0,
        substeps: int = 0,
        servo_gain: float = 10.0,
        fall_height: float = 0.25,
        fall_tilt: float = 60.0,
        noise: float = 0.0,
    ) -> None:
        if lock >= duration:
            raise ConfigError(
                f"nao-walk: lock ({lock} s) must be shorter than duration ({duration} s)"
            )
        self.backend_info = registry().physics_backend(backend)
        self.space = cpg_space()
        self.fitness_kind = fitness
        self.physics = PhysicsSettings(substeps=substeps, servo_gain=servo_gain)
        self.episode = EpisodeSettings(duration, lock, fall_height, fall_tilt)
        self.noise = noise
        self.robot = nao()
        limits = {}
        for joint in ("llj3", "llj4", "llj5"):
            hinge = self.robot.hinges[self.robot.joint_index(joint)]
            limits[joint] = (hinge.lower, hinge.upper)
        self._limits = limits
        self._runner: EpisodeRunner | None = None

    @property
    def runner(self) -> EpisodeRunner:
        """The episode runner, its engine built on first use (once per process)."""
        if self._runner is None:
            engine = self.backend_info.factory(self.robot, self.physics)
            self._runner = EpisodeRunner(engine, self.episode)
        return self._runner

    def gait(self, x: np.ndarray) -> Gait:
        """The CPG controller for decision vector x (space order)."""
        return MatsuokaCpg(
            [float(v) for v in x],
            hip_limits=self._limits["llj3"],
            knee_limits=self._limits["llj4"],
            ankle_limits=self._limits["llj5"],
        )

    def disturbance(self, seed: int) -> Disturbance | None:
        """The episode conditions seed draws at this problem's noise (None when noise is 0)."""
        if self.noise == 0:
            return None
        return Disturbance.draw(self.noise, seed, self.physics.friction, self.runner.walk_steps)

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        result = self.runner.run(self.gait(x), disturbance=self.disturbance(seed))
        value = fitness(result, self.fitness_kind, self.episode.duration)
        return Evaluation(value, result.metrics())

    def close(self) -> None:
        if self._runner is not None:
            self._runner.backend.close()
            self._runner = None

    def __getstate__(self) -> dict[str, Any]:
        # Engines do not pickle; each process builds its own on first use.
        return {**self.__dict__, "_runner": None}


@hookimpl
def metaopt_problems() -> list[ProblemInfo]:
    """Announce nao-walk."""
    return [
        ProblemInfo(
            name="nao-walk",
            summary="NAO biped walking with a Matsuoka CPG (the paper's task), MuJoCo or PyBullet",
            factory=NaoWalk,
            params=PARAMS,
            description=(
                "Tune the 10 parameters of a two-neuron Matsuoka CPG (tau1, tau2, alpha, beta, "
                "gamma, c, w11, w12, b1, b2) so the classic rcssserver3d NAO walks straight: "
                "15 s episodes, 3 s lock phase, 50 Hz control, fitness X - |Y| with a fall "
                "penalty. See docs/nao-walk.md."
            ),
            default_budget=750,
        )
    ]
