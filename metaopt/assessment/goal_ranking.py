"""Candidates ranked again against other goals from their robustness tables (the CSV
`metaopt robustness --csv` writes), without evaluating anything: how a race's choice would
change with another bound (say a fall rate of 5 % rather than 2 %), by the same margins
`metaopt robustness --goal` ranks by."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from metaopt.assessment.robustness import Goal, write_rows
from metaopt.assessment.search_medians import SearchTable


@dataclass(frozen=True)
class GoalRanked:
    """A candidate's table with the (goal, engine) pairs it misses and its smallest margin to
    a goal on any engine (Goal.margin_in)."""

    table: SearchTable
    missed: int
    margin: float


def rank_by_goals(tables: Sequence[SearchTable], goals: Sequence[Goal]) -> list[GoalRanked]:
    """The candidates by their smallest margin to a goal on any engine, largest first, as
    `metaopt robustness --goal` ranks them; equal margins keep the given order (a file's own
    ranking: the fitness that broke ties there is not in the CSV)."""
    ranked = []
    for table in tables:
        margins = [
            goal.margin_in(figures, table.failed[engine])
            for goal in goals
            for engine, figures in table.figures.items()
        ]
        ranked.append(GoalRanked(table, sum(m < 0 for m in margins), min(margins)))
    return sorted(ranked, key=lambda r: -r.margin)


RANKING_COLUMNS = ("rank", "source", "candidate", "goals_missed", "goal_margin", "meets_goals")


def write_goal_ranking(path: Path, ranked: Sequence[GoalRanked]) -> None:
    """One row per candidate, best first: its rank, file, label, the (goal, engine) pairs it
    misses, its goal margin and whether it meets every goal. Written whole or not at all."""
    rows = [
        [number, r.table.source, r.table.candidate, r.missed, r.margin, r.missed == 0]
        for number, r in enumerate(ranked, start=1)
    ]
    write_rows(path, list(RANKING_COLUMNS), rows)
