"""scripts/engine_transfer.py: how often a gait walking on one engine walks on another, read
from a real run store's multi-engine evaluations."""

from __future__ import annotations

import numpy as np
import pytest

from metaopt.storage.run_store import RunStore
from metaopt_problems.nao_walk.gait_agreement import transfer_rates
from tests.conftest import load_script, metaopt_cli


@pytest.fixture(scope="module")
def transfer():
    return load_script("scripts/engine_transfer.py")


def test_rates_are_the_share_of_walkers_on_one_engine_that_walk_on_another() -> None:
    distance = np.array([[5.0, 5.0, 1.0], [5.0, 1.0, 5.0], [5.0, 5.0, 5.0], [1.0, 5.0, 5.0]])
    fell = np.array([[0, 0, 0], [0, 0, 0], [0, 1, 0], [0, 0, 0]])
    rates = transfer_rates(distance, fell, 4.0)
    # Walking 4 m without a fall: engine 0 in episodes 0-2, engine 1 in 0 and 3 (it fell in
    # 2), engine 2 in 1-3.
    assert np.diag(rates).tolist() == [3, 2, 3]
    assert rates[0, 1] == pytest.approx(1 / 3) and rates[0, 2] == pytest.approx(2 / 3)
    assert rates[1, 0] == 0.5 and rates[1, 2] == 0.5
    assert rates[2, 0] == pytest.approx(2 / 3) and rates[2, 1] == pytest.approx(1 / 3)
    assert np.isnan(transfer_rates(distance, fell, 9.0)[0, 1])  # nobody walks 9 m


def test_the_store_is_read_back_per_engine(tmp_path, transfer) -> None:
    """A real two-engine run's evaluations come back as one row per episode, in the engines'
    order; a one-engine run beside it in the store is left out."""
    short = ["--set", "duration=2", "--set", "lock=0.5", "--seed", "1", "--db", "runs.db"]
    for backend, budget in (("mujoco+ode", "3"), ("mujoco", "2")):
        done = metaopt_cli("run", "-o", "random", "-p", "nao-walk", "--budget", budget,
                           "--set", f"backend={backend}", *short, cwd=tmp_path)  # fmt: skip
        assert done.returncode == 0, done.stderr
    distance, fell = transfer.walked([tmp_path / "runs.db"], ["mujoco", "ode"])
    assert distance.shape == fell.shape == (3, 2)
    assert set(np.unique(fell)) <= {0.0, 1.0} and np.all(np.abs(distance) < 2.0)
    with RunStore(tmp_path / "runs.db") as store:
        first = next(store.evaluations(store.runs()[0].id)).metrics
    assert distance[0].tolist() == [first["distance@mujoco"], first["distance@ode"]]
