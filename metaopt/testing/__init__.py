"""The conformance kit: checks that an optimizer or a problem keeps metaopt's contract.

Call it from a plugin's own pytest suite::

    from metaopt.testing import check_optimizer, check_problem

    def test_my_optimizer_conforms():
        check_optimizer("hill-climb")                  # a registered name, or an OptimizerInfo

    def test_my_problem_conforms():
        check_problem("bowl", params={"dim": 3})

or get one pytest test per check::

    CHECKS = optimizer_checks("hill-climb")

    @pytest.mark.parametrize("check", CHECKS)
    def test_conforms(check):
        CHECKS[check]()

A physics engine (a ``metaopt_physics_backends`` plugin) gets the engine agreement suite: what
it simulates, measured from it (friction, motors, mass, standing, free fall; see
metaopt.physics.agreement)::

    def test_my_engine_agrees():
        check_engine("my-engine")

A breach raises ConformanceError (an AssertionError) saying what was breached and how to fix it.
The kit holds a plugin to what the run loop and the run store rely on, and to a little more
that a sound plugin always satisfies: an optimizer declares ``budget`` (metaopt.budget_param()),
which generic code gives every optimizer; a problem must evaluate every point sampled uniformly in
its space to a finite fitness, and different seeds must make an optimizer propose different
candidates. A state must survive ``json.dumps`` with default settings, as the run store writes it
(so inf and nan are allowed), and a fresh optimizer loading it must continue bit for bit.
"""

from metaopt.testing.common import Check, ConformanceError
from metaopt.testing.engines import check_engine, engine_checks
from metaopt.testing.optimizers import check_optimizer, optimizer_checks
from metaopt.testing.problems import check_problem, problem_checks

__all__ = [
    "Check",
    "ConformanceError",
    "check_engine",
    "check_optimizer",
    "check_problem",
    "engine_checks",
    "optimizer_checks",
    "problem_checks",
]
