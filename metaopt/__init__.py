"""metaopt: metaheuristic optimization with plugins."""

from metaopt.errors import ConfigError, EvaluationError, MetaoptError, StoreError
from metaopt.hookspecs import hookimpl
from metaopt.optimizer import Optimizer, OptimizerInfo, restore_rng, rng_state
from metaopt.params import Param
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense
from metaopt.space import Space, Variable

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "Evaluation",
    "EvaluationError",
    "MetaoptError",
    "Optimizer",
    "OptimizerInfo",
    "Param",
    "Problem",
    "ProblemInfo",
    "Sense",
    "Space",
    "StoreError",
    "Variable",
    "__version__",
    "hookimpl",
    "restore_rng",
    "rng_state",
]
