"""``metaopt robustness RUN|NAME ...``: candidates over their problem's standard perturbation
table on every installed engine, ranked when there are several (the work is in
metaopt.assessment.robustness)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import click

from metaopt.assessment import goal_ranking, robustness, search_medians
from metaopt.assessment.candidates import Candidate, find_candidates
from metaopt.cli.common import (
    build_executor,
    console,
    db_option,
    scheduling_options,
)
from metaopt.cli.compare import MAX_SEEDS
from metaopt.cli.output import output_file_option
from metaopt.errors import ConfigError, SettingWarning, once_each
from metaopt.physics import engine_names
from metaopt.plugins import registry
from metaopt.problem import ProblemInfo, Sense
from metaopt.reporting import display
from metaopt.reporting.plain import plain
from metaopt.settings import parse_problem_settings
from metaopt.storage.limits import MAX_STORED_INT


@click.command("robustness")
@click.argument(
    "targets", metavar="RUN|RUN:CANDIDATE|RUN:recommended|NAME...", nargs=-1, required=True
)
@click.option(
    "--top",
    type=click.IntRange(min=1, max=1000),
    default=1,
    show_default=True,
    help="From each run, its K best candidates with distinct vectors, ranked over the table.",
)
@click.option(
    "--last",
    type=click.IntRange(min=1),
    default=None,
    metavar="N",
    help="Take a run's best (or --top K best) among its N latest candidates only: a long noisy "
    "run's latest have been through more of its selection than an early lucky one [all].",
)
@click.option("--engines", default=None, help="Engines joined by '+' [every installed one].")
@click.option(
    "--seeds",
    type=click.IntRange(min=1, max=MAX_SEEDS),
    default=10,
    show_default=True,
    help="Evaluation seeds per perturbation and engine.",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0, max=MAX_STORED_INT),
    default=0,
    show_default=True,
    help="Draws the evaluation seeds (the same ones in every cell).",
)
@click.option(
    "--cells", default=None, metavar="NAME,...", help="Only these perturbations of the table [all]."
)
@click.option(
    "--set",
    "settings",
    multiple=True,
    metavar="NAME=VALUE",
    help="Change one of the candidate's problem parameters first (not one the table sets in "
    "every cell).",
)
@output_file_option(
    "--csv",
    "csv_path",
    "Write the table (every candidate's) as CSV here.",
    suffix=".csv",
)
@output_file_option(
    "--ranking",
    "ranking_path",
    "Write the ranking as CSV here: rank, target (RUN:CANDIDATE, RUN:recommended or NAME, "
    "to name it to another command), candidate, goals missed, goal margin, whether it meets "
    "the goals, score.",
    suffix=".csv",
)
@output_file_option(
    "--figure",
    "figure_path",
    "Draw speed and fall rate per perturbation (PNG) here, of the best-ranked candidate.",
    suffix=".png",
)
@click.option(
    "--goal",
    "goal_texts",
    multiple=True,
    metavar="METRIC>=VALUE",
    help="A bound on a metric's median (a rate's value) over each engine's whole table, e.g. "
    "'speed>=0.44' 'fell<=0.05': rank by the smallest margin to a goal, then by fitness.",
)
@scheduling_options
@db_option
def robustness_command(
    targets: tuple[str, ...], top: int, last: int | None, engines: str | None, seeds: int,
    seed: int, cells: str | None, settings: tuple[str, ...], csv_path: Path | None,
    ranking_path: Path | None, figure_path: Path | None, goal_texts: tuple[str, ...],
    executor: str | None, workers: int | None, scheduler: str | None, db_path: str,
) -> None:  # fmt: skip
    """Evaluate candidates over their problem's standard perturbation table, on every engine,
    over N seeds per cell: a run's best (or its --top K best, among its --last N latest),
    one of its candidates (RUN:CANDIDATE), what its optimizer recommends (RUN:recommended:
    CMA-ES's mean) or a stored one (e.g. a nao-walk gait). Several are ranked by their worst
    engine's mean fitness over the table (with --goal: by their margin to the goals first);
    the best is shown cell by cell, and with --goal which goals it meets."""
    plugins = registry()
    candidates, info = _candidates(targets, top, last, plugins.problems, db_path)
    if info.perturbations is None:
        raise ConfigError(f"problem {info.name!r} has no perturbation table")
    changes = parse_problem_settings(settings, info)
    robustness.check_changes(changes, info.perturbations)
    robustness.check_space_kept(candidates, changes, info)
    candidates = [replace(c, params={**c.params, **changes}) for c in candidates]
    names = engine_names(engines) if engines is not None else tuple(plugins.physics_backends)
    once_each(names, lambda name: f"--engines names {name} twice; name each engine once")
    for name in names:
        plugins.physics_backend(name)  # ConfigError listing the installed ones
    table = robustness.select_cells(
        info.perturbations, [c.strip() for c in cells.split(",")] if cells is not None else None
    )
    goals = [
        robustness.parse_goal(t, table.metrics, table.version, table.only_when) for t in goal_texts
    ]
    # a figure it cannot draw: refused before any work
    drawn_metrics = (
        None if figure_path is None else robustness.figure_metrics(table.metrics, table.version)
    )
    plans = [  # bad parameters: before any work
        robustness.tasks(candidate, info, table, names, seeds, seed) for candidate in candidates
    ]
    differ = robustness.differing_params(candidates, table, robustness.engine_param(info))
    if differ:
        warnings.warn(
            f"the candidates differ in {', '.join(differ)}: each is scored with its own, so "
            "the ranking compares unlike fitnesses where these change the score (--set "
            "NAME=VALUE sets one alike for all)",
            SettingWarning,
            stacklevel=1,
        )
    several = f" x {len(candidates)} candidates" if len(candidates) > 1 else ""
    inert_pairs = sum(len(plan.left_out) for plan in plans)
    evaluations = sum(len(plan.tasks) for plan in plans)
    inert = (f", {evaluations} evaluations (left out: {inert_pairs} x a cell on an engine it "
             "changes nothing on)") if inert_pairs else ""  # fmt: skip
    console.print(plain(f"perturbation table {table.version}: {len(table.cells)} cells x "
                        f"{len(names)} engines x {seeds} seeds{several}{inert}"))  # fmt: skip
    with build_executor(executor, workers, scheduler) as pool:
        results = robustness.evaluate(plans, pool)
    ranked = robustness.rank(
        list(zip(candidates, results, strict=True)), _maximizes(info, candidates[0]), goals
    )
    if len(ranked) > 1:
        console.print(display.robustness_ranking(ranked, table.version, table.metrics, goals))
    best = ranked[0]
    # the best candidate's plan; by identity, as a Candidate (it holds an array) is unhashable
    left_out_of = {id(c): plan.left_out for c, plan in zip(candidates, plans, strict=True)}
    console.print(
        display.robustness_table(
            best.candidate.label,
            table.version,
            best.results,
            table.metrics,
            best.totals,
            left_out_of[id(best.candidate)],
        )
    )
    if goals:
        console.print(plain(display.goal_verdict(best.candidate.label, best.totals, goals)))
    if csv_path is not None:
        robustness.write_csv(
            csv_path, table,
            [(r.candidate, [*r.results, *r.totals]) for r in ranked],
        )  # fmt: skip
        console.print(plain(f"wrote {csv_path}"))
    if ranking_path is not None:
        robustness.write_ranking(ranking_path, ranked)
        console.print(plain(f"wrote {ranking_path}"))
    if drawn_metrics is not None:
        from metaopt.reporting.plots import save_figure

        save_figure(
            robustness.figure(best.candidate, table, best.results, *drawn_metrics), figure_path
        )
        console.print(plain(f"wrote {figure_path}"))


def _candidates(
    targets: tuple[str, ...], top: int, last: int | None, problems: dict, db_path: str
) -> tuple[list[Candidate], ProblemInfo]:
    """Every target's candidates, all of one problem (a ranking compares like with like), each
    once (``1 1``, or ``1`` and ``1:N`` of its best, would rank one candidate twice)."""
    found = [find_candidates(target, problems, db_path, top, last) for target in targets]
    info = found[0][1]
    for target, (_, other) in zip(targets, found, strict=True):
        if other.name != info.name:
            raise ConfigError(
                f"{target!r} is a candidate of {other.name!r}, {targets[0]!r} of "
                f"{info.name!r}: rank candidates of one problem"
            )
    named = [(t, c) for t, (candidates, _) in zip(targets, found, strict=True) for c in candidates]
    once_each(named, _named_again, key=lambda pair: pair[1].target)
    return [candidate for _, candidate in named], info


def _named_again(pair: tuple[str, Candidate]) -> str:
    """The refusal of a target naming a candidate an earlier target names (the same target
    again, or ``1:N`` after ``1`` whose best is N)."""
    target, candidate = pair
    return (
        f"{target!r} names {candidate.label} again; each candidate counts once in the ranking, "
        "so name each once"
    )


#: what a refusal of a file given twice accepts
_EACH_ONCE = "each table counts once, so give each file once"


def _given_twice(path: Path) -> str:
    """The refusal of a robustness table given twice."""
    return f"{path} is given twice; {_EACH_ONCE}"


def _against_itself(path: Path) -> str:
    """The refusal of a baseline that is also one of the searches: a table paired with itself
    differs by nothing, and a design's search is no baseline of it."""
    return (
        f"--against {path} is also given as a search; a baseline is another design's table "
        "(on the same seed), so give each table once, as a search or after --against"
    )


def _maximizes(info: ProblemInfo, candidate: Candidate) -> bool:
    """Whether the candidate's problem is maximized (its instances say; building one is cheap:
    engines are built on first use)."""
    problem = info.factory(**candidate.params)
    try:
        return problem.sense == Sense.MAXIMIZE
    finally:
        problem.close()


#: the robustness tables (robustness --csv) that robustness-summary and robustness-rank read
_csv_tables = click.argument(
    "csv_paths", metavar="CSV...", nargs=-1, required=True,
    type=click.Path(dir_okay=False, path_type=Path),
)  # fmt: skip


def _alike_with_goals(
    tables: list[search_medians.SearchTable], goal_texts: tuple[str, ...]
) -> tuple[list[search_medians.SearchTable], list[robustness.Goal]]:
    """The tables on the metrics they share, once checked alike, and the goals parsed
    against those metrics (and the installed table's only_when, where its version is one)."""
    tables = search_medians.alike(tables)
    first = tables[0]
    only_when = next(
        (
            info.perturbations.only_when
            for info in registry().problems.values()
            if info.perturbations is not None and info.perturbations.version == first.version
        ),
        {},
    )
    return tables, [
        robustness.parse_goal(t, first.metrics, first.version, only_when) for t in goal_texts
    ]


@click.command("robustness-summary")
@_csv_tables
@click.option(
    "--goal",
    "goal_texts",
    multiple=True,
    metavar="METRIC>=VALUE",
    help="A bound on a metric (as robustness --goal), checked on each engine's median over "
    "the searches.",
)
@click.option(
    "--against",
    "against_paths",
    multiple=True,
    metavar="CSV",
    type=click.Path(dir_okay=False, path_type=Path),
    help="A baseline search's table, once per CSV in the same order (the same seed, another "
    "design or less time): also shows the median of the paired differences.",
)
@output_file_option(
    "--csv",
    "csv_path",
    "Write the figures as CSV here: each search's per engine, then the medians and standard "
    "deviations over the searches (and the median paired differences).",
    suffix=".csv",
)
@output_file_option(
    "--figure",
    "figure_path",
    "Draw each search's speed against its fall rate, per engine, with the median and the "
    "goals' bounds (PNG) here.",
    suffix=".png",
)
def robustness_summary_command(
    csv_paths: tuple[Path, ...],
    goal_texts: tuple[str, ...],
    against_paths: tuple[Path, ...],
    csv_path: Path | None,
    figure_path: Path | None,
) -> None:
    """Summarise several searches of one design: each CSV is one search's chosen candidate
    over the perturbation table (robustness --csv); shows each search's whole-table figures
    per engine and their median and standard deviation over the searches, against the
    goals. A search is one chaotic trajectory: a design is judged by medians over its seeds,
    and two designs run on the same seeds by their paired differences (--against)."""
    once_each(csv_paths, _given_twice)
    once_each(against_paths, lambda path: f"--against {path} is given twice; {_EACH_ONCE}")
    once_each([*csv_paths, *against_paths], _against_itself)  # a repeat here is a baseline
    tables = [search_medians.read_table(path) for path in csv_paths]
    baselines = [search_medians.read_table(path) for path in against_paths]
    compared, goals = _alike_with_goals([*tables, *baselines], goal_texts)
    tables, baselines = compared[: len(tables)], compared[len(tables) :]
    paired = search_medians.paired_differences(tables, baselines) if baselines else None
    summary = search_medians.medians(tables)
    # drawn before anything is printed or written: a table it cannot draw is refused first
    drawn = None if figure_path is None else search_medians.figure(tables, summary, goals)
    console.print(display.search_medians_table(tables, summary))
    if goals:
        console.print(plain(display.search_medians_verdict(tables, summary, goals)))
    if paired is not None:
        console.print(display.paired_differences_table(paired, tables[0].metrics))
    if csv_path is not None:
        search_medians.write_medians(csv_path, tables, summary, paired)
        console.print(plain(f"wrote {csv_path}"))
    if drawn is not None:
        from metaopt.reporting.plots import save_figure

        save_figure(drawn, figure_path)
        console.print(plain(f"wrote {figure_path}"))


@click.command("robustness-rank")
@_csv_tables
@click.option(
    "--goal",
    "goal_texts",
    multiple=True,
    required=True,
    metavar="METRIC>=VALUE",
    help="A bound on a metric's median (a rate's value) over each engine's whole table, as "
    "robustness --goal.",
)
@output_file_option(
    "--ranking",
    "ranking_path",
    "Write the ranking as CSV here: rank, file, candidate, goals missed, goal margin, whether "
    "it meets the goals.",
    suffix=".csv",
)
def robustness_rank_command(
    csv_paths: tuple[Path, ...], goal_texts: tuple[str, ...], ranking_path: Path | None
) -> None:
    """Rank the candidates of robustness tables (robustness --csv, e.g. a race's) again
    against other goals, from the files alone: by their smallest margin to a goal on any
    engine, as robustness --goal ranks, without evaluating anything. Equal margins keep the
    files' order."""
    once_each(csv_paths, _given_twice)
    tables = [table for path in csv_paths for table in search_medians.read_tables(path)]
    tables, goals = _alike_with_goals(tables, goal_texts)
    ranked = goal_ranking.rank_by_goals(tables, goals)
    console.print(display.goal_ranking_table(ranked, goals))
    if ranking_path is not None:
        goal_ranking.write_goal_ranking(ranking_path, ranked)
        console.print(plain(f"wrote {ranking_path}"))
