"""Finding a candidate by name: a problem's stored candidate (e.g. a nao-walk gait), a run's
best (or its best few) or one candidate of a run, for the commands that test one (robustness) or
start from one (run --start-from).

Targets: ``NAME`` (a stored candidate), ``RUN`` (the run's best), ``RUN:NUMBER`` (candidate
NUMBER of the run, as ``metaopt robustness RUN --top K`` labels them) and ``RUN:recommended``
(what the run's optimizer recommends beside its best: metaopt.assessment.recommendation)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from metaopt.assessment.recommendation import RECOMMENDED, recommended_point
from metaopt.errors import ConfigError, StoreError
from metaopt.params import resolve
from metaopt.problem import ProblemInfo
from metaopt.space import Space
from metaopt.warm_start import fitted_start


@dataclass(frozen=True)
class Candidate:
    """What is tested: a decision vector and the problem parameters it was found with;
    ``target``: how a command names it again (``RUN:NUMBER`` or a stored candidate's name)."""

    label: str
    problem: str
    params: Mapping[str, Any]
    x: np.ndarray
    target: str = ""


def find_candidate(
    target: str, problems: Mapping[str, ProblemInfo], db_path: str
) -> tuple[Candidate, ProblemInfo]:
    """``target`` as one candidate: a problem's stored candidate by name, else a run id in the
    store at db_path, whose best candidate is taken (by its aggregate when it resampled),
    ``RUN:NUMBER``, that run's candidate NUMBER, or ``RUN:recommended``."""
    candidates, info = find_candidates(target, problems, db_path, 1)
    return candidates[0], info


def find_candidates(
    target: str,
    problems: Mapping[str, ProblemInfo],
    db_path: str,
    top: int,
    last: int | None = None,
) -> tuple[list[Candidate], ProblemInfo]:
    """``target``'s candidates: a stored candidate, ``RUN:NUMBER`` or ``RUN:recommended``
    alone; for a run id, its ``top`` best candidates with distinct decision vectors, best
    first, among its ``last`` latest when given (labelled ``run R`` when they are its one
    best, else ``run R candidate N``, N being what ``RUN:N`` names)."""
    named = stored_candidate_named(target, problems)
    if named is not None:
        candidate, info, _ = named
        return [candidate], info
    from metaopt.storage.run_store import RunStore

    check_run_target(target, problems, db_path)
    run_id, _, number = target.partition(":")
    with RunStore(db_path) as store:
        run = store.run(run_id)
        if number != RECOMMENDED:
            records = (
                [store.candidate(run, int(number))]
                if number
                else store.best_candidates(run, top, last)
            )
            if not records:
                among = f" among its {last} latest candidates" if last is not None else ""
                raise StoreError(f"run {run.id} has no successful evaluation{among}")
    info = problems.get(run.problem)
    if info is None:
        raise ConfigError(f"run {run.id}'s problem {run.problem!r} is not installed")
    params = resolve(info.params, run.problem_params, info.name)
    if number == RECOMMENDED:
        point = recommended_point(run)
        named = f"{run.id}:{RECOMMENDED}"  # as the run's other candidates: '01' names run 1
        return [Candidate(f"run {run.id} recommended", info.name, params, point, named)], info
    best_alone = top == 1 and last is None and not number
    return [
        Candidate(
            f"run {run.id}" if best_alone else f"run {run.id} candidate {r.number}",
            info.name, params, r.x, target=f"{run.id}:{r.number}",
        )
        for r in records
    ], info  # fmt: skip


def stored_candidate_named(
    name: str, problems: Mapping[str, ProblemInfo]
) -> tuple[Candidate, ProblemInfo, int] | None:
    """The candidate an installed problem keeps as data under ``name`` (its parameters
    resolved), that problem, and the evaluation seed it was recorded with; None if none
    does."""
    for info in problems.values():
        stored = info.stored_candidates() if info.stored_candidates else {}
        if name in stored:
            params = resolve(info.params, stored[name].params, info.name)
            candidate = Candidate(name, info.name, params, stored[name].x, name)
            return candidate, info, stored[name].seed
    return None


def check_run_target(target: str, problems: Mapping[str, ProblemInfo], db_path: str) -> None:
    """ConfigError, naming what is accepted, unless ``target`` reads ``RUN``, ``RUN:NUMBER`` or
    ``RUN:recommended`` and a store exists at db_path (for a target that is no stored
    candidate's name)."""
    run_id, _, number = target.partition(":")
    if not run_id.isdigit() or (number and not number.isdigit() and number != RECOMMENDED):
        names = sorted(n for i in problems.values() if i.stored_candidates
                       for n in i.stored_candidates())  # fmt: skip
        raise ConfigError(
            f"{target!r} is neither a stored candidate ({', '.join(names) or 'none'}) nor "
            "a run (RUN, RUN:CANDIDATE or RUN:recommended)"
        )
    if not Path(db_path).exists():
        raise ConfigError(
            f"no run store at {db_path} to find run {target} in; run `metaopt run` first or "
            "pass --db PATH"
        )


def find_start(
    target: str,
    problem: ProblemInfo,
    problem_params: Mapping[str, Any],
    problems: Mapping[str, ProblemInfo],
    db_path: str,
) -> tuple[str, list[float]]:
    """``target`` (as find_candidate finds it) as a start point of a run of ``problem`` with
    ``problem_params``, in that run's variable order (metaopt.warm_start.fitted_start), with
    the candidate's label (what `show` says the run started from)."""
    candidate, info = find_candidate(target, problems, db_path)
    return candidate.label, _fitted(repr(target), candidate, info, problem, problem_params)


def stored_start(
    name: str,
    problem: ProblemInfo,
    problem_params: Mapping[str, Any],
    problems: Mapping[str, ProblemInfo],
) -> list[float]:
    """The stored candidate ``name`` as a start point of a run of ``problem`` with
    ``problem_params``, for an experiment file (which names no run: its runs' store is the
    comparison's); ConfigError naming what is accepted otherwise."""
    named = stored_candidate_named(name, problems)
    if named is None:
        names = sorted(n for i in problems.values() if i.stored_candidates
                       for n in i.stored_candidates())  # fmt: skip
        raise ConfigError(
            f"start_from {name!r} is not a stored candidate ({', '.join(names) or 'none'}); "
            "an experiment starts from stored candidates by name, or from values: "
            "settings.start = [[...]]"
        )
    candidate, info, _ = named
    return _fitted(repr(name), candidate, info, problem, problem_params)


def _fitted(
    label: str,
    candidate: Candidate,
    info: ProblemInfo,
    problem: ProblemInfo,
    problem_params: Mapping[str, Any],
) -> list[float]:
    """``candidate`` (of ``info``) as a start point of ``problem`` built with
    ``problem_params``; ConfigError unless it is a candidate of that problem whose variables
    are the run's, or the run's less some with a neutral value."""
    if info.name != problem.name:
        raise ConfigError(
            f"{label} is a candidate of {info.name!r}, not of {problem.name!r}: start from "
            f"a run or stored candidate of {problem.name!r}"
        )
    names = space_of(info, candidate.params).names
    space = space_of(problem, resolve(problem.params, dict(problem_params), problem.name))
    return fitted_start(label, names, candidate.x, space)


def space_of(info: ProblemInfo, params: Mapping[str, Any]) -> Space:
    """The search space of ``info``'s problem built with ``params`` (cheap: a problem builds
    its engines on first use), closed again."""
    problem = info.factory(**params)
    try:
        return problem.space
    finally:
        problem.close()
