"""A real-coded genetic algorithm with elitist survival (optimizer ``ga``).

Each generation is ``population`` new candidates bred from the current population by tournament
selection, crossover (SBX or BLX-α) and per-gene mutation (``mutations`` genes per child on
average), then brought inside the bounds by ``Space.repair``. Mutation is ``two-scale`` by
default: polynomial steps, each either coarse (index ``eta_m``, to leave a basin) or fine (an
index rising over the budget, for the last digits); ``polynomial`` (coarse steps only) and
``gaussian`` (a shrinking normal step) are the alternatives. With ``survival`` plus (the default)
the best ``population`` of parents and offspring together form the next population; with
``elites`` the offspring do, but for the ``elites`` best parents, which pass unchanged and are not
evaluated again. A generation costs exactly ``population`` evaluations: the paper's setting, 10
generations of 200, is ``--set population=200 --set survival=elites`` with a budget of 2000.
docs/optimizers.md compares the defaults with pymoo's and DEAP's GAs.

Candidates may be asked for and told in batches of any size: told results accumulate until a
whole generation has been evaluated, and asks beyond the current generation are served by breeding
more offspring from the current population.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
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
    population_param,
    restore_rng,
    rng_state,
)
from metaopt.space import repair_param

Crossover = Callable[[np.ndarray, np.ndarray, np.random.Generator], tuple[np.ndarray, np.ndarray]]


def tournament_winners(fitness: np.ndarray, n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of n winners of size-k tournaments without replacement (lowest fitness wins).

    The population is shuffled and cut into groups of k, as often as needed (Goldberg, Korb &
    Deb 1989): no one meets itself, every member competes about equally often, and k equal to
    the population size always picks the best.
    """
    size = fitness.size
    groups_per_shuffle = size // k
    shuffles = -(-n // groups_per_shuffle)
    order = rng.permuted(np.tile(np.arange(size), (shuffles, 1)), axis=1)
    contestants = order[:, : groups_per_shuffle * k].reshape(-1, k)[:n]
    return contestants[np.arange(n), np.argmin(fitness[contestants], axis=1)]


def sbx(
    first: np.ndarray, second: np.ndarray, rng: np.random.Generator, eta: float
) -> tuple[np.ndarray, np.ndarray]:
    """Simulated binary crossover (Deb & Agrawal 1995) with distribution index eta, as Deb's own
    implementation does it: each gene is crossed with probability 1/2 (else copied), and the
    two children's genes are swapped with probability 1/2, so genes also mix as in a uniform
    crossover. Crossed genes are symmetric around the parents' mean, nearer the parents for a
    larger eta. Children may leave the bounds; the caller repairs them.
    """
    u = rng.random(first.shape)
    beta = np.where(u <= 0.5, 2.0 * u, 0.5 / (1.0 - u)) ** (1.0 / (eta + 1.0))
    crossed = rng.random(first.shape) < 0.5
    mean, half_spread = 0.5 * (first + second), 0.5 * beta * (second - first)
    low = np.where(crossed, mean - half_spread, first)
    high = np.where(crossed, mean + half_spread, second)
    swapped = rng.random(first.shape) < 0.5
    return np.where(swapped, high, low), np.where(swapped, low, high)


def blx(
    first: np.ndarray, second: np.ndarray, rng: np.random.Generator, alpha: float
) -> tuple[np.ndarray, np.ndarray]:
    """BLX-α crossover (Eshelman & Schaffer 1993): each child gene is uniform in the parents'
    interval widened by alpha times its length on both sides. The caller repairs the children.
    """
    low, high = np.minimum(first, second), np.maximum(first, second)
    margin = alpha * (high - low)
    low, span = low - margin, high - low + 2.0 * margin
    return low + rng.random(first.shape) * span, low + rng.random(first.shape) * span


def polynomial_mutation(
    x: np.ndarray,
    width: np.ndarray,
    rng: np.random.Generator,
    rate: float,
    eta: float | np.ndarray,
) -> np.ndarray:
    """Polynomial mutation (Deb & Goyal 1996): each gene, with probability rate, moves by at most
    one range width, small steps far likelier for a large eta (the mean step is 1/(eta + 2) of
    the width). eta is one index, or one per gene (an array of x's shape). The caller repairs
    the result.
    """
    u = rng.random(x.shape)
    exponent = 1.0 / (eta + 1.0)
    step = np.where(u < 0.5, (2.0 * u) ** exponent - 1.0, 1.0 - (2.0 * (1.0 - u)) ** exponent)
    return x + (rng.random(x.shape) < rate) * step * width


def gaussian_mutation(
    x: np.ndarray, width: np.ndarray, rng: np.random.Generator, rate: float, sigma: float
) -> np.ndarray:
    """Gaussian mutation: each gene, with probability rate, moves by a normal step whose standard
    deviation is sigma times its range width. The caller repairs the result.
    """
    step = rng.standard_normal(x.shape) * (sigma * width)
    return x + (rng.random(x.shape) < rate) * step


class GeneticAlgorithm(Optimizer):
    """Generational real-coded GA with elitism; see the module docstring for the scheme."""

    steady_state = False

    def __init__(
        self,
        space: Space,
        seed: int,
        *,
        population: int,
        elites: int,
        tournament: int,
        crossover: str,
        crossover_rate: float,
        eta_c: float,
        blx_alpha: float,
        mutation: str,
        mutations: float,
        eta_m: float,
        sigma: float,
        sigma_min: float,
        survival: str,
        budget: int,
        repair: str,
        eta_m_end: float,
        fine_share: float,
    ) -> None:
        super().__init__(space, seed)
        if survival == "elites" and elites >= population:  # plus survival keeps no elites
            raise ConfigError(
                f"ga parameter 'elites' = {elites} must be below 'population' = {population} "
                "with survival elites"
            )
        if tournament > population:
            raise ConfigError(
                f"ga parameter 'tournament' = {tournament} cannot exceed "
                f"'population' = {population}"
            )
        if sigma_min > sigma:
            raise ConfigError(f"ga parameter 'sigma_min' = {sigma_min} must not exceed 'sigma'")
        if mutation == "two-scale" and eta_m_end < eta_m:
            raise ConfigError(
                f"ga parameter 'eta_m_end' = {eta_m_end} must not be below 'eta_m' = {eta_m}: "
                "two-scale's fine steps must not be coarser than its coarse ones"
            )
        self.population_size = population
        self.elites = elites
        self.tournament_size = tournament
        self.crossover_rate = crossover_rate
        self.repair_method = repair
        self.survival = survival
        self.budget = budget
        self.mutation_rate = min(1.0, mutations / space.dim)
        self.mutation_kind = mutation
        self.eta_m, self.eta_m_end, self.fine_share = eta_m, eta_m_end, fine_share
        self.sigma, self.sigma_min = sigma, sigma_min
        self.crossover: Crossover = (
            partial(sbx, eta=eta_c) if crossover == "sbx" else partial(blx, alpha=blx_alpha)
        )
        empty = np.empty((0, space.dim))
        #: The current population and its fitness; None until the first generation is told.
        self.members: np.ndarray | None = None
        self.fitness: np.ndarray | None = None
        #: Bred candidates not yet asked for.
        self.queue = empty
        #: Evaluated offspring of the generation being completed.
        self.offspring, self.offspring_fitness = empty, np.empty(0)
        #: Generations fully evaluated (the random initial population is the first).
        self.generations = 0
        #: Evaluations told so far (the mutation schedules span the budget).
        self.told = 0

    def budget_warning(self, candidates: int) -> str | None:
        """A budget within the random first generation breeds nothing."""
        if candidates > self.population_size:
            return None
        return (
            f"population {self.population_size} is not smaller than the budget's {candidates} "
            "candidates: the run evaluates only the random first generation, none is bred "
            "(lower population or raise --budget)"
        )

    @property
    def batch_size(self) -> int:
        """One generation."""
        return self.population_size

    def ask(self, n: int) -> np.ndarray:
        """The next n candidates of the current generation, breeding more when it runs out."""
        while len(self.queue) < n:
            self.queue = np.concatenate([self.queue, self._breed(self.population_size)])
        asked, self.queue = self.queue[:n], self.queue[n:]
        return asked

    def tell(self, candidates: np.ndarray, fitnesses: np.ndarray) -> None:
        """Collect evaluated offspring; each full generation's worth replaces the population."""
        fitnesses = np.asarray(fitnesses, dtype=float)
        self.told += len(fitnesses)
        self.offspring = np.concatenate([self.offspring, np.asarray(candidates, dtype=float)])
        self.offspring_fitness = np.concatenate(
            [self.offspring_fitness, np.where(np.isnan(fitnesses), np.inf, fitnesses)]
        )
        size = self.population_size
        while len(self.offspring) >= size:
            self._replace(self.offspring[:size], self.offspring_fitness[:size])
            self.offspring, self.offspring_fitness = (
                self.offspring[size:],
                self.offspring_fitness[size:],
            )

    def _breed(self, n: int) -> np.ndarray:
        """n new candidates: uniform at first, then selection, crossover, mutation, repair."""
        if self.members is None:
            return self.space.sample(self.rng, n)
        pairs = -(-n // 2)
        winners = self.members[
            tournament_winners(self.fitness, 2 * pairs, self.tournament_size, self.rng)
        ]
        first, second = winners[:pairs], winners[pairs:]
        child_a, child_b = self.crossover(first, second, self.rng)
        crossed = (self.rng.random(pairs) < self.crossover_rate)[:, None]
        children = np.concatenate(
            [np.where(crossed, child_a, first), np.where(crossed, child_b, second)]
        )[:n]
        width, rate = self.space.width, self.mutation_rate
        if self.mutation_kind == "gaussian":
            mutated = gaussian_mutation(children, width, self.rng, rate, self.sigma_at(self.told))
        else:
            eta = self._mutation_index(children.shape)
            mutated = polynomial_mutation(children, width, self.rng, rate, eta)
        return self.space.repair(mutated, self.repair_method)

    def _progress(self, told: int) -> float:
        """The share of the budget told, at most 1: the schedules stay at their end past it."""
        return min(told / self.budget, 1.0)

    def sigma_at(self, told: int) -> float:
        """Gaussian step (fraction of the range) after ``told`` evaluations: from sigma at the
        start to sigma_min at the budget, exponentially (wide search first, fine steps last)."""
        return self.sigma * (self.sigma_min / self.sigma) ** self._progress(told)

    def fine_eta_at(self, told: int) -> float:
        """two-scale's fine index after ``told`` evaluations: eta + 2 grows exponentially from
        eta_m + 2 at the start to eta_m_end + 2 at the budget, so that the mean fine step,
        1/(eta + 2) of the range, shrinks exponentially like the gaussian one."""
        start, end = self.eta_m + 2.0, self.eta_m_end + 2.0
        return start * (end / start) ** self._progress(told) - 2.0

    def _mutation_index(self, shape: tuple[int, ...]) -> float | np.ndarray:
        """The polynomial index of each gene of children of ``shape``: eta_m for ``polynomial``;
        for ``two-scale`` the fine index with probability fine_share, else eta_m. The coarse
        steps move genes between basins all run long; the fine ones, once the population has
        closed in, make useful children where a coarse step would throw the child out of the
        basin. (An index rising for every gene refines as well but ends those moves: it left 9
        of 11 runs on the 10-variable Rastrigin in a local minimum, docs/optimizers.md.)"""
        if self.mutation_kind == "polynomial":
            return self.eta_m
        fine = self.rng.random(shape) < self.fine_share
        return np.where(fine, self.fine_eta_at(self.told), self.eta_m)

    def _replace(self, offspring: np.ndarray, fitness: np.ndarray) -> None:
        """Make a new population: the old one's elites plus the best of the offspring."""
        if self.members is None:
            self.members, self.fitness = offspring, fitness
        elif self.survival == "plus":
            merged = np.concatenate([self.members, offspring])
            merged_fitness = np.concatenate([self.fitness, fitness])
            kept = np.argsort(merged_fitness, kind="stable")[: self.population_size]
            self.members, self.fitness = merged[kept], merged_fitness[kept]
        else:
            elite = np.argsort(self.fitness, kind="stable")[: self.elites]
            kept = np.argsort(fitness, kind="stable")[: self.population_size - self.elites]
            self.members = np.concatenate([self.members[elite], offspring[kept]])
            self.fitness = np.concatenate([self.fitness[elite], fitness[kept]])
        # Offspring still queued were bred from the population just replaced.
        self.queue = self.queue[:0]
        self.generations += 1

    def state_dict(self) -> dict[str, Any]:
        """Population, queue, partial generation, counters and generator as plain JSON."""
        return {
            "rng": rng_state(self.rng),
            "members": None if self.members is None else self.members.tolist(),
            "fitness": None if self.fitness is None else self.fitness.tolist(),
            "queue": self.queue.tolist(),
            "offspring": self.offspring.tolist(),
            "offspring_fitness": self.offspring_fitness.tolist(),
            "generations": self.generations,
            "told": self.told,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what state_dict returned."""
        dim = self.space.dim
        restore_rng(self.rng, state["rng"])
        if state["members"] is None:
            self.members = self.fitness = None
        else:
            self.members = np.array(state["members"], dtype=float).reshape(-1, dim)
            self.fitness = np.array(state["fitness"], dtype=float)
        self.queue = np.array(state["queue"], dtype=float).reshape(-1, dim)
        self.offspring = np.array(state["offspring"], dtype=float).reshape(-1, dim)
        self.offspring_fitness = np.array(state["offspring_fitness"], dtype=float)
        self.generations = int(state["generations"])
        # States saved before the told count existed: every generation was fully told.
        self.told = int(state.get("told", self.generations * self.population_size))


PARAMS = (
    population_param("population", 100, "candidates per generation", low=2),
    Param("elites", int, 2, "best members passed unchanged to the next generation", low=0),
    Param("tournament", int, 2, "tournament size k of parent selection", low=1),
    Param("crossover", str, "sbx", "crossover operator", choices=("sbx", "blx")),
    Param("crossover_rate", float, 0.9, "probability that two parents are crossed", low=0, high=1),
    Param("eta_c", float, 15.0, "sbx: distribution index (larger: children nearer parents)", low=0),
    Param("blx_alpha", float, 0.5, "blx: widening of the parents' interval on each side", low=0),
    Param(
        "mutation",
        str,
        "two-scale",
        "mutation operator: two-scale (polynomial, each mutated gene's index eta_m or, with "
        "probability fine_share, one rising from eta_m to eta_m_end over the budget), "
        "polynomial (index eta_m throughout: the default until two-scale came) or gaussian",
        choices=("two-scale", "polynomial", "gaussian"),
    ),
    Param(
        "mutations",
        float,
        1.0,
        "genes mutated per child on average: each gene mutates with probability "
        "mutations / dim (at most 1); 1 is the customary rate 1/dim, 0 turns mutation off",
        low=0,
    ),
    Param(
        "eta_m",
        float,
        20.0,
        "polynomial: distribution index (larger: smaller steps); two-scale: the coarse steps' "
        "index, and the fine steps' at the start",
        low=0,
    ),
    Param(
        "eta_m_end",
        float,
        1000.0,
        "two-scale: the fine steps' index at the budget's end (the mean fine step shrinks "
        "exponentially from 1/(eta_m + 2) to 1/(eta_m_end + 2) of the range)",
        low=0,
    ),
    Param(
        "fine_share",
        float,
        0.5,
        "two-scale: probability that a mutated gene takes a fine step rather than a coarse one",
        low=0,
        high=1,
    ),
    Param(
        "sigma",
        float,
        0.1,
        "gaussian: step deviation at the start, as a fraction of the range",
        low=0,
        low_open=True,
    ),
    Param(
        "sigma_min",
        float,
        0.001,
        "gaussian: step deviation at the budget's end (it shrinks exponentially from sigma)",
        low=0,
        low_open=True,
    ),
    Param(
        "survival",
        str,
        "plus",
        "plus: the best of parents and offspring form the next population; elites: the "
        "offspring do, but for the elites best parents",
        choices=("plus", "elites"),
    ),
    budget_param(),
    repair_param("how offspring outside the bounds are brought back: clip or reflect"),
)


@hookimpl
def metaopt_optimizers() -> list[OptimizerInfo]:
    """The genetic algorithm."""
    return [
        OptimizerInfo(
            name="ga",
            summary="Real-coded generational genetic algorithm with elitism",
            factory=GeneticAlgorithm,
            params=PARAMS,
            description=__doc__,
        )
    ]
