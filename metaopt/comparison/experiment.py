"""An experiment: a grid of optimizers (each with its own budget and parameters) × problem
settings × seeds, read from a TOML file or from `metaopt compare` flags and checked against
the plugins' declarations before anything runs."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from metaopt.assessment.candidates import stored_start
from metaopt.errors import ConfigError, SettingWarning
from metaopt.params import Param, resolve, suggest
from metaopt.plugins import Registry
from metaopt.problem import ProblemInfo
from metaopt.running import RunSettings, RunSpec, check_run
from metaopt.settings import parse_problem_settings

_TOP_KEYS = ("name", "problem", "seeds", "target", "budget", "problem_settings", "optimizers")
_OPTIMIZER_KEYS = ("label", "name", "budget", "params", "settings")


@dataclass(frozen=True)
class OptimizerEntry:
    """One optimizer of the experiment: its label in tables, plugin name, budget, parameters."""

    label: str
    name: str
    budget: int
    params: dict[str, Any] = field(default_factory=dict)
    settings: RunSettings = field(default_factory=RunSettings)


@dataclass(frozen=True)
class Cell:
    """One optimizer on one combination of problem settings; run once per seed."""

    optimizer: OptimizerEntry
    problem_params: dict[str, Any]
    #: the problem parameters that differ between cells (the grid's columns)
    varying: tuple[str, ...] = ()

    @property
    def setting(self) -> str:
        """The varying problem settings as text ('backend=mujoco'); '' when none vary."""
        return ", ".join(f"{name}={self.problem_params[name]}" for name in self.varying)

    @property
    def key(self) -> str:
        """The cell's identity in the run store: label and problem settings."""
        return f"{self.optimizer.label} {json.dumps(self.problem_params, sort_keys=True)}"


@dataclass(frozen=True)
class Experiment:
    """Optimizers × problem-settings grid × seeds on one problem, with an optional target."""

    name: str
    problem: str
    seeds: tuple[int, ...]
    optimizers: tuple[OptimizerEntry, ...]
    #: problem parameter -> the values the grid takes (each combination is a column)
    problem_grid: dict[str, list[Any]] = field(default_factory=dict)
    #: success when a run's best fitness reaches it (sense-aware)
    target: float | None = None
    #: part of the grid kept by `compare --only`: "optimizer" (labels) or a problem setting ->
    #: the values kept; a cell's identity and setting text stay those of the whole grid
    only: dict[str, tuple[Any, ...]] = field(default_factory=dict)

    @property
    def fixed_settings(self) -> str:
        """The problem settings every cell shares, as text ('duration=3.0, lock=1.0')."""
        return ", ".join(
            f"{name}={values[0]}" for name, values in self.problem_grid.items() if len(values) == 1
        )

    def cells(self) -> list[Cell]:
        """Every cell, grouped by problem setting, optimizers in the order given."""
        names = list(self.problem_grid)
        varying = tuple(name for name in names if len(self.problem_grid[name]) > 1)
        combinations = itertools.product(*(self.problem_grid[n] for n in names))
        cells = [
            Cell(optimizer, dict(zip(names, values)), varying)
            for values in combinations
            for optimizer in self.optimizers
        ]
        return [cell for cell in cells if self._selected(cell)]

    def _selected(self, cell: Cell) -> bool:
        """Whether ``cell`` lies in the part of the grid ``only`` keeps."""
        return all(
            (cell.optimizer.label if name == "optimizer" else cell.problem_params[name]) in kept
            for name, kept in self.only.items()
        )

    def spec(self, cell: Cell, seed: int) -> RunSpec:
        """The run of ``cell`` with ``seed``."""
        entry = cell.optimizer
        return RunSpec(
            optimizer=entry.name,
            problem=self.problem,
            budget=entry.budget,
            seed=seed,
            optimizer_params=dict(entry.params),
            problem_params=dict(cell.problem_params),
            settings=entry.settings,
        )


def load_experiment(path: str | Path, plugins: Registry) -> Experiment:
    """The experiment in a TOML file; ConfigError naming the file and what is wrong."""
    path = Path(path)
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        raise ConfigError(
            f"{path}: experiment files need Python 3.11 or later (tomllib); on 3.10 use the "
            "flags form: metaopt compare -o NAME -p NAME ..."
        ) from None
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such experiment file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise ConfigError(f"{path}: cannot read it: {error}") from None
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{path}: not valid TOML: {error}") from None
    raw.setdefault("name", path.stem)
    return _checked(raw, str(path), plugins)


def restrict(experiment: Experiment, pairs: Iterable[str], plugins: Registry) -> Experiment:
    """The part of ``experiment`` that NAME=VALUE pairs select (`compare --only`): NAME is
    ``optimizer`` (a label) or a problem setting of the grid; values of one name are
    alternatives, different names must all hold. Runs keep the whole experiment's identity, so
    a part run alone joins the same cells as the whole."""
    wanted: dict[str, list[str]] = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        if not sep or not name.strip():
            raise ConfigError(f"--only expects NAME=VALUE, got {pair!r} (e.g. --only backend=ode)")
        wanted.setdefault(name.strip(), []).append(text.strip())
    declared = {p.name: p for p in plugins.problem(experiment.problem).params}
    parts = ["optimizer", *experiment.problem_grid]
    only: dict[str, tuple[Any, ...]] = {}
    for name, texts in wanted.items():
        if name == "optimizer":
            choices = [entry.label for entry in experiment.optimizers]
        elif name in experiment.problem_grid:
            choices = experiment.problem_grid[name]
        else:
            raise ConfigError(
                f"--only {name}=...: {name!r} is not a part of experiment {experiment.name!r}'s "
                f"grid.{suggest(name, parts)} Accepted: {', '.join(parts)}"
            )
        kept = []
        for text in texts:
            matches = [value for value in choices if _same(name, value, text, declared)]
            if not matches:
                shown = ", ".join(str(value) for value in choices)
                raise ConfigError(
                    f"--only {name}={text}: the experiment {experiment.name!r} has no such "
                    f"{name}; it has {shown}"
                )
            kept.extend(matches)
        only[name] = tuple(kept)
    return dataclasses.replace(experiment, only={**experiment.only, **only})


def _same(name: str, value: Any, text: str, declared: dict[str, Param]) -> bool:
    """Whether the grid's ``value`` of ``name`` is the one ``text`` names (numbers by value)."""
    if name == "optimizer" or name not in declared:
        return str(value) == text
    try:
        return declared[name].parse(text, "--only") == declared[name].validate(value, "--only")
    except ConfigError:
        return False


def experiment_from_flags(
    *,
    optimizers: Iterable[str],
    problem: str,
    seeds: int,
    budget: int | None,
    settings: Iterable[str],
    target: float | None,
    name: str | None,
    plugins: Registry,
) -> Experiment:
    """The experiment `metaopt compare -o A -o B -p P ...` describes. ``settings`` are problem
    NAME=VALUE pairs; a name given several times makes a grid over its values."""
    problem_info = plugins.problem(problem)
    grid: dict[str, list[Any]] = {}
    for pair in settings:
        for key, value in parse_problem_settings([pair], problem_info).items():
            grid.setdefault(key, []).append(value)
    labels = list(optimizers)
    budget = problem_info.default_budget if budget is None else budget
    raw = {
        "name": name or f"{'-vs-'.join(labels)}-on-{problem}-{budget}",
        "problem": problem,
        "seeds": seeds,
        "budget": budget,
        "problem_settings": grid,
        "optimizers": [{"name": label} for label in labels],
    }
    if target is not None:
        raw["target"] = target
    return _checked(raw, "command line", plugins)


def _checked(raw: dict[str, Any], source: str, plugins: Registry) -> Experiment:
    """Validate a decoded experiment; every ConfigError starts with ``source``."""
    try:
        return _experiment(raw, plugins)
    except ConfigError as error:
        raise ConfigError(f"{source}: {error}") from None


def _experiment(raw: dict[str, Any], plugins: Registry) -> Experiment:
    _known_keys(raw, _TOP_KEYS, "the experiment")
    name = raw.get("name")
    if not isinstance(name, str) or not name:
        raise ConfigError(f"'name' must be a non-empty string, got {name!r}")
    if "problem" not in raw:
        raise ConfigError("no 'problem' given (e.g. problem = \"sphere\")")
    problem_info = plugins.problem(str(raw["problem"]))
    grid = _problem_grid(raw.get("problem_settings", {}), problem_info)
    default_budget = raw.get("budget")
    entries = raw.get("optimizers")
    if not isinstance(entries, list) or not entries:
        raise ConfigError("no optimizers given; add at least one optimizer with a name and budget")
    optimizers = tuple(
        _optimizer_entry(entry, number, default_budget, plugins, problem_info, grid)
        for number, entry in enumerate(entries, start=1)
    )
    labels = [entry.label for entry in optimizers]
    for label in labels:
        if labels.count(label) > 1:
            raise ConfigError(f"optimizer label {label!r} is used twice; give each a 'label'")
    target = raw.get("target")
    if target is not None and (isinstance(target, bool) or not isinstance(target, int | float)):
        raise ConfigError(f"'target' must be a number, got {target!r}")
    if target is not None and not math.isfinite(target):
        raise ConfigError(f"target must be a finite fitness, got {target}")
    experiment = Experiment(
        name=name,
        problem=problem_info.name,
        seeds=_seeds(raw.get("seeds")),
        optimizers=optimizers,
        problem_grid=grid,
        target=None if target is None else float(target),
    )
    _check_cells(experiment, plugins, problem_info)
    return experiment


def _check_cells(experiment: Experiment, plugins: Registry, problem_info: ProblemInfo) -> None:
    """Every cell's run as `metaopt run --check` checks it (the optimizer and problem built
    together, e.g. screening with both), so that a bad cell is refused before any cell runs.
    The runs warn of their settings themselves; the check does not warn twice."""
    for cell in experiment.cells():
        spec = experiment.spec(cell, experiment.seeds[0])
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", SettingWarning)
                check_run(spec, plugins.optimizer(cell.optimizer.name), problem_info)
        except ConfigError as error:
            setting = f" [{cell.setting}]" if cell.setting else ""
            raise ConfigError(f"cell {cell.optimizer.label!r}{setting}: {error}") from None


def _seeds(value: Any) -> tuple[int, ...]:
    """A list of distinct integer seeds, or N meaning seeds 1..N."""
    if isinstance(value, int) and not isinstance(value, bool) and value >= 1:
        return tuple(range(1, value + 1))
    if (
        isinstance(value, list)
        and value
        and all(isinstance(s, int) and not isinstance(s, bool) for s in value)
    ):
        if len(set(value)) < len(value):
            raise ConfigError(f"'seeds' lists a seed twice: {value}")
        return tuple(value)
    raise ConfigError(f"'seeds' must be a list of integers or a count N >= 1, got {value!r}")


def _problem_grid(table: Any, problem_info: ProblemInfo) -> dict[str, list[Any]]:
    """Each problem parameter's values (a scalar is one value), checked against the problem:
    each value against its declaration, each combination by a problem built from it, so that
    a setting the problem refuses stops the experiment before any run is stored."""
    if not isinstance(table, dict):
        raise ConfigError("problem_settings must be a table of parameter = list of values")
    grid = {name: v if isinstance(v, list) else [v] for name, v in table.items()}
    for name, values in grid.items():
        if not values:
            raise ConfigError(f"problem setting {name!r} has no values")
        for value in values:
            resolve(problem_info.params, {name: value}, f"problem {problem_info.name!r}")
    for combination in itertools.product(*grid.values()):  # the problem's own checks
        problem_info.checked_params(dict(zip(grid, combination)))
    return grid


def _optimizer_entry(
    entry: Any,
    number: int,
    default_budget: Any,
    plugins: Registry,
    problem_info: ProblemInfo,
    grid: dict[str, list[Any]],
) -> OptimizerEntry:
    where = f"optimizer entry {number}"
    if not isinstance(entry, dict) or "name" not in entry:
        raise ConfigError(f"{where} needs a 'name' (an optimizer, e.g. name = \"hs\")")
    _known_keys(entry, _OPTIMIZER_KEYS, where)
    where = f"{where} ({entry['name']!r})"
    try:
        info = plugins.optimizer(str(entry["name"]))
    except ConfigError as error:
        raise ConfigError(f"{where}: {error}") from None
    budget = entry.get("budget", default_budget)
    if budget is None:
        raise ConfigError(f"{where} has no 'budget' and the experiment sets none")
    if isinstance(budget, bool) or not isinstance(budget, int) or budget < 1:
        raise ConfigError(f"{where}: 'budget' must be a positive integer, got {budget!r}")
    params = entry.get("params", {})
    settings = entry.get("settings", {})
    if not isinstance(params, dict) or not isinstance(settings, dict):
        raise ConfigError(f"{where}: 'params' and 'settings' must be tables")
    _known_keys(settings, tuple(f.name for f in fields(RunSettings)), f"{where} settings")
    try:
        resolve(info.params, params, f"optimizer {info.name!r}")
        if "start_from" in settings:
            settings = {**settings, **_stored_starts(settings, problem_info, grid, plugins)}
        run_settings = RunSettings(**settings)
        run_settings.check(budget)
    except (ConfigError, TypeError) as error:
        raise ConfigError(f"{where}: {error}") from None
    label = entry.get("label", info.name)
    return OptimizerEntry(str(label), info.name, budget, dict(params), run_settings)


def _stored_starts(
    settings: dict[str, Any],
    problem_info: ProblemInfo,
    grid: dict[str, list[Any]],
    plugins: Registry,
) -> dict[str, Any]:
    """The run settings ``start`` (the points) and ``start_from`` (their names) for
    ``settings.start_from``: a stored candidate's name or a list of them, each checked to give
    the same start point in every cell's problem."""
    names = settings["start_from"]
    if isinstance(names, str):
        names = [names]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise ConfigError(
            f"settings.start_from must be a stored candidate's name or a list of them, "
            f"got {settings['start_from']!r}"
        )
    if "start" in settings:
        raise ConfigError(
            "settings give both start (values) and start_from (stored candidates); give one"
        )
    combinations = [dict(zip(grid, values)) for values in itertools.product(*grid.values())]
    points = []
    for name in names:
        found = [stored_start(name, problem_info, c, plugins.problems) for c in combinations]
        if any(point != found[0] for point in found):
            raise ConfigError(
                f"settings.start_from {name!r} gives different start points in different cells "
                "(their problems have different variables); give each problem its own experiment"
            )
        points.append(found[0])
    return {"start": points, "start_from": ", ".join(names)}


def _known_keys(table: dict[str, Any], known: tuple[str, ...], where: str) -> None:
    for key in table:
        if key not in known:
            raise ConfigError(
                f"{where} has an unknown key {key!r}.{suggest(key, known)} "
                f"Accepted: {', '.join(known)}"
            )
