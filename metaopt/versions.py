"""Versions of metaopt, Python and the libraries a run depended on (stored with each run)."""

from __future__ import annotations

import importlib.metadata
import platform

_DISTRIBUTIONS = ("metaopt", "numpy", "pluggy", "click", "rich", "mujoco", "pybullet")


def environment_versions(extra: tuple[str, ...] = ()) -> dict[str, str]:
    """{name: version} for Python, the platform and the installed distributions that matter."""
    versions = {"python": platform.python_version(), "platform": platform.platform()}
    for name in (*_DISTRIBUTIONS, *extra):
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return versions
