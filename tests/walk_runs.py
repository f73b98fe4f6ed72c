"""Stored runs for the report and video tests: a short nao-walk run whose best candidate is the
stored Harmony Search gait, with one poor and one failed evaluation beside it."""

from __future__ import annotations

from pathlib import Path

from metaopt.plugins import registry
from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.stored_gaits import gait_vector, load_gait

#: A 3 s episode with a 1 s lock phase: 2 s (100 control steps) of walking.
SHORT_WALK = {"duration": 3.0, "lock": 1.0}


def store_walk_run(db: Path) -> int:
    """Write the run into the store at db; returns its id."""
    params = {**load_gait()["problem_params"], **SHORT_WALK}
    problem = registry().problem("nao-walk").factory(**params)
    gait = gait_vector(load_gait())
    with RunStore(db) as store:
        run_id = store.create_run(
            optimizer="hs", optimizer_params={}, problem="nao-walk", problem_params=params,
            seed=0, budget=3, sense="maximize", space=problem.space.to_json(), settings={},
            versions={},
        )  # fmt: skip
        for index, x in enumerate((problem.space.lower, gait)):
            evaluation = problem.evaluate(x, seed=index)
            store.add_evaluation(run_id, index, index, x, evaluation.fitness,
                                 evaluation.metrics, None, index, 0.1)  # fmt: skip
        store.add_evaluation(run_id, 2, 2, gait * 2, None, None, "diverged", 2, 0.1)
        store.finish_run(run_id, "finished", 1.0)
    problem.close()
    return run_id
