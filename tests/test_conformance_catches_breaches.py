"""The conformance kit catches each kind of breach, in the right check, saying what to fix."""

from __future__ import annotations

import pytest

from metaopt.testing import (
    ConformanceError,
    check_optimizer,
    check_problem,
    optimizer_checks,
    problem_checks,
)
from tests.fixtures import broken_plugins as broken

OPTIMIZER_BREACHES = [
    (broken.OUT_OF_BOUNDS, "ask_tell_shapes", ["outside the space", "space.repair"]),
    (broken.IGNORES_N, "ask_tell_shapes", ["ask(1) returned shape (4, 1), expected (1, 1)"]),
    (broken.FORGETS_RNG, "state_round_trip", ["differs from the uninterrupted run", "rng_state"]),
    (broken.NUMPY_STATE, "state_round_trip", ["state['center'] is numpy.ndarray", ".tolist()"]),
    (broken.RECOMMENDS_OUTSIDE, "recommendation", ["outside the space", "space.repair"]),
    (broken.GLOBAL_RANDOM, "deterministic", ["seed 7", "never from np.random"]),
    (broken.CRASHES_ON_INF, "tell_inf", ["OverflowError", "+inf", "worse than any finite"]),
    (broken.MAXIMIZER, "minimizes", ["no better than the median", "must minimize"]),
    (broken.RENAMED_PARAM, "factory_keywords", ["no keyword argument", "'step'"]),
    (broken.BAD_DEFAULT, "declared_params", ["default 2.0", "a float in [0, 1]"]),
    (broken.NO_BUDGET, "declares_budget", ["no int parameter 'budget'", "budget_param()"]),
]

PROBLEM_BREACHES = [
    (broken.IMPURE, "pure", ["pure function of (x, seed)", "no counters"]),
    (broken.NAN_FITNESS, "evaluate", ["fitness is nan", "finite float"]),
    (broken.ARRAY_FITNESS, "evaluate", ["fitness is numpy.ndarray", "float(value)"]),
    (broken.FLOAT32_METRICS, "evaluate", ["metric 'distance' is numpy.float32", "Python floats"]),
    (broken.MISSING_KEY_METRIC, "key_metrics", ["['energy']", "drop it from key_metrics"]),
]


def _caught(check, phrases: list[str]) -> None:
    with pytest.raises(ConformanceError) as caught:
        check()
    for phrase in phrases:
        assert phrase in str(caught.value)


def test_the_sound_plugins_pass_every_check():
    check_optimizer(broken.SOUND_OPTIMIZER)
    check_problem(broken.SOUND_PROBLEM, in_subprocess=True)


@pytest.mark.parametrize(
    ("info", "check", "phrases"), OPTIMIZER_BREACHES, ids=[b[0].name for b in OPTIMIZER_BREACHES]
)
def test_an_optimizer_breach_is_caught_by_its_check(info, check, phrases):
    _caught(optimizer_checks(info)[check], phrases)


@pytest.mark.parametrize(
    ("info", "check", "phrases"), PROBLEM_BREACHES, ids=[b[0].name for b in PROBLEM_BREACHES]
)
def test_a_problem_breach_is_caught_by_its_check(info, check, phrases):
    _caught(problem_checks(info)[check], phrases)


def test_check_optimizer_lists_every_breached_check():
    with pytest.raises(ConformanceError, match=r"'GlobalRandom' breaks 2 of 9 checks") as caught:
        check_optimizer(broken.GLOBAL_RANDOM)
    assert "- deterministic:" in str(caught.value)
    assert "- state_round_trip:" in str(caught.value)


def test_a_problem_that_depends_on_its_process_is_caught_by_the_subprocess_check():
    problem_checks(broken.PROCESS_DEPENDENT)["pure"]()  # the same in this process
    check = problem_checks(broken.PROCESS_DEPENDENT, in_subprocess=True)["pure_in_subprocess"]
    _caught(check, ["in another process", "pure function of (x, seed)"])
