"""metaopt: metaheuristic optimization with plugins."""

from metaopt.api import History, Result, create_optimizer, maximize, minimize
from metaopt.errors import (
    ConfigError,
    EvaluationError,
    MetaoptError,
    RunFailed,
    SettingWarning,
    StoreError,
)
from metaopt.hookspecs import hookimpl
from metaopt.optimizer import (
    Optimizer,
    OptimizerInfo,
    budget_param,
    json_float,
    population_param,
    restore_rng,
    rng_state,
)
from metaopt.params import Param
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense
from metaopt.space import Space, Variable

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "Evaluation",
    "EvaluationError",
    "History",
    "MetaoptError",
    "Optimizer",
    "OptimizerInfo",
    "Param",
    "Problem",
    "ProblemInfo",
    "Result",
    "RunFailed",
    "Sense",
    "SettingWarning",
    "Space",
    "StoreError",
    "Variable",
    "__version__",
    "budget_param",
    "create_optimizer",
    "hookimpl",
    "json_float",
    "maximize",
    "minimize",
    "population_param",
    "restore_rng",
    "rng_state",
]
