"""Finding plugins: the pluggy manager, entry-point loading and the name registries."""

from __future__ import annotations

import importlib.metadata
import os
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from types import ModuleType
from typing import TYPE_CHECKING, Any

import pluggy

from metaopt import hookspecs
from metaopt.errors import ConfigError
from metaopt.params import close_matches, suggest

if TYPE_CHECKING:
    from metaopt.executors.base import ExecutorInfo
    from metaopt.optimizer import OptimizerInfo
    from metaopt.physics import BackendInfo
    from metaopt.problem import ProblemInfo

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
        #: (kind, name) -> entry-point name of the plugin that announced it.
        self.provided_by: dict[tuple[str, str], str] = {}
        self.optimizers = self._collect(manager.hook.metaopt_optimizers, "optimizer")
        self.problems = self._collect(manager.hook.metaopt_problems, "problem")
        self.physics_backends = self._collect(
            manager.hook.metaopt_physics_backends, "physics backend"
        )
        self.executors = self._collect(manager.hook.metaopt_executors, "executor")

    def _collect(self, hook: pluggy.HookCaller, kind: str) -> dict[str, Any]:
        found: dict[str, Any] = {}
        for implementation in hook.get_hookimpls():
            for info in implementation.function():
                if info.name in found:
                    other = self.provided_by[(kind, info.name)]
                    raise ConfigError(
                        f"plugins {other!r} and {implementation.plugin_name!r} both provide the "
                        f"{kind} {info.name!r}; uninstall one or exclude it with "
                        f"{LOAD_PLUGINS_ENV}"
                    )
                found[info.name] = info
                self.provided_by[(kind, info.name)] = implementation.plugin_name
        return dict(sorted(found.items()))

    def source(self, kind: str, name: str) -> str:
        """The distribution that provides a plugin, for `metaopt list`."""
        plugin_name = self.provided_by.get((kind, name), "?")
        source = self.sources.get(plugin_name)
        return source.distribution if source else plugin_name

    def optimizer(self, name: str) -> OptimizerInfo:
        """The OptimizerInfo called name, or a ConfigError with close matches."""
        return _lookup(self.optimizers, name, "optimizer")

    def problem(self, name: str) -> ProblemInfo:
        """The ProblemInfo called name, or a ConfigError with close matches."""
        return _lookup(self.problems, name, "problem")

    def executor(self, name: str) -> ExecutorInfo:
        """The ExecutorInfo called name, or a ConfigError listing the installed ones."""
        return _lookup(self.executors, name, "executor")

    def physics_backend(self, name: str) -> BackendInfo:
        """The BackendInfo called name, or a ConfigError listing the installed ones (or saying
        what the engine needs, when it cannot run here)."""
        info = _lookup(self.physics_backends, name, "physics backend")
        if info.unavailable:
            raise ConfigError(f"physics backend {name!r} is unavailable: {info.unavailable}")
        return info

    def available_physics_backends(self) -> list[str]:
        """The physics engines that can run here, in registry order (an engine whose library is
        missing is listed by `metaopt list` but left out)."""
        return [name for name, info in self.physics_backends.items() if not info.unavailable]

    def tables(self) -> dict[str, dict[str, Any]]:
        """Every kind's table by the kind's name."""
        return {
            "optimizer": self.optimizers,
            "problem": self.problems,
            "physics backend": self.physics_backends,
            "executor": self.executors,
        }

    def any_kind(self, name: str) -> tuple[str, Any]:
        """(kind, info) of the plugin called name, whatever its kind, or a ConfigError with the
        close matches among every kind (ignoring case)."""
        for kind, table in self.tables().items():
            if name in table:
                return kind, table[name]
        kinds = {known: kind for kind, table in self.tables().items() for known in table}
        close = [f"{match!r} ({kinds[match]})" for match in close_matches(name, list(kinds))]
        hint = f" Did you mean {' or '.join(close)}?" if close else ""
        raise ConfigError(
            f"unknown plugin {name!r}.{hint} Installed: "
            + "; ".join(
                f"{kind}s {', '.join(table)}" for kind, table in self.tables().items() if table
            )
        )


def _lookup(table: dict[str, Any], name: str, kind: str) -> Any:
    if name in table:
        return table[name]
    installed = ", ".join(table) or "none installed"
    raise ConfigError(
        f"unknown {kind} {name!r}.{suggest(name, list(table))} Installed: {installed}"
    )


def build_manager(extra_modules: Iterable[ModuleType] = ()) -> tuple[pluggy.PluginManager, dict]:
    """A plugin manager with the entry-point plugins (filtered by METAOPT_LOAD_PLUGINS) loaded."""
    manager = pluggy.PluginManager("metaopt")
    manager.add_hookspecs(hookspecs)
    sources: dict[str, PluginSource] = {}
    wanted = os.environ.get(LOAD_PLUGINS_ENV)
    allowed = None if wanted is None else {n.strip() for n in wanted.split(",") if n.strip()}
    entry_points = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    unknown = sorted((allowed or set()) - {entry_point.name for entry_point in entry_points})
    if unknown:
        raise ConfigError(
            f"{LOAD_PLUGINS_ENV} names no installed plugin {', '.join(map(repr, unknown))}; it "
            f"takes entry-point names (not optimizer or problem names): "
            f"{', '.join(sorted({entry_point.name for entry_point in entry_points}))}"
        )
    for entry_point in entry_points:
        if allowed is not None and entry_point.name not in allowed:
            continue
        if manager.has_plugin(entry_point.name):
            continue
        try:
            module = entry_point.load()
        except Exception as error:  # a broken plugin must say which one it is
            raise ConfigError(
                f"plugin {entry_point.name!r} ({entry_point.value}) failed to load: "
                f"{type(error).__name__}: {error}. Fix or uninstall it, or leave it out with "
                f"{LOAD_PLUGINS_ENV}=<names of the plugins to load>"
            ) from None
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
