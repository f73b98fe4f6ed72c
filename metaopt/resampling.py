"""How a resampled candidate's fitness and metrics combine over its samples (``--aggregate``)."""

from __future__ import annotations

import statistics
from collections.abc import Callable, Sequence

AGGREGATES: dict[str, Callable[[Sequence[float]], float]] = {
    "mean": statistics.fmean,
    "median": statistics.median,
}


def aggregate_fitness(fitnesses: Sequence[float], aggregate: str) -> float:
    """A candidate's fitness from its samples': one sample as it is; several by ``aggregate``."""
    return fitnesses[0] if len(fitnesses) == 1 else AGGREGATES[aggregate](fitnesses)


def aggregate_metrics(metrics: Sequence[dict[str, float]], aggregate: str) -> dict[str, float]:
    """A candidate's metrics from its samples': one sample's as they are; several combine by
    ``aggregate``, only the metrics every sample has."""
    if len(metrics) == 1:
        return dict(metrics[0])
    combine = AGGREGATES[aggregate]
    return {
        name: combine([m[name] for m in metrics])
        for name in metrics[0]
        if all(name in m for m in metrics)
    }


def aggregate_samples(
    fitnesses: Sequence[float], metrics: Sequence[dict[str, float]], aggregate: str
) -> tuple[float, dict[str, float]]:
    """(fitness, metrics) of a candidate from its samples' values: one sample is taken as it
    is; several combine by ``aggregate``, metrics only where every sample has them."""
    return aggregate_fitness(fitnesses, aggregate), aggregate_metrics(metrics, aggregate)
