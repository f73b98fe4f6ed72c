"""Writing a new plugin package: a working optimizer or problem, its tests, a README.

``create_plugin("optimizer", "my-es")`` writes ./my-es, a package that installs with pip, registers
the optimizer ``my-es`` through the ``metaopt`` entry-point group and checks itself with the
conformance kit (metaopt.testing). The command line is ``metaopt new optimizer my-es``.
"""

from __future__ import annotations

import importlib.util
import keyword
import re
from dataclasses import dataclass
from pathlib import Path
from string import Template

from metaopt.errors import ConfigError
from metaopt.plugins import registry

KINDS = ("optimizer", "problem")
_NAME = re.compile(r"[a-z][a-z0-9]*(?:[-_][a-z0-9]+)*\Z")


@dataclass(frozen=True)
class PluginNames:
    """The names a plugin goes by, all derived from the one the user chose."""

    name: str  # as metaopt knows it: metaopt run -o NAME
    distribution: str  # for pip: metaopt-NAME
    package: str  # the Python package: metaopt_NAME
    entry_point: str  # in the metaopt entry-point group
    class_name: str  # the Optimizer or Problem subclass


def plugin_names(name: str) -> PluginNames:
    """Derive and validate the names of a new plugin called name, or raise ConfigError."""
    if not _NAME.match(name):
        raise ConfigError(
            f"plugin name {name!r} is not accepted; use lowercase letters and digits, words "
            "joined by - or _, starting with a letter (e.g. my-es)"
        )
    identifier = name.replace("-", "_")
    if keyword.iskeyword(identifier):
        raise ConfigError(f"plugin name {name!r} is a Python keyword; choose another")
    return PluginNames(
        name=name,
        distribution=f"metaopt-{name.replace('_', '-')}",
        package=f"metaopt_{identifier}",
        entry_point=identifier,
        class_name="".join(word.capitalize() for word in identifier.split("_")),
    )


def create_plugin(kind: str, name: str, directory: Path | None = None) -> Path:
    """Write a plugin package for a new optimizer or problem into directory (default ./name).

    Refuses (ConfigError) an unknown kind, a bad name, a name already registered or importable,
    and an existing directory. Returns the directory written.
    """
    if kind not in KINDS:
        raise ConfigError(f"unknown plugin kind {kind!r}; accepted: {', '.join(KINDS)}")
    names = plugin_names(name)
    plugins = registry()
    taken = "optimizer" if name in plugins.optimizers else "problem"
    if name in plugins.optimizers or name in plugins.problems:
        raise ConfigError(
            f"an installed plugin already provides the {taken} {name!r} "
            f"({plugins.source(taken, name)}); choose another name"
        )
    if importlib.util.find_spec(names.package) is not None:
        raise ConfigError(f"a module {names.package!r} is already importable; choose another name")
    target = Path(directory) if directory is not None else Path(name)
    if target.exists():
        raise ConfigError(
            f"{target} already exists; choose another --directory or remove it (nothing written)"
        )
    files = {
        "pyproject.toml": PYPROJECT,
        "README.md": README[kind],
        f"{names.package}/__init__.py": MODULE[kind],
        f"tests/test_{names.entry_point}.py": TESTS[kind],
    }
    for relative, template in files.items():
        path = target / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(Template(template).substitute(vars(names), kind=kind), encoding="utf-8")
    return target


PYPROJECT = """\
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "$distribution"
version = "0.1.0"
description = "The metaopt $kind $name"
readme = "README.md"
requires-python = ">=3.10"
dependencies = ["metaopt", "numpy"]

[project.optional-dependencies]
test = ["pytest"]

# metaopt finds plugins through this entry-point group.
[project.entry-points.metaopt]
$entry_point = "$package"

[tool.setuptools]
packages = ["$package"]
"""

_README_COMMON = """\
## Install and run

```bash
pip install -e .
metaopt list $name
$run
```

## Test

```bash
pip install -e ".[test]"
python -m pytest
```

The tests run metaopt's conformance kit (`metaopt.testing`), one test per check of the contract
every $kind must keep. Change the algorithm as you like; keep those tests passing.
"""

README = {
    "optimizer": """\
# $distribution

The metaopt optimizer `$name`: a (1+λ) evolution strategy. Each batch is λ Gaussian mutations of
the parent; the best of them becomes the parent when it is better; the step size grows after a
success and shrinks after a failure (the 1/5th success rule). It lives in `$package/__init__.py`.

"""
    + _README_COMMON.replace("$run", "metaopt run -o $name -p sphere --budget 2000 --seed 1"),
    "problem": """\
# $distribution

The metaopt problem `$name`: a tilted bowl, Σ w_i (x_i − c_i)², to minimize, with optional
Gaussian noise drawn from the evaluation's seed. It lives in `$package/__init__.py`.

"""
    + _README_COMMON.replace("$run", "metaopt run -o hs -p $name --budget 2000 --seed 1"),
}

MODULE = {
    "optimizer": '''\
"""The metaopt optimizer $name: a (1+λ) evolution strategy with the 1/5th success rule.

Each batch is λ Gaussian mutations of the parent (step size a fraction of each variable's range),
reflected back inside the bounds. The best of a batch replaces the parent when it is better, and
the step size then grows by SUCCESS; otherwise it shrinks by FAILURE, so that it stays put when
one batch in five succeeds.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from metaopt import (
    Optimizer,
    OptimizerInfo,
    Param,
    Space,
    budget_param,
    hookimpl,
    restore_rng,
    rng_state,
)

SUCCESS = 1.5
FAILURE = SUCCESS**-0.25
#: The step size (a fraction of the range) stays within these bounds.
MIN_STEP, MAX_STEP = 1e-12, 1.0


class $class_name(Optimizer):
    """A (1+λ) evolution strategy over a box; minimizes."""

    def __init__(
        self, space: Space, seed: int, *, offspring: int, step: float, budget: int
    ) -> None:
        # budget: the evaluations it will be told; the 1/5th rule needs no schedule over them.
        super().__init__(space, seed)  # gives self.space and self.rng, seeded by seed
        self.offspring = offspring
        self.step = step
        self.parent = space.sample(self.rng, 1)[0]
        self.parent_fitness = math.inf

    @property
    def batch_size(self) -> int:
        """λ: the candidates the optimizer prefers to be asked for at once."""
        return self.offspring

    def ask(self, n: int) -> np.ndarray:
        """n mutations of the parent, inside the bounds; any n works."""
        steps = self.rng.normal(0.0, self.step, (n, self.space.dim)) * self.space.width
        return self.space.repair(self.parent + steps, "reflect")

    def tell(self, candidates: np.ndarray, fitnesses: np.ndarray) -> None:
        """Keep the best candidate if it beats the parent; adapt the step size."""
        best = int(np.argmin(fitnesses))  # failed evaluations arrive as +inf
        if fitnesses[best] < self.parent_fitness:
            self.parent = np.array(candidates[best], dtype=float)
            self.parent_fitness = float(fitnesses[best])
            self.step = min(self.step * SUCCESS, MAX_STEP)
        else:
            self.step = max(self.step * FAILURE, MIN_STEP)

    def state_dict(self) -> dict[str, Any]:
        """Everything later asks depend on, the generator included, as plain JSON."""
        return {
            "parent": self.parent.tolist(),
            "parent_fitness": self.parent_fitness,
            "step": self.step,
            "rng": rng_state(self.rng),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what state_dict returned."""
        self.parent = np.array(state["parent"], dtype=float)
        self.parent_fitness = float(state["parent_fitness"])
        self.step = state["step"]
        restore_rng(self.rng, state["rng"])


@hookimpl
def metaopt_optimizers() -> list[OptimizerInfo]:
    """Announce the optimizer to metaopt."""
    return [
        OptimizerInfo(
            name="$name",
            summary="(1+λ) evolution strategy with the 1/5th success rule",
            factory=$class_name,  # called as factory(space, seed, **params)
            params=(
                Param("offspring", int, 10, "λ: mutations per batch", low=1),
                Param(
                    "step",
                    float,
                    0.1,
                    "initial step size, fraction of each variable's range",
                    low=0.0,
                    high=1.0,
                    low_open=True,
                ),
                budget_param(),  # every optimizer declares it; metaopt sets the run's
            ),
            description=__doc__ or "",
        )
    ]
''',
    "problem": '''\
"""The metaopt problem $name: a tilted bowl Σ w_i (x_i − c_i)² to minimize, optionally noisy.

The minimum, 0, lies at c (evenly spread from -1 to 2); the weights w_i = i tilt the bowl. With
``noise`` > 0 a Gaussian term is added, drawn from a generator seeded by the evaluation's seed, so
that evaluate stays a pure function of (x, seed) as metaopt requires.
"""

from __future__ import annotations

import numpy as np
from metaopt import Evaluation, Param, Problem, ProblemInfo, Sense, Space, hookimpl


class $class_name(Problem):
    """The tilted bowl in dim variables, each in [-5, 5]."""

    sense = Sense.MINIMIZE
    key_metrics = ("distance",)
    optimum = 0.0

    def __init__(self, dim: int, noise: float) -> None:
        self.space = Space.from_bounds([-5.0] * dim, [5.0] * dim)
        self.centre = np.linspace(-1.0, 2.0, dim)
        self.weights = np.arange(1.0, dim + 1.0)
        self.noise = noise

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        """The bowl's value at x, plus noise from seed; the distance to the minimum as a metric."""
        offset = np.asarray(x, dtype=float) - self.centre
        value = float(np.dot(self.weights, offset**2))
        if self.noise > 0.0:
            value += float(np.random.default_rng(seed).normal(0.0, self.noise))
        return Evaluation(value, {"distance": float(np.linalg.norm(offset))})


@hookimpl
def metaopt_problems() -> list[ProblemInfo]:
    """Announce the problem to metaopt."""
    return [
        ProblemInfo(
            name="$name",
            summary="A tilted bowl to minimize, optionally noisy",
            factory=$class_name,  # called as factory(**params)
            params=(
                Param("dim", int, 5, "number of variables", low=1),
                Param("noise", float, 0.0, "standard deviation of noise", low=0.0),
            ),
            description=__doc__ or "",
            default_budget=2000,
        )
    ]
''',
}

TESTS = {
    "optimizer": '''\
"""Tests of the optimizer $name: metaopt's conformance checks, and a minimum found."""

import numpy as np
import pytest
from metaopt import Space
from metaopt.testing import optimizer_checks

from $package import $class_name

CHECKS = optimizer_checks("$name")


@pytest.mark.parametrize("check", CHECKS)
def test_conforms(check):
    CHECKS[check]()


def test_finds_the_minimum_of_a_sphere():
    space = Space.from_bounds([-5.0] * 5, [5.0] * 5)
    optimizer = $class_name(space, seed=1, offspring=10, step=0.1, budget=4000)
    for _ in range(400):
        candidates = optimizer.ask(optimizer.batch_size)
        optimizer.tell(candidates, (candidates**2).sum(axis=1))
    assert optimizer.parent_fitness < 1e-6
    assert np.abs(optimizer.parent).max() < 1e-3
''',
    "problem": '''\
"""Tests of the problem $name: metaopt's conformance checks, and where its minimum lies."""

import pytest
from metaopt.testing import problem_checks

from $package import $class_name

CHECKS = problem_checks("$name", in_subprocess=True)


@pytest.mark.parametrize("check", CHECKS)
def test_conforms(check):
    CHECKS[check]()


def test_the_minimum_is_zero_at_the_centre():
    problem = $class_name(dim=4, noise=0.0)
    result = problem.evaluate(problem.centre, seed=0)
    assert result.fitness == problem.optimum == 0.0
    assert result.metrics == {"distance": 0.0}
''',
}
