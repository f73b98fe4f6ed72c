"""BBOB: COCO's 24 noiseless black-box functions (through ``cocoex``), optionally logged by COCO.

The problem ``bbob`` picks one COCO problem by function (1-24), dimension (2, 3, 5, 10, 20, 40)
and instance. Its fitness is the *precision* f(x) - f_opt, COCO's own target measure, so the
optimum is 0 and a run has hit COCO's final target when the best fitness is below 1e-8. The raw
f(x) is kept as the metric ``f``.

With ``observe=FOLDER`` every evaluation is also written in COCO's format (``.info``, ``.dat``,
``.tdat`` ...) by a ``cocoex.Observer`` so cocopp can post-process it. The folder is made
absolute when the problem is built and handed to COCO as ``outer_folder``/``result_folder``,
so COCO never writes into the working directory (its default is ``./exdata``); nothing here
changes the working directory. Building a ``cocoex.Suite`` writes no files.

cocoex handles cannot be pickled and some misuse crashes the interpreter (an invalid problem
exits from C, a freed problem segfaults), so the parameters are validated before cocoex sees
them, the suite is held as long as its problem, and pickling keeps only the parameters.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cocoex
import numpy as np

from metaopt import ConfigError, Evaluation, Param, Problem, ProblemInfo, Sense, Space, hookimpl

SUITE = "bbob"
#: The dimensions COCO's bbob suite defines (``cocoex.Suite("bbob", "", "").dimensions``).
DIMENSIONS = (2, 3, 5, 10, 20, 40)
#: COCO's precision target: a run has solved a problem when f(x) - f_opt < 1e-8.
FINAL_TARGET = 1e-8
FUNCTION_NAMES = (
    "sphere",
    "separable ellipsoidal",
    "separable Rastrigin",
    "Büche-Rastrigin",
    "linear slope",
    "attractive sector",
    "step ellipsoidal",
    "Rosenbrock",
    "rotated Rosenbrock",
    "ellipsoidal",
    "discus",
    "bent cigar",
    "sharp ridge",
    "different powers",
    "Rastrigin",
    "Weierstrass",
    "Schaffer F7",
    "ill-conditioned Schaffer F7",
    "composite Griewank-Rosenbrock",
    "Schwefel",
    "Gallagher 101 peaks",
    "Gallagher 21 peaks",
    "Katsuura",
    "Lunacek bi-Rastrigin",
)

PARAMS = (
    Param("function", int, 1, "BBOB function number (1 sphere ... 24 Lunacek)", low=1, high=24),
    Param(
        "dim",
        int,
        10,
        f"number of variables, one of {', '.join(map(str, DIMENSIONS))}",
        low=DIMENSIONS[0],
        high=DIMENSIONS[-1],
    ),
    Param(
        "instance",
        int,
        1,
        "instance: which shifted, rotated copy of the function",
        low=1,
        high=100_000,  # COCO seeds instances with function + 10000 * instance, a C int
    ),
    Param(
        "observe",
        str,
        "",
        "folder for COCO's own output, for cocopp ('' = off; a taken folder gets -0001)",
    ),
)


def observe_folder(observe: str) -> str:
    """The absolute COCO output folder for an ``observe`` value ('' stays ''), or ConfigError.

    COCO splits its options on whitespace, so a folder with spaces cannot be passed to it.
    """
    if not observe:
        return ""
    if any(c.isspace() for c in observe):
        raise ConfigError(
            f"bbob parameter 'observe' = {observe!r}: COCO cannot write to a path with spaces; "
            "choose one without"
        )
    return str(Path(observe).expanduser().absolute())


class BBOBProblem(Problem):
    """One COCO bbob problem over [-5, 5]^dim, minimized; fitness f(x) - f_opt, optimum 0."""

    sense = Sense.MINIMIZE
    optimum = 0.0

    def __init__(self, function: int, dim: int, instance: int, observe: str = "") -> None:
        for param, value in zip(PARAMS, (function, dim, instance, observe)):
            param.validate(value, "bbob")
        if dim not in DIMENSIONS:
            raise ConfigError(
                f"bbob parameter 'dim' = {dim} is invalid; COCO's bbob suite has dimensions "
                f"{', '.join(map(str, DIMENSIONS))}"
            )
        self.function, self.dim, self.instance = function, dim, instance
        self.observe = observe_folder(observe)
        self._connect()

    def _connect(self) -> None:
        """Create the cocoex suite and problem (cheap, writes no file); the observer waits."""
        selection = f"function_indices: {self.function} dimensions: {self.dim}"
        self._suite = cocoex.Suite(SUITE, f"instances: {self.instance}", selection)
        self._coco = self._suite.get_problem_by_function_dimension_instance(
            self.function, self.dim, self.instance
        )
        self._observer: Any = None
        self.f_opt = float(self._bare().best_value())
        self.space = Space.from_bounds(self._coco.lower_bounds, self._coco.upper_bounds)

    def _bare(self) -> Any:
        return cocoex.BareProblem(SUITE, self.function, self.dim, self.instance)

    @property
    def argmin(self) -> np.ndarray:
        """Where f_opt lies (COCO's best parameter)."""
        return np.array(self._bare().best_parameter(), dtype=float)

    @property
    def result_folder(self) -> str:
        """Where COCO writes (with its -0001 suffix if taken), once the first evaluation ran."""
        return str(self._observer.result_folder) if self._observer is not None else ""

    def evaluate(self, x: np.ndarray, seed: int) -> Evaluation:
        """f(x) - f_opt at x; deterministic, so the seed is unused. Logged when observing."""
        if self._coco is None:  # closed, then used again
            self._connect()
        if self.observe and self._observer is None:
            self._observer = self._open_observer()
            self._coco.observe_with(self._observer)
        value = float(self._coco(np.ascontiguousarray(x, dtype=float)))
        return Evaluation(value - self.f_opt, {"f": value})

    def _open_observer(self) -> Any:
        """COCO's observer writing into self.observe; COCO's 'output to folder' line is muted."""
        folder = Path(self.observe)
        options = (
            f"outer_folder: {folder.parent} result_folder: {folder.name} "
            f"algorithm_name: {folder.name}"
        )
        previous = cocoex.log_level("warning")
        try:
            return cocoex.Observer(SUITE, options)
        finally:
            cocoex.log_level(previous)

    def close(self) -> None:
        """Free the cocoex problem, which completes COCO's output files; safe to call twice."""
        if self._coco is not None:
            self._coco.free()
        self._coco = self._suite = self._observer = None

    def __getstate__(self) -> dict[str, Any]:
        keep = ("function", "dim", "instance", "observe")
        return {name: self.__dict__[name] for name in keep}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._connect()


def _description() -> str:
    names = ", ".join(f"{number} {name}" for number, name in enumerate(FUNCTION_NAMES, 1))
    return (
        "COCO's noiseless bbob suite through cocoex. Fitness is the precision f(x) - f_opt "
        f"(optimum 0; COCO's final target is {FINAL_TARGET:g}); the raw f(x) is the metric 'f'. "
        f"Bounds [-5, 5] in every variable. Functions: {names}. Set observe=FOLDER to write "
        "COCO's own output there for cocopp."
    )


@hookimpl
def metaopt_problems() -> list[ProblemInfo]:
    """The bbob problem."""
    return [
        ProblemInfo(
            name="bbob",
            summary="COCO bbob: 24 noiseless black-box functions (cocoex)",
            factory=BBOBProblem,
            params=PARAMS,
            description=_description(),
        )
    ]
