"""A run's recommendation (``RUN:recommended``): the point its optimizer, rebuilt from the run's
last checkpoint, would answer with beside its best evaluated candidate (CMA-ES: the mean of its
distribution). It was never evaluated by the run, so it is tested, replayed or started from
like any candidate, without a score of its own."""

from __future__ import annotations

import numpy as np

from metaopt.errors import ConfigError
from metaopt.params import resolve
from metaopt.space import Space
from metaopt.storage.run_store import RunRecord

#: What follows ``RUN:`` to name a run's recommendation rather than one of its candidates.
RECOMMENDED = "recommended"


def recommended_point(run: RunRecord) -> np.ndarray:
    """The recommendation of ``run``'s optimizer in the state of its last checkpoint;
    ConfigError saying what to name instead where there is none."""
    from metaopt.plugins import registry

    info = registry().optimizer(run.optimizer)
    state = (run.checkpoint or {}).get("state")
    if state is None:
        raise ConfigError(
            f"run {run.id} has no optimizer state to recommend from (it stopped before its "
            f"first checkpoint); name its best evaluated candidate instead: {run.id}"
        )
    params = resolve(info.params, run.optimizer_params, info.name)
    optimizer = info.factory(Space.from_json(run.space), run.seed, **params)
    optimizer.load_state_dict(state)
    point = optimizer.recommendation()
    if point is None:
        raise ConfigError(
            f"run {run.id}'s optimizer {run.optimizer!r} recommends nothing beside its best "
            f"evaluated candidate: name that one ({run.id}); cmaes recommends its mean"
        )
    return np.asarray(point, dtype=float)
