"""Every installed optimizer and problem passes the conformance kit, one test per check.

The tests are generated from the plugin registry, so a newly installed plugin is checked without
touching this file.
"""

from __future__ import annotations

import importlib.metadata
import os
import subprocess
import sys

import pytest

from metaopt.plugins import ENTRY_POINT_GROUP, LOAD_PLUGINS_ENV, registry
from metaopt.testing import optimizer_checks, problem_checks

PLUGINS = registry()


def _problem_settings() -> list[tuple[str, str, dict]]:
    """(test label, problem, parameters) per installed problem; robot episodes kept short."""
    settings = []
    for name in PLUGINS.problems:
        if name == "nao-walk":
            settings += [
                (f"{name}-{backend}", name, {"duration": 2.0, "lock": 1.0, "backend": backend})
                for backend, info in PLUGINS.physics_backends.items()
                if not info.unavailable
            ]
        else:
            settings.append((name, name, {}))
    return settings


def _optimizer_cases() -> list:
    return [
        pytest.param(check, id=f"{name}-{check_name}")
        for name in PLUGINS.optimizers
        for check_name, check in optimizer_checks(name).items()
    ]


def _problem_cases() -> list:
    return [
        pytest.param(check, id=f"{label}-{check_name}")
        for label, name, params in _problem_settings()
        for check_name, check in problem_checks(name, params, in_subprocess=True).items()
    ]


def test_every_installed_plugin_is_in_the_registry():
    if os.environ.get(LOAD_PLUGINS_ENV) is not None:
        pytest.skip(f"{LOAD_PLUGINS_ENV} limits which plugins load")
    installed = {e.name for e in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}
    assert installed <= set(PLUGINS.sources)
    assert {"hs", "ga", "random"} <= set(PLUGINS.optimizers)
    assert {"sphere", "rastrigin", "rosenbrock", "nao-walk"} <= set(PLUGINS.problems)


@pytest.mark.parametrize("check", _optimizer_cases())
def test_optimizer_conforms(check):
    check()


@pytest.mark.parametrize("check", _problem_cases())
def test_problem_conforms(check):
    check()


def test_the_outside_example_plugin_conforms_by_registered_name(outside_plugin_path, tmp_path):
    code = (
        "from metaopt.testing import check_optimizer, check_problem; "
        "check_optimizer('hill-climb'); check_problem('bowl', params={'dim': 3})"
    )
    result = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(outside_plugin_path)},
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
