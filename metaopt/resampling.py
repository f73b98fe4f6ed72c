"""How a resampled candidate's fitness and metrics combine over its samples (``--aggregate``)."""

from __future__ import annotations

import statistics
from collections.abc import Callable, Sequence

AGGREGATES: dict[str, Callable[[Sequence[float]], float]] = {
    "mean": statistics.fmean,
    "median": statistics.median,
}


def aggregate_samples(
    fitnesses: Sequence[float], metrics: Sequence[dict[str, float]], aggregate: str
) -> tuple[float, dict[str, float]]:
    """(fitness, metrics) of a candidate from its samples' values: one sample is taken as it
    is; several combine by ``aggregate``, metrics only where every sample has them."""
    if len(fitnesses) == 1:
        return fitnesses[0], dict(metrics[0])
    combine = AGGREGATES[aggregate]
    combined = {
        name: combine([m[name] for m in metrics])
        for name in metrics[0]
        if all(name in m for m in metrics)
    }
    return combine(fitnesses), combined
