"""Finding plugins: the pluggy manager, entry-point loading and the name registries."""

from __future__ import annotations

import importlib.metadata
import os
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from types import ModuleType
from typing import Any

import pluggy

from metaopt import hookspecs
from metaopt.errors import ConfigError
from metaopt.params import suggest

ENTRY_POINT_GROUP = "metaopt"
#: Comma-separated entry-point names to load; unset loads all, empty loads none.
LOAD_PLUGINS_ENV = "METAOPT_LOAD_PLUGINS"


@dataclass(frozen=True)
class PluginSource:
    """Where a loaded plugin came from (for `metaopt list` and error messages)."""

    entry_point: str
    module: str
    distribution: str


class Registry:
    """Everything the loaded plugins announce, by kind and name."""

    def __init__(self, manager: pluggy.PluginManager, sources: dict[str, PluginSource]) -> None:
        self.manager = manager
        self.sources = sources
        self.optimizers = self._collect(manager.hook.metaopt_optimizers(), "optimizer")
        self.problems = self._collect(manager.hook.metaopt_problems(), "problem")
        self.physics_backends = self._collect(
            manager.hook.metaopt_physics_backends(), "physics backend"
        )

    @staticmethod
    def _collect(results: Iterable[list], kind: str) -> dict[str, Any]:
        found: dict[str, Any] = {}
        for infos in results:
            for info in infos:
                if info.name in found:
                    raise ConfigError(f"two plugins both provide the {kind} {info.name!r}")
                found[info.name] = info
        return dict(sorted(found.items()))

    def optimizer(self, name: str):
        """The OptimizerInfo called name, or a ConfigError with close matches."""
        return _lookup(self.optimizers, name, "optimizer")

    def problem(self, name: str):
        """The ProblemInfo called name, or a ConfigError with close matches."""
        return _lookup(self.problems, name, "problem")

    def physics_backend(self, name: str):
        """The BackendInfo called name, or a ConfigError listing the installed ones."""
        return _lookup(self.physics_backends, name, "physics backend")


def _lookup(table: dict[str, Any], name: str, kind: str):
    if name in table:
        return table[name]
    installed = ", ".join(table) or "none installed"
    raise ConfigError(f"unknown {kind} {name!r}.{suggest(name, list(table))} Installed: {installed}")


def build_manager(extra_modules: Iterable[ModuleType] = ()) -> tuple[pluggy.PluginManager, dict]:
    """A plugin manager with the entry-point plugins (filtered by METAOPT_LOAD_PLUGINS) loaded."""
    manager = pluggy.PluginManager("metaopt")
    manager.add_hookspecs(hookspecs)
    sources: dict[str, PluginSource] = {}
    wanted = os.environ.get(LOAD_PLUGINS_ENV)
    allowed = None if wanted is None else {n.strip() for n in wanted.split(",") if n.strip()}
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if allowed is not None and entry_point.name not in allowed:
            continue
        if manager.has_plugin(entry_point.name):
            continue
        module = entry_point.load()
        manager.register(module, name=entry_point.name)
        distribution = entry_point.dist.name if entry_point.dist else "?"
        sources[entry_point.name] = PluginSource(entry_point.name, entry_point.value, distribution)
    for module in extra_modules:
        manager.register(module)
    return manager, sources


@lru_cache(maxsize=1)
def registry() -> Registry:
    """The process-wide registry of installed plugins (loaded once)."""
    manager, sources = build_manager()
    return Registry(manager, sources)
