"""CMA-ES: the covariance matrix adaptation evolution strategy, (mu/mu_w, lambda) with rank-one
and rank-mu updates and cumulative step-size adaptation (Hansen and Ostermeier 2001; the
defaults of Hansen's 2016 tutorial, arXiv:1604.00772).

Each generation samples ``population`` (lambda) candidates from a normal distribution
N(m, sigma^2 C) in coordinates where every variable's range is [0, 1], brings those past a
bound back with ``Space.repair`` (``repair``), and moves m, sigma and C towards the better half
of them. It is the usual method for tuning a few dozen continuous parameters of a noisy,
rugged simulation, such as a gait's; metaopt's HS and GA are population samplers without a
learned step shape.

The first generation is metaopt's initial population: uniform random points in the bounds, or
a warm start's points (``--start-from``). The distribution then starts at their weighted
recombination (the mean of the better half, weighted as every later generation is) with step
``sigma0`` (a share of each range) and C = I. A warm start therefore starts CMA-ES at the
known point's neighbourhood; set ``sigma0`` to the spread you trust around it.

Every step that enters the update is the told candidate's, not the sampled one's: a repaired
candidate, one told from a warm start or one asked before the previous update moves the
distribution by what was evaluated. Such steps are shortened to at most sqrt(n) + 2n / (n + 2)
in the distribution's own metric (Hansen 2011, "Injecting external solutions into CMA-ES"),
which leaves ordinary samples alone. A batch that divides ``population`` (the default batch is
the population) gives the textbook algorithm; a generation is updated once ``population``
results have been told.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from metaopt import (
    ConfigError,
    Optimizer,
    OptimizerInfo,
    Param,
    Space,
    budget_param,
    hookimpl,
    json_float,
    population_param,
    restore_rng,
    rng_state,
)
from metaopt.space import repair_param


class StrategyConstants:
    """The learning rates and weights that follow from the dimension and the population size
    (the tutorial's defaults, Table 1)."""

    def __init__(self, dim: int, population: int) -> None:
        n = dim
        self.population = population
        self.parents = population // 2
        raw = math.log(self.parents + 0.5) - np.log(np.arange(1, self.parents + 1))
        self.weights = raw / raw.sum()
        self.mu_eff = 1.0 / float(np.sum(self.weights**2))
        mu_eff = self.mu_eff
        self.c_sigma = (mu_eff + 2.0) / (n + mu_eff + 5.0)
        self.d_sigma = (
            1.0 + 2.0 * max(0.0, math.sqrt((mu_eff - 1.0) / (n + 1.0)) - 1.0) + self.c_sigma
        )
        self.c_c = (4.0 + mu_eff / n) / (n + 4.0 + 2.0 * mu_eff / n)
        self.c_1 = 2.0 / ((n + 1.3) ** 2 + mu_eff)
        self.c_mu = min(
            1.0 - self.c_1, 2.0 * (mu_eff - 2.0 + 1.0 / mu_eff) / ((n + 2.0) ** 2 + mu_eff)
        )
        #: E||N(0, I)||, the length an unbiased evolution path has
        self.chi_n = math.sqrt(n) * (1.0 - 1.0 / (4.0 * n) + 1.0 / (21.0 * n * n))
        #: the longest step (in C's metric) an update takes from one candidate
        self.max_step = math.sqrt(n) + 2.0 * n / (n + 2.0)


def default_population(dim: int) -> int:
    """lambda = 4 + floor(3 ln n), the usual default."""
    return 4 + int(3.0 * math.log(dim))


class CMAES(Optimizer):
    """CMA-ES over the space scaled to the unit box; see the module docstring."""

    def __init__(
        self,
        space: Space,
        seed: int,
        *,
        population: int,
        sigma0: float,
        repair: str,
        budget: int,
    ) -> None:
        # CMA-ES has no schedule over the budget: its step adapts to what it finds.
        super().__init__(space, seed)
        if population == 1:
            raise ConfigError("cmaes: population must be 0 (the default) or at least 2, got 1")
        self.constants = StrategyConstants(space.dim, population or default_population(space.dim))
        self.repair = repair
        n = space.dim
        self.generation = 0  # updates made; 0: the first (uniform or warm-start) generation
        self.mean: np.ndarray | None = None  # unit-box coordinates, set by the first generation
        self.sigma = sigma0
        self.cov = np.eye(n)
        self.p_sigma = np.zeros(n)
        self.p_c = np.zeros(n)
        self._told_x: list[np.ndarray] = []  # this generation's results so far (unit box)
        self._told_f: list[float] = []
        self._decompose()

    @property
    def batch_size(self) -> int:
        """One generation: lambda candidates."""
        return self.constants.population

    @property
    def selected(self) -> int:
        """The update reads the better half (mu = lambda // 2) by rank; the others get no
        weight."""
        return self.constants.parents

    def budget_warning(self, candidates: int) -> str | None:
        """A run no longer than the first, uniform generation never uses the distribution."""
        if candidates <= self.constants.population:
            return (
                f"{candidates} candidates are no more than its first generation "
                f"({self.constants.population} uniform random points); give a budget of "
                "several generations"
            )
        return None

    # -- ask/tell -----------------------------------------------------------------------

    def ask(self, n: int) -> np.ndarray:
        """n samples of N(m, sigma^2 C), repaired into the bounds; uniform ones before the
        first generation has been told."""
        if self.mean is None:
            return self.space.sample(self.rng, n)
        normal = self.rng.standard_normal((n, self.space.dim))
        unit = self.mean + self.sigma * (normal * self._scales) @ self._axes.T
        return self.space.repair(self.space.lower + unit * self.space.width, self.repair)

    def tell(self, candidates: np.ndarray, fitnesses: np.ndarray) -> None:
        """Collect results; every ``population`` of them make one update."""
        for x, f in zip(np.atleast_2d(candidates), np.atleast_1d(fitnesses)):
            self._told_x.append((np.asarray(x, dtype=float) - self.space.lower) / self.space.width)
            self._told_f.append(float(f))
            if len(self._told_f) == self.constants.population:
                self._update(np.array(self._told_x), np.array(self._told_f))
                self._told_x, self._told_f = [], []

    def recommendation(self) -> np.ndarray | None:
        """The distribution's mean, clipped into the bounds; None before the first update."""
        if self.mean is None:
            return None
        return self.space.repair(self.space.lower + self.mean * self.space.width, "clip")

    # -- the update ---------------------------------------------------------------------

    def _update(self, unit_points: np.ndarray, fitnesses: np.ndarray) -> None:
        k = self.constants
        # A stable sort: equal fitnesses (failed evaluations: +inf) keep their order.
        best = unit_points[np.argsort(fitnesses, kind="stable")[: k.parents]]
        if self.mean is None:  # the first generation sets where the distribution starts
            self.mean = k.weights @ best
            self.generation = 1
            return
        steps = self._bounded((best - self.mean) / self.sigma)
        step = k.weights @ steps
        self.mean = self.mean + self.sigma * step
        whitened = self._axes @ self._eigen_coordinates(step)  # C^(-1/2) step
        self.p_sigma = (1.0 - k.c_sigma) * self.p_sigma + math.sqrt(
            k.c_sigma * (2.0 - k.c_sigma) * k.mu_eff
        ) * whitened
        path_length = float(np.linalg.norm(self.p_sigma))
        # p_sigma's variance if it had been fed unbiased steps: generation counts its updates,
        # this one included (the first generation only placed the mean).
        unbiased = path_length / math.sqrt(1.0 - (1.0 - k.c_sigma) ** (2 * self.generation))
        # Stall the rank-one path while the step size path is long (the tutorial's h_sigma).
        h_sigma = unbiased < (1.4 + 2.0 / (self.space.dim + 1.0)) * k.chi_n
        self.p_c = (1.0 - k.c_c) * self.p_c + h_sigma * math.sqrt(
            k.c_c * (2.0 - k.c_c) * k.mu_eff
        ) * step
        rank_one = np.outer(self.p_c, self.p_c) + (not h_sigma) * k.c_c * (2.0 - k.c_c) * self.cov
        rank_mu = (steps * k.weights[:, None]).T @ steps
        self.cov = (1.0 - k.c_1 - k.c_mu) * self.cov + k.c_1 * rank_one + k.c_mu * rank_mu
        self.cov = (self.cov + self.cov.T) / 2.0
        self.sigma *= math.exp((k.c_sigma / k.d_sigma) * (path_length / k.chi_n - 1.0))
        self.generation += 1
        self._decompose()

    def _bounded(self, steps: np.ndarray) -> np.ndarray:
        """Steps no longer than max_step in C's metric (Hansen 2011): repaired and injected
        candidates cannot throw the distribution off; samples are hardly ever shortened."""
        lengths = np.linalg.norm(self._eigen_coordinates(steps), axis=-1)
        factor = np.minimum(1.0, self.constants.max_step / np.maximum(lengths, 1e-300))
        return steps * factor[:, None]

    def _eigen_coordinates(self, steps: np.ndarray) -> np.ndarray:
        """D^-1 B^T y for a step y (or each row of a batch): its coordinates on C's axes, in
        units of each axis's scale; their norm is the step's length in C's metric."""
        return (steps @ self._axes) / self._scales

    def _decompose(self) -> None:
        """C = B diag(D^2) B^T, kept as the axes B and the scales D."""
        eigenvalues, self._axes = np.linalg.eigh(self.cov)
        self._scales = np.sqrt(np.maximum(eigenvalues, 1e-300))

    # -- state --------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Distribution, paths, the generation's results so far and the generator."""
        return {
            "rng": rng_state(self.rng),
            "generation": self.generation,
            "mean": None if self.mean is None else self.mean.tolist(),
            "sigma": self.sigma,
            "cov": self.cov.tolist(),
            "p_sigma": self.p_sigma.tolist(),
            "p_c": self.p_c.tolist(),
            "told_x": [x.tolist() for x in self._told_x],
            "told_f": [json_float(f) for f in self._told_f],
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what state_dict returned."""
        restore_rng(self.rng, state["rng"])
        self.generation = state["generation"]
        self.mean = None if state["mean"] is None else np.array(state["mean"], dtype=float)
        self.sigma = float(state["sigma"])
        self.cov = np.array(state["cov"], dtype=float)
        self.p_sigma = np.array(state["p_sigma"], dtype=float)
        self.p_c = np.array(state["p_c"], dtype=float)
        self._told_x = [np.array(x, dtype=float) for x in state["told_x"]]
        self._told_f = [float(f) for f in state["told_f"]]
        self._decompose()


PARAMS = (
    population_param(
        "population",
        0,
        "lambda, candidates per generation (0: 4 + floor(3 ln n): 10 for the paper's 10 CPG "
        "parameters, 12 for nao-walk's steered controller's 15)",
        low=0,
    ),
    Param(
        "sigma0",
        float,
        0.3,
        "initial step size, as a share of each variable's range (0.3 for a start anywhere in "
        "the box; about a warm start's --start-spread to search near it); at most 1, the "
        "whole range",
        low=0.0,
        low_open=True,
        high=1.0,
    ),
    repair_param("how candidates sampled past a bound come back: clip to it or reflect off it"),
    budget_param(),
)


@hookimpl
def metaopt_optimizers() -> list[OptimizerInfo]:
    """Announce CMA-ES."""
    return [
        OptimizerInfo(
            name="cmaes",
            summary="CMA-ES (Hansen and Ostermeier 2001), (mu/mu_w, lambda), the tutorial's "
            "defaults",
            factory=CMAES,
            params=PARAMS,
            description=__doc__ or "",
        )
    ]
