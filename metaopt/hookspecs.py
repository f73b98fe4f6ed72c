"""The hooks a metaopt plugin can implement.

A plugin is a plain module with functions decorated by ``metaopt.hookimpl``, announced through an
entry point in the ``metaopt`` group of its package's pyproject.toml::

    [project.entry-points.metaopt]
    my_plugin = "my_package.my_module"

Every hook returns a list, so one module can announce several things. The built-in optimizers,
problems and physics engines use exactly these hooks.
"""

from __future__ import annotations

import pluggy

hookspec = pluggy.HookspecMarker("metaopt")
hookimpl = pluggy.HookimplMarker("metaopt")


@hookspec
def metaopt_optimizers() -> list:
    """Return the optimizers this plugin provides, as a list of ``metaopt.OptimizerInfo``."""


@hookspec
def metaopt_problems() -> list:
    """Return the problems this plugin provides, as a list of ``metaopt.ProblemInfo``."""


@hookspec
def metaopt_executors() -> list:
    """Return ways to run evaluations, as a list of ``metaopt.executors.ExecutorInfo``.

    An executor takes ``EvaluationTask`` objects and returns ``concurrent.futures.Future``
    objects of ``Outcome`` (e.g. local processes, Dask; an outside package could add Ray or MPI).
    """


@hookspec
def metaopt_physics_backends() -> list:
    """Return physics engines for robot problems, as a list of ``metaopt.physics.BackendInfo``.

    A backend builds a simulation from a ``metaopt.physics.RobotDescription`` and drives it
    through the small ``metaopt.physics.PhysicsBackend`` interface (e.g. MuJoCo, PyBullet).
    """
