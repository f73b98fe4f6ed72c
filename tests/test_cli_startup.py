"""Every `metaopt` call pays its imports: the CLI and the plugin registry load no physics engine,
plotting, statistics or cluster library until a command uses one (scipy.stats alone took a
second of each call)."""

from __future__ import annotations

import subprocess
import sys

HEAVY = ("scipy", "matplotlib", "mujoco", "pybullet", "dask", "distributed")


def test_the_cli_and_the_registry_start_without_the_heavy_libraries() -> None:
    probe = (
        "import sys, metaopt.cli; from metaopt.plugins import registry; registry(); "
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=120
    ).stdout.strip()
    assert loaded == "[]"
