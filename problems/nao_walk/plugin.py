"""The `nao-walk` problem: tune the paper's Matsuoka CPG so the simulated NAO walks.

The decision vector is the controller's parameters (the paper's CPG by default: 10,
controller.cpg_space; extended.py's controllers with ``controller``); evaluate runs one
15 s episode (episode.py) on the chosen physics backend and returns the fitness and metrics.
With several backends joined by '+' (``mujoco+pybullet``) it runs the episode on each: the
fitness and the plain metrics are the worst engine's, and every engine's metrics are added as
``NAME@ENGINE`` (``engine_score=mean`` scores their mean instead: a search from random
candidates then sees every engine's progress, where the worst is flat until a gait walks on
all). Perturbations (docs/robustness.md): friction, servo gain, a mass scale (the
robot description's bodies scaled before any engine is built), a push on the torso, sensor
latency, and the seed-drawn noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from metaopt import hookimpl
from metaopt.assessment.robustness import select_cells
from metaopt.errors import ConfigError
from metaopt.params import Param
from metaopt.physics import PhysicsSettings, engine_names
from metaopt.plugins import registry
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense, StoredCandidate
from metaopt.space import Space

if TYPE_CHECKING:
    from matplotlib.figure import Figure

from .controller import MatsuokaCpg, cpg_space
from .episode import (
    FITNESS_KINDS,
    FLIGHT_ALLOWED,
    FRICTION_SPREAD,
    Disturbance,
    EpisodeRunner,
    EpisodeSettings,
    Gait,
    Push,
    control_steps,
    fitness,
)
from .extended import (
    BalancedCpg,
    ExtendedCpg,
    SteeredCpg,
    StrideCpg,
    balanced_space,
    extended_space,
    steered_space,
    stride_space,
)
from .robot import nao
from .robustness import PUSH_IMPULSE, STANDARD_TABLE, UNSAMPLED
from .video import film


class ControllerKind(NamedTuple):
    """A controller nao-walk can tune: its decision space, and how to build the gait for a
    decision vector (parameters in space order, joint limits by joint name)."""

    space: Callable[[], Space]
    build: Callable[[list[float], Mapping[str, tuple[float, float]]], Gait]


def _paper_cpg(params: list[float], limits: Mapping[str, tuple[float, float]]) -> MatsuokaCpg:
    return MatsuokaCpg(
        params, hip_limits=limits["llj3"], knee_limits=limits["llj4"], ankle_limits=limits["llj5"]
    )


#: The controllers nao-walk can tune: the paper's, and the extended, stride, steered and
#: balanced ones of extended.py.
CONTROLLER_KINDS = {
    "paper": ControllerKind(cpg_space, _paper_cpg),
    "extended": ControllerKind(extended_space, ExtendedCpg),
    "stride": ControllerKind(stride_space, StrideCpg),
    "steered": ControllerKind(steered_space, SteeredCpg),
    "balanced": ControllerKind(balanced_space, BalancedCpg),
}
CONTROLLERS = tuple(CONTROLLER_KINDS)
#: worlds: none, one cell of the standard perturbation table drawn per evaluation, or a push
#: of the table's size in a drawn direction at a drawn time.
WORLDS = ("none", "standard", "pushes")
#: worlds=pushes: the push comes no earlier than this after walking starts (the gait grows
#: over the first seconds) ...
PUSH_AFTER_S = 2.0
#: ... and no later than this before the episode ends (time to fall, if it will).
PUSH_BEFORE_END_S = 3.0
#: world_cells: the cells' names are joined by this.
CELL_SEPARATOR = ","
#: How several engines' fitnesses make one: the worst of them, or their mean.
ENGINE_SCORES = ("worst", "mean")
#: The engine a screen leaves out unless screen_engines names others: the slowest, about 4x
#: MuJoCo's and ODE's time per walk (benchmarks/episode_throughput.py).
SLOWEST_ENGINE = "pybullet"
#: With several engines, each engine's fitness is a metric too: this name, then @ENGINE.
FITNESS_METRIC = "fitness"

PARAMS = (
    Param("backend", str, "mujoco", "physics engine (an installed physics backend plugin), or "
          "several joined by '+' (scored by engine_score)"),
    Param("engine_score", str, "worst", "with several engines: worst (the fitness is the worst "
          "engine's) or mean (their mean; the plain metrics stay the worst engine's)",
          choices=ENGINE_SCORES),
    Param("engine_cap", float, 0.0, "with several engines: each engine's fitness counts at "
          "most this before its flight penalty and before engine_score takes the worst or the "
          "mean (0 = no cap): with the mean, going past the cap on one engine stops paying, so "
          "the slower engines must catch up, and running there still costs", low=0.0),
    Param("screen_engines", str, "", "with several engines and engine_score=worst: the "
          "engines metaopt run --screen walks a candidate on first, joined by '+' (empty: all "
          "but pybullet, the slowest); the worst of them bounds its fitness, and it walks on "
          "the others only where the run needs its full score"),
    Param("controller", str, "paper", "paper (the paper's CPG and its 10 parameters), "
          "extended (sway, knee lift, torso feedback; docs/nao-walk.md), stride (extended, "
          "with a knee phase and an ankle push-off), steered (stride, with heading "
          "feedback) or balanced (steered, with a stepping strategy)", choices=CONTROLLERS),
    Param("fitness", str, "robust", "robust (monotone, default), paper (eq. 9 as printed) or "
          "progress (a fall costs 1 m and the walk it cut short)",
          choices=FITNESS_KINDS),
    Param("duration", float, 15.0, "simulated seconds per episode, lock phase included",
          low=0.0, high=600.0, low_open=True),
    Param("lock", float, 3.0, "seconds the robot stands with the controller off", low=0.0),
    Param("substeps", int, 0, "physics steps per 20 ms control period; 0 = the engine's default",
          low=0, high=100),
    Param("friction", float, 0.0, "ground friction coefficient; inf = no sliding limit (the "
          "paper's simulator; ODE only); 0 = the engine's default (1 on MuJoCo and PyBullet, "
          "inf on ODE); MuJoCo takes at most 3, PyBullet 10", low=0.0, infinite=True),
    Param("friction_scale", float, 1.0, "multiplies the ground friction (the given one or the "
          "engine's default; an unlimited one stays unlimited): the friction perturbation",
          low=0.0, low_open=True, high=100.0),
    Param("slip", float, 5e-3, "force-dependent slip of the ground contacts, m/s per N "
          "(the paper's simulator: 0.005; 0 = none); only ODE has it, the others ignore it",
          low=0.0, high=1.0),
    Param("servo_gain", float, 10.0, "joint velocity command per radian of angle error, 1/s",
          low=0.0, low_open=True),
    Param("weight_scale", float, 1.0, "paper controller: multiplies Table 2's bounds of the "
          "output weights w11, w12 (1 = the paper's; larger = wider joint swings allowed)",
          low=1.0, high=100.0),
    Param("fall_height", float, 0.25, "fallen when the torso centre is lower than this, m",
          low=0.0),
    Param("fall_tilt", float, 60.0, "fallen when the torso tilts further than this, degrees",
          low=0.0, high=180.0, low_open=True),
    Param("noise", float, 0.0, "disturbance scale drawn from the evaluation's seed: friction, "
          "push, hip sensors (docs/nao-walk.md, Noise); 0 = deterministic; the friction it can "
          "draw, friction x exp(0.2 noise), must stay within each engine's limit", low=0.0,
          high=10.0),
    Param("mass_scale", float, 1.0, "every body's mass and inertia multiplied by this",
          low=0.1, high=10.0),
    Param("push", float, 0.0, "impulse on the torso, N·s, over one control period at "
          "push_time; 0 = none", low=0.0, high=100.0),
    Param("push_direction", float, 0.0, "direction of the push, degrees from forward "
          "(90 = to the left)", low=-360.0, high=360.0),
    Param("push_time", float, 6.0, "episode time of the push, s (within the walking phase)",
          low=0.0),
    Param("latency", int, 0, "sensor latency: the controller reads what was measured this "
          "many 20 ms control steps earlier", low=0, high=50),
    Param("measure_flight", bool, False, "also measure the metric flight: the share of the "
          "walking phase after 2 s with neither foot on the ground (a contact query per step)"),
    Param("flight_penalty", float, 0.0, "metres of fitness lost per unit of flight share "
          "above flight_allowed (neither foot on the ground: a run, not a walk); a fall before "
          "the flight is measured counts as flight throughout; > 0 measures flight; 0 = none",
          low=0.0, high=1000.0),
    Param("flight_allowed", float, FLIGHT_ALLOWED, "flight share (neither foot on the ground) "
          "charged no flight_penalty: 0.05 is the robust-walk goal's bound; a search may ask "
          "for less, to keep a margin for the worlds its gait was not tuned in",
          low=0.0, high=1.0),
    Param("worlds", str, "none", "none; standard: each evaluation's seed draws one cell of "
          "the standard perturbation table (docs/robustness.md) to walk in; pushes: each "
          f"evaluation's seed draws a push of the table's size ({PUSH_IMPULSE:g} N·s) on the "
          f"torso, in any horizontal direction, at a time from {PUSH_AFTER_S:g} s after walking "
          f"starts to {PUSH_BEFORE_END_S:g} s before the end",
          choices=WORLDS),
    Param("world_cells", str, "", "with worlds=standard: the cells drawn from, their names "
          f"joined by '{CELL_SEPARATOR}' (empty = every cell); with worlds=pushes: each pushed "
          "evaluation also walks in one of these cells, drawn from its seed (empty = the nominal "
          "world), and a push cell's evaluation gets that cell's push instead of a drawn one; "
          "a cell named k times is drawn k times as often, e.g. "
          "'nominal,servo gain x1.2,latency 1' or 'nominal,nominal,servo gain x1.2'"),
    Param("cell_durations", str, "", "with world_cells: some of its cells walked for another "
          f"duration, s, as 'NAME=SECONDS' joined by '{CELL_SEPARATOR}' (the others walk "
          "duration); engine_cap scales with the walking time, so the cap is the same speed in "
          "every cell; e.g. 'servo gain x1.2=15,latency 1=15': a short walk in most worlds, a "
          "long one where gaits fall late"),
)  # fmt: skip


def _require_choice(name: str, value: str, accepted: tuple[str, ...]) -> None:
    """ConfigError naming the parameter and what it accepts, for a value not among them (the
    CLI checks choices before; this is for NaoWalk built from Python)."""
    if value not in accepted:
        raise ConfigError(f"nao-walk: unknown {name} {value!r}; accepted: {', '.join(accepted)}")


def _check_push_window(push: float, lock: float, duration: float) -> None:
    """ConfigError where worlds=pushes cannot draw a push: a push set as well, or an episode
    too short for the window it draws from."""
    if push:
        raise ConfigError(
            f"nao-walk: worlds=pushes draws each evaluation's push; leave push at 0 (got {push})"
        )
    shortest = lock + PUSH_AFTER_S + PUSH_BEFORE_END_S
    if duration <= shortest:
        raise ConfigError(
            f"nao-walk: worlds=pushes pushes from {PUSH_AFTER_S:g} s after walking starts to "
            f"{PUSH_BEFORE_END_S:g} s before the end; duration must be more than {shortest:g} s "
            f"(got {duration:g})"
        )


def _check_push_time(push_time: float, lock: float, duration: float) -> None:
    """ConfigError for a push_time outside the walking phase once rounded, as the runner rounds
    it, to the nearest control step: from lock to the start of the walking phase's last step."""
    period = PhysicsSettings().control_period
    walking = duration - lock
    last = control_steps(walking, period) - 1 if math.isfinite(walking) else None
    if (
        last is not None
        and lock <= push_time < duration
        and 0 <= control_steps(push_time - lock, period) <= last
    ):
        return
    latest = "before duration"
    if last is not None and last >= 0:
        latest = f"{lock + last * period:g} s, the last step's start"
    raise ConfigError(
        f"nao-walk: push_time ({push_time} s) must fall within the walking phase: a push acts in "
        f"the {period * 1000:g} ms control step nearest to it, so it is accepted from lock "
        f"({lock} s) to {latest} (duration {duration} s)"
    )


def _check_noisy_friction(engine: str, friction: float, noise: float, max_friction: float) -> None:
    """ConfigError where the noise can draw a ground friction above what the engine handles
    (Disturbance.draw multiplies the nominal friction by up to exp(FRICTION_SPREAD * noise))."""
    highest = friction * math.exp(FRICTION_SPREAD * abs(noise))
    if highest > max_friction:
        raise ConfigError(
            f"nao-walk: noise {noise:g} draws ground frictions up to {highest:.4g} (friction "
            f"{friction:g} x exp({FRICTION_SPREAD:g} x {noise:g})), more than the {engine} "
            f"backend handles (at most {max_friction:g}); lower noise, friction or "
            "friction_scale, or use another backend"
        )


def _cell_indices(world_cells: str, worlds: str) -> tuple[int, ...]:
    """The standard table's cells world_cells names, as indices in table order (every cell
    when empty), each repeated as often as it is named, so that a cell named twice is drawn
    twice as often; ConfigError for a name the table lacks, or for cells worlds cannot draw."""
    if not world_cells:
        return tuple(range(len(STANDARD_TABLE.cells))) if worlds == "standard" else ()
    if worlds == "none":
        raise ConfigError(
            "nao-walk: world_cells names the cells worlds=standard or worlds=pushes draws "
            f"from; with worlds=none leave it empty (got {world_cells!r})"
        )
    names = [name.strip() for name in world_cells.split(CELL_SEPARATOR)]
    try:
        chosen = select_cells(STANDARD_TABLE, names).cells
    except ConfigError as error:
        raise ConfigError(f"nao-walk: world_cells: {error}") from None
    return tuple(
        STANDARD_TABLE.cells.index(cell) for cell in chosen for _ in range(names.count(cell.name))
    )


def _cell_durations(
    cell_durations: str, world_cells: tuple[int, ...], lock: float
) -> dict[int, float]:
    """The durations cell_durations gives, by cell index; ConfigError for an entry that is no
    'NAME=SECONDS', a cell world_cells does not draw, or a walk no longer than the lock."""
    if not cell_durations:
        return {}
    durations: dict[int, float] = {}
    drawn = {STANDARD_TABLE.cells[cell].name: cell for cell in world_cells}
    for entry in cell_durations.split(CELL_SEPARATOR):
        name, _, seconds = (part.strip() for part in entry.rpartition("="))
        try:
            duration = float(seconds)
        except ValueError:
            duration = math.nan
        if not name or not lock < duration < math.inf:
            raise ConfigError(
                f"nao-walk: cell_durations entry {entry.strip()!r}: expected 'NAME=SECONDS' "
                f"with SECONDS more than the lock ({lock:g} s), e.g. 'latency 1=15'"
            )
        if name not in drawn:
            raise ConfigError(
                f"nao-walk: cell_durations names {name!r}, which world_cells does not draw; "
                f"accepted: {', '.join(drawn) or 'none (set worlds and world_cells first)'}"
            )
        durations[drawn[name]] = duration
    return durations


class NaoWalk(Problem):
    """The paper's task on one physics backend (or several, scored by engine_score). With noise
    0 the seed is not used; with noise > 0 it draws the episode's Disturbance. Either way
    (x, seed) gives the same episode in any process."""

    sense = Sense.MAXIMIZE
    key_metrics = ("distance", "drift", "speed", "time_walked", "fell")

    def __init__(
        self,
        backend: str = "mujoco",
        controller: str = "paper",
        fitness: str = "robust",
        duration: float = 15.0,
        lock: float = 3.0,
        substeps: int = 0,
        friction: float = 0.0,
        friction_scale: float = 1.0,
        slip: float = 5e-3,
        servo_gain: float = 10.0,
        weight_scale: float = 1.0,
        fall_height: float = 0.25,
        fall_tilt: float = 60.0,
        noise: float = 0.0,
        mass_scale: float = 1.0,
        push: float = 0.0,
        push_direction: float = 0.0,
        push_time: float = 6.0,
        latency: int = 0,
        measure_flight: bool = False,
        flight_penalty: float = 0.0,
        flight_allowed: float = FLIGHT_ALLOWED,
        worlds: str = "none",
        world_cells: str = "",
        cell_durations: str = "",
        engine_score: str = "worst",
        engine_cap: float = 0.0,
        screen_engines: str = "",
    ) -> None:
        """Check every parameter up front (a one-line ConfigError, not a failure in every
        evaluation) and keep them; each engine is built on first use."""
        #: every parameter, to build the perturbed worlds from (worlds=standard)
        self._params = {k: v for k, v in locals().items() if k not in ("self", "__class__")}
        if lock >= duration:
            raise ConfigError(
                f"nao-walk: lock ({lock} s) must be shorter than duration ({duration} s)"
            )
        if push:
            _check_push_time(push_time, lock, duration)
        self.engines = engine_names(backend)
        #: ConfigError for an engine that is not installed, listing the installed ones
        self.backend_infos = {name: registry().physics_backend(name) for name in self.engines}
        if len(self.backend_infos) < len(self.engines):
            raise ConfigError(f"nao-walk: backend {backend!r} names an engine twice")
        #: each engine's physics settings (they differ in the default friction only)
        self.physics_on: dict[str, PhysicsSettings] = {}
        for name, info in self.backend_infos.items():
            mu = (friction or info.default_friction) * friction_scale
            if mu > info.max_friction:
                raise ConfigError(
                    f"nao-walk: friction {mu} is more than the {name} backend handles "
                    f"(at most {info.max_friction}); use a smaller one or another backend"
                )
            _check_noisy_friction(name, mu, noise, info.max_friction)
            self.physics_on[name] = PhysicsSettings(
                substeps=substeps, servo_gain=servo_gain, friction=mu, slip=slip
            )
        _require_choice("controller", controller, CONTROLLERS)
        if weight_scale != 1.0 and controller != "paper":
            raise ConfigError(
                f"nao-walk: weight_scale widens the paper controller's Table 2 bounds; with "
                f"controller={controller!r} leave it at 1"
            )
        self.controller = controller
        kind = CONTROLLER_KINDS[controller]
        self.space = cpg_space(weight_scale) if controller == "paper" else kind.space()
        _require_choice("fitness", fitness, FITNESS_KINDS)
        self.fitness_kind = fitness
        #: the first engine's physics settings
        self.physics = self.physics_on[self.engines[0]]
        shove = Push(push, push_direction, push_time) if push else None
        self.episode = EpisodeSettings(
            duration, lock, fall_height, fall_tilt, shove, latency,
            measure_flight or flight_penalty > 0,
        )  # fmt: skip
        self.flight_penalty = flight_penalty
        self.flight_allowed = flight_allowed
        self.noise = noise
        self.robot = nao().with_mass_scale(mass_scale) if mass_scale != 1 else nao()
        self._limits = {hinge.name: (hinge.lower, hinge.upper) for hinge in self.robot.hinges}
        self._runners: dict[str, EpisodeRunner] = {}
        _require_choice("worlds", worlds, WORLDS)
        if worlds == "pushes":
            _check_push_window(push, lock, duration)
        self.worlds = worlds
        _require_choice("engine_score", engine_score, ENGINE_SCORES)
        self.engine_score = engine_score
        self.engine_cap = engine_cap
        self.screen_engines = self._screen_engines(screen_engines)
        #: the standard table's cells an evaluation's seed draws from (none: its own world)
        self.world_cells = _cell_indices(world_cells, worlds)
        #: the cells walked for another duration than this problem's, by index
        self.cell_durations = _cell_durations(cell_durations, self.world_cells, lock)
        self._worlds: dict[int, NaoWalk] = {}
        for cell in self.world_cells:
            try:
                self._world(cell).close()  # a world refusing its parameters says so now
            except ConfigError as error:  # naming the cell: its parameters are not the given
                reason = str(error).removeprefix("nao-walk: ")
                raise ConfigError(
                    f"nao-walk: in the cell {STANDARD_TABLE.cells[cell].name!r} that "
                    f"worlds={worlds} draws: {reason}"
                ) from None
            del self._worlds[cell]

    def _screen_engines(self, given: str) -> tuple[str, ...]:
        """The engines a screen walks on, in the backend's order (none: no screen)."""
        if not given:
            if len(self.engines) < 2 or SLOWEST_ENGINE not in self.engines:
                return ()
            return tuple(engine for engine in self.engines if engine != SLOWEST_ENGINE)
        named = engine_names(given)
        if not set(named) < set(self.engines):
            raise ConfigError(
                f"nao-walk: screen_engines {given!r} must name some of the backend's engines "
                f"({'+'.join(self.engines)}), not all of them"
            )
        return tuple(engine for engine in self.engines if engine in named)

    @property
    def screens(self) -> bool:
        """With several engines scored by the worst: their worst on screen_engines bounds it."""
        return self.engine_score == "worst" and bool(self.screen_engines)

    @property
    def runner(self) -> EpisodeRunner:
        """The episode runner on the first (for one backend: the only) engine."""
        return self.runner_on(self.engines[0])

    def prepare(self) -> None:
        """Import every engine and build its model (once per process)."""
        for engine in self.engines:
            self.runner_on(engine)

    def runner_on(self, engine: str) -> EpisodeRunner:
        """The episode runner on one of this problem's engines, built on first use (once per
        process)."""
        runner = self._runners.get(engine)
        if runner is None:
            backend = self.backend_infos[engine].factory(self.robot, self.physics_on[engine])
            runner = self._runners[engine] = EpisodeRunner(backend, self.episode)
        return runner

    def gait(self, x: np.ndarray) -> Gait:
        """The controller for decision vector x (space order)."""
        return CONTROLLER_KINDS[self.controller].build([float(v) for v in x], self._limits)

    def disturbance(self, seed: int, engine: str | None = None) -> Disturbance | None:
        """The episode conditions seed draws at this problem's noise (None when noise is 0)
        on engine (default: the first); engines differ only in their nominal friction."""
        if self.noise == 0:
            return None
        friction = self.physics_on[engine or self.engines[0]].friction
        return Disturbance.draw(self.noise, seed, friction, self.runner.walk_steps)

    def world_of(self, seed: int) -> int | None:
        """The standard table's cell an evaluation with seed walks in, drawn from world_cells
        by its own stream of the seed, apart from the noise's; None where it walks in its own
        world (no world_cells)."""
        if not self.world_cells:
            return None
        draw = np.random.default_rng((seed, 1)).integers(len(self.world_cells))
        return self.world_cells[int(draw)]

    def drawn_push(self, seed: int) -> Push:
        """The push an evaluation with seed walks with (worlds=pushes, unless its cell pushes
        by itself): the table's impulse, its
        direction and time drawn from their own stream of the seed, apart from the noise's and
        the cell's."""
        rng = np.random.default_rng((seed, 2))
        direction = float(rng.uniform(-180.0, 180.0))
        earliest = self.episode.lock + PUSH_AFTER_S
        time = float(rng.uniform(earliest, self.episode.duration - PUSH_BEFORE_END_S))
        return Push(PUSH_IMPULSE, direction, time)

    def _world(self, cell: int) -> NaoWalk:
        """The problem of one cell of the standard table, built on first use (walking the
        cell's own duration where cell_durations gives one)."""
        world = self._worlds.get(cell)
        if world is None:
            params = STANDARD_TABLE.cells[cell].apply({**self._params, **UNSAMPLED})
            duration = self.cell_durations.get(cell)
            if duration is not None:  # the same cap per second walked
                walking = (duration - params["lock"]) / (params["duration"] - params["lock"])
                params.update(duration=duration, engine_cap=params["engine_cap"] * walking)
            world = self._worlds[cell] = NaoWalk(**params)
        return world

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        return self._in_drawn_world(seed, lambda walk, push: walk._evaluate(x, seed, push))

    def screen(self, x: np.ndarray, seed: int) -> Evaluation:
        """x walked on the screen engines alone: the worst there is no worse than the worst on
        every engine."""
        return self._in_drawn_world(
            seed, lambda walk, push: walk._evaluate(x, seed, push, walk.screen_engines)
        )

    def complete(self, x: np.ndarray, seed: int, screened: Evaluation) -> Evaluation:
        """x walked on the engines its screen left out, scored with the screen's walks (read
        back from its per-engine metrics): the same Evaluation as ``evaluate``."""
        walked = {engine: _engine_evaluation(screened.metrics, engine)
                  for engine in self.screen_engines}  # fmt: skip
        return self._in_drawn_world(
            seed, lambda walk, push: walk._evaluate(x, seed, push, walked=walked)
        )

    def _in_drawn_world(
        self, seed: int, walk_in: Callable[[NaoWalk, Push | None], Evaluation]
    ) -> Evaluation:
        """walk_in(world, push) for the world and push seed draws, with what was drawn added
        to its metrics."""
        cell, walk = self._drawn_world(seed)
        push = self._push_of(walk, seed)
        evaluation = walk_in(walk, push)
        drawn: dict[str, float] = {}
        if cell is not None:
            drawn["world"] = float(cell)
        if push is not None:
            drawn.update(push_direction=push.direction, push_time=push.time)
        return Evaluation(evaluation.fitness, {**evaluation.metrics, **drawn})

    def _drawn_world(self, seed: int) -> tuple[int | None, NaoWalk]:
        """The cell seed draws (None: none drawn) and the problem that walks in it (this one
        where none is drawn)."""
        cell = self.world_of(seed)
        return cell, self if cell is None else self._world(cell)

    def _push_of(self, walk: NaoWalk, seed: int) -> Push | None:
        """The push seed draws with worlds=pushes, unless the world it walks in (walk: a
        cell's, or this one) pushes by its own settings, as the table's push cells do; None
        otherwise: that world's own push, or none."""
        if self.worlds != "pushes" or walk.episode.push is not None:
            return None
        return self.drawn_push(seed)

    def _evaluate(
        self, x: np.ndarray, seed: int, push: Push | None = None,
        engines: tuple[str, ...] = (), walked: Mapping[str, Evaluation] | None = None,
    ) -> Evaluation:  # fmt: skip
        """x's evaluation on ``engines`` (default: every engine), scored by engine_score;
        ``push`` replaces the settings' push; ``walked`` holds engines' evaluations already
        made (a screen's)."""
        gait = self.gait(x)
        if len(self.engines) == 1:
            return self._evaluate_on(self.engines[0], gait, seed, push=push)
        cap = self.engine_cap or math.inf
        walked = walked or {}
        on_engine = {
            engine: walked.get(engine) or self._evaluate_on(engine, gait, seed, cap, push)
            for engine in engines or self.engines
        }
        worst = min(on_engine.values(), key=lambda evaluation: evaluation.fitness)
        metrics = dict(worst.metrics)
        for engine, evaluation in on_engine.items():
            for name, value in evaluation.metrics.items():
                metrics[f"{name}@{engine}"] = value
            metrics[f"{FITNESS_METRIC}@{engine}"] = evaluation.fitness
        scores = [e.fitness for e in on_engine.values()]
        if self.engine_score == "mean":
            return Evaluation(float(np.mean(scores)), metrics)
        return Evaluation(min(scores), metrics)

    def _evaluate_on(
        self, engine: str, gait: Gait, seed: int, cap: float = math.inf, push: Push | None = None
    ) -> Evaluation:
        runner = self.runner_on(engine)
        result = runner.run(gait, disturbance=self.disturbance(seed, engine), push=push)
        value = fitness(
            result, self.fitness_kind, self.episode.duration, self.flight_penalty, cap,
            self.flight_allowed,
        )  # fmt: skip
        return Evaluation(value, result.metrics())

    def walked(self, seed: int) -> tuple[NaoWalk, Disturbance | None, Push | None]:
        """Where an evaluation with seed walks: the problem whose runner it uses (the seed's
        cell's, where it draws one), its disturbance, and its push (None: the settings')."""
        _, walk = self._drawn_world(seed)
        return walk, walk.disturbance(seed), self._push_of(walk, seed)

    def figures(self, x: np.ndarray, seed: int) -> dict[str, Figure]:
        """The paper's Figs. 6-10 of candidate x's walk on the first engine (figures.py), in the
        world its evaluation with seed walked."""
        from .figures import walk_figures  # matplotlib only when drawing

        walk, disturbance, push = self.walked(seed)
        result = walk.runner.run(walk.gait(x), record=True, disturbance=disturbance, push=push)
        return walk_figures(result, self.engines[0])

    def video(
        self,
        x: np.ndarray,
        seed: int,
        frame: Callable[[np.ndarray], None],
        size: tuple[int, int],
        fps: int,
    ) -> None:
        """Film candidate x's walk on the first engine, the camera following it (video.py), in
        the world its evaluation with seed walked."""
        walk, disturbance, push = self.walked(seed)
        film(walk.runner, walk.gait(x), disturbance, frame, size, fps, push)

    def close(self) -> None:
        while self._runners:
            _, runner = self._runners.popitem()
            runner.backend.close()
        while self._worlds:
            _, world = self._worlds.popitem()
            world.close()

    def __getstate__(self) -> dict[str, Any]:
        # Engines do not pickle; each process builds its own on first use.
        return {**self.__dict__, "_runners": {}, "_worlds": {}}


def _engine_evaluation(metrics: Mapping[str, float], engine: str) -> Evaluation:
    """One engine's Evaluation, read back from a several-engine evaluation's metrics."""
    suffix = f"@{engine}"
    own = {name.removesuffix(suffix): value for name, value in metrics.items()
           if name.endswith(suffix)}  # fmt: skip
    return Evaluation(own.pop(FITNESS_METRIC), own)


def _stored_gaits() -> dict[str, StoredCandidate]:
    from .stored_gaits import stored_candidates  # stored_gaits imports this module

    return stored_candidates()


@hookimpl
def metaopt_problems() -> list[ProblemInfo]:
    """Announce nao-walk."""
    return [
        ProblemInfo(
            name="nao-walk",
            summary="NAO biped walking with a Matsuoka CPG (the paper's task), MuJoCo, PyBullet "
            "or ODE",
            factory=NaoWalk,
            params=PARAMS,
            description=(
                "Tune the 10 parameters of a two-neuron Matsuoka CPG (tau1, tau2, alpha, beta, "
                "gamma, c, w11, w12, b1, b2) so the classic rcssserver3d NAO walks straight: "
                "15 s episodes, 3 s lock phase, 50 Hz control, fitness X - |Y| with a fall "
                "penalty; controller=extended, stride or steered tunes a richer CPG instead. See "
                "docs/nao-walk.md."
            ),
            default_budget=750,
            perturbations=STANDARD_TABLE,
            stored_candidates=_stored_gaits,
        )
    ]
