"""Uniform random sampling of the space (optimizer ``random``): the baseline to beat."""

from __future__ import annotations

from typing import Any

import numpy as np

from metaopt import (
    Optimizer,
    OptimizerInfo,
    Space,
    budget_param,
    hookimpl,
    population_param,
    restore_rng,
    rng_state,
)


class RandomSearch(Optimizer):
    """Every candidate is drawn uniformly inside the bounds, independently of all results."""

    # Results change nothing, so they may come back one at a time and in any order.
    steady_state = True

    def __init__(self, space: Space, seed: int, *, batch_size: int, budget: int) -> None:
        # Sampling has no schedule: the budget every optimizer is given changes nothing here.
        super().__init__(space, seed)
        self._batch_size = batch_size

    @property
    def batch_size(self) -> int:
        """The batch_size parameter."""
        return self._batch_size

    def ask(self, n: int) -> np.ndarray:
        """n uniform samples."""
        return self.space.sample(self.rng, n)

    def tell(self, candidates: np.ndarray, fitnesses: np.ndarray) -> None:
        """Nothing to learn: sampling ignores results."""

    def state_dict(self) -> dict[str, Any]:
        """Only the random generator."""
        return {"rng": rng_state(self.rng)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what state_dict returned."""
        restore_rng(self.rng, state["rng"])


@hookimpl
def metaopt_optimizers() -> list[OptimizerInfo]:
    """Random search."""
    return [
        OptimizerInfo(
            name="random",
            summary="Uniform random sampling inside the bounds (baseline)",
            factory=RandomSearch,
            params=(
                population_param("batch_size", 100, "candidates asked for at once"),
                budget_param(),
            ),
            description=__doc__,
        )
    ]
