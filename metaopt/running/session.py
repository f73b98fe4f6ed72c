"""One run's loop: asks the optimizer, has an executor evaluate, stores every evaluation, tells
the results in order, and keeps counters, the best so far and checkpoints (resumable)."""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, BrokenExecutor, Future, as_completed, wait
from contextlib import contextmanager
from dataclasses import dataclass, replace
from functools import partial
from itertools import chain, islice
from typing import Any

import numpy as np

from metaopt.errors import RunFailed, SettingWarning
from metaopt.executors.base import SCREEN_BOUND, EvaluationTask, Executor, Outcome, problem_key
from metaopt.optimizer import Optimizer
from metaopt.problem import Evaluation, Problem, ProblemInfo, Sense
from metaopt.resampling import aggregate_fitness, aggregate_metrics
from metaopt.running.signals import RunInterrupted, stop_on_sigterm
from metaopt.running.spec import MAX_TIME_STOP, Progress, RunResult, RunSpec
from metaopt.seeding import CommonSeeds, EvaluationSeeds
from metaopt.storage.run_store import EvaluationRecord, RunRecord, RunStore
from metaopt.warm_start import start_points

CHECKPOINT_INTERVAL = 1.0
#: A run whose first this many evaluations all failed stops as failed rather than spend its
#: budget on a problem set up so that nothing can succeed (docs/index.md).
ALL_FAILED_STOP = 10


@dataclass
class Candidate:
    """A candidate being evaluated: its samples' outcomes as they come back."""

    number: int
    x: np.ndarray
    outcomes: list[Outcome | None]
    #: the fitness the optimizer is told in place of the candidate's own, set where screening
    #: ranked it below the optimizer's selected ranks (a bound, or past the cut)
    bound: float | None = None

    @property
    def complete(self) -> bool:
        return all(o is not None for o in self.outcomes)


class Session:
    """One run's loop state: counters, best so far, checkpoints."""

    def __init__(
        self,
        run_id: int,
        spec: RunSpec,
        optimizer: Optimizer,
        problem: Problem,
        problem_info: ProblemInfo,
        store: RunStore,
        problem_params: dict[str, Any],
    ) -> None:
        self.run_id = run_id
        self.spec = spec
        self.settings = spec.settings
        self.optimizer = optimizer
        self.problem = problem
        self.store = store
        self.factory = problem_info.factory
        self.problem_params = problem_params
        self.problem_key = problem_key(problem_info.factory, problem_params)
        self.sign = -1.0 if Sense(problem.sense) is Sense.MAXIMIZE else 1.0
        self.resample = self.settings.resample
        #: sync mode: candidates asked per batch
        self.batch_size = self.settings.batch_size(optimizer)
        common = self.settings.common_seeds
        self.seeds = (
            EvaluationSeeds(spec.seed)
            if common == "off"
            else CommonSeeds(
                spec.seed, self.resample, self.batch_size if common == "batch" else None
            )
        )
        self.total = (spec.budget // self.resample) * self.resample
        self.told_below = 0  # every candidate whose evaluations all lie below this is told
        self.told_extra: set[int] = set()  # candidates told beyond told_below (async)
        self.stored = self.failed = self.screened = 0
        self.first_error: str | None = None
        #: the loop leaves on a break or an interrupt, storing every outcome that finished
        #: (no all-failed stop cuts that short)
        self.keeping = False
        self.best_score = math.inf
        target = self.settings.target
        #: the optimizer's (minimizing) score at which the run stops
        self.target_score = -math.inf if target is None else self.sign * target
        self.best: tuple[float, np.ndarray, dict[str, float]] | None = None
        self.deadline = math.inf  # perf_counter() past which no candidate is asked (max_time)
        self.reusable: dict[int, EvaluationRecord] = {}
        self.last_checkpoint = time.perf_counter()
        settings = self.settings
        #: the warm start's candidates, numbered from 0 (none without a warm start)
        self.start = (
            np.empty((0, problem.space.dim))
            if settings.start is None
            else start_points(
                problem.space, settings.start, settings.start_spread, settings.start_points,
                spec.seed,
            )
        )  # fmt: skip

    # -- resume ----------------------------------------------------------------------------

    def restore(self, record: RunRecord, checkpoint: dict) -> None:
        """Counters, best so far and reusable evaluations from the store."""
        self.told_below = checkpoint["told_below"]
        self.told_extra = set(checkpoint["told_extra"])
        by_candidate: dict[int, list[EvaluationRecord]] = {}
        for evaluation in self.store.evaluations(record.id):
            self.stored += 1
            self.failed += evaluation.status == "failed"
            self.screened += evaluation.status == "screened"
            by_candidate.setdefault(evaluation.candidate, []).append(evaluation)
        for number, evaluations in by_candidate.items():
            if len(evaluations) == self.resample and self._was_told(number):
                outcomes = [_outcome_of(e) for e in evaluations]
                self._score(Candidate(number, evaluations[0].x, outcomes))
            elif not self._was_told(number):
                self.reusable.update((e.index, e) for e in evaluations)
        # counted again when reused (_count) or evaluated again (_record); a resumed
        # batch is screened again (_reused_complete): its screens are counted then
        for evaluation in self.reusable.values():
            self.stored -= 1
            self.failed -= evaluation.status == "failed"
            self.screened -= evaluation.status == "screened"

    def _count(self, outcome: Outcome) -> None:
        """Count a stored outcome: one just recorded, or one taken on resume (restore left the
        reusable ones out of the counts)."""
        self.stored += 1
        self.failed += outcome.error is not None
        self.screened += outcome.screened

    def _was_told(self, number: int) -> bool:
        return (number + 1) * self.resample <= self.told_below or number in self.told_extra

    # -- the loop --------------------------------------------------------------------------

    def execute(self, executor: Executor, progress: Progress | None) -> RunResult:
        """Run the loop to its end on ``executor`` and store how it ended (finished, failed or
        interrupted), everything evaluated kept."""
        # Starting and stopping the executor's workers (a Dask cluster: seconds) is part of the
        # run's cost: its wall time counts both.
        started = time.perf_counter() - executor.startup_time
        if self.settings.max_time is not None:
            self.deadline = started + self.settings.max_time
        status, message = "failed", None
        if progress is not None:
            progress.start(self.total, self.stored)
        try:
            with stop_on_sigterm():
                if self.settings.mode == "sync":
                    self._run_sync(executor, progress)
                else:
                    self._run_async(executor, progress)
            if self.best is None:
                raise RunFailed(self._why_failed())
            status = "finished"
            if self.stored < self.total and self.out_of_time and not self.target_met:
                message = (
                    f"{MAX_TIME_STOP} of {self.settings.max_time:g} s after "
                    f"{self.stored} of {self.total} evaluations"
                )
        except RunFailed as error:
            message = str(error)
            raise
        except KeyboardInterrupt:
            status, message = "interrupted", "stopped by the user (Ctrl-C or SIGTERM)"
            raise RunInterrupted(self.run_id, self.stored) from None
        except BaseException as error:
            message = f"{type(error).__name__}: {error}"
            raise
        finally:
            try:
                executor.shutdown()
            except KeyboardInterrupt:
                # Ctrl-C again here: the RunInterrupted under way (its run id and count, the
                # CLI's resume line) carries on, not this bare one.
                if status != "interrupted":
                    raise
            finally:  # a second Ctrl-C as the workers stop (seconds) still marks the run
                # A checkpoint is only ever taken right after a tell: an interrupted run keeps
                # its last one, and the evaluations stored since are reused when it is resumed.
                final = (self.run_id, self._checkpoint()) if status == "finished" else None
                self.store.flush(checkpoint=final)
                wall_time = time.perf_counter() - started  # the stored and the reported
                self.store.finish_run(self.run_id, status, wall_time, message)
        return self._result(status, wall_time)

    def _warn_of_waiting_workers(self, batch: int, workers: int) -> None:
        """SettingWarning when a sync batch has fewer evaluations than the executor has
        workers: the others wait at every batch (HS asks one candidate at a time)."""
        tasks = batch * self.resample
        if tasks < workers:
            wanted = math.ceil(workers / self.resample)
            candidates = f"{batch} candidate{'s' if batch > 1 else ''}"
            each = f" of {self.resample} evaluations" if self.resample > 1 else ""
            idle = workers - tasks
            warnings.warn(
                f"{self.spec.optimizer} asks {candidates} per batch{each}: {idle} of the "
                f"{workers} workers {'waits' if idle == 1 else 'wait'} at every batch; ask for "
                f"{wanted} per batch (--batch {wanted}; sync results depend on the batch, not "
                "the workers) or run in --mode async",
                SettingWarning,
                stacklevel=2,
            )

    def _run_sync(self, executor: Executor, progress: Progress | None) -> None:
        batch_size = self.batch_size
        self._warn_of_waiting_workers(batch_size, executor.workers)
        next_index = self.told_below
        while next_index < self.total and not self.stopping:
            first = next_index // self.resample
            # Batch k holds candidates k * batch_size onwards, also after a resume that raised
            # the budget past a short last batch: the optimizer is asked as in the longer run.
            count = min(batch_size - first % batch_size, (self.total - next_index) // self.resample)
            candidates = [
                Candidate(first + i, x, [None] * self.resample)
                for i, x in enumerate(self._ask(first, count))
            ]
            if self.settings.screen:
                self._screen_and_complete(executor, candidates)
            else:
                self._evaluate(executor, candidates)
            scores = np.array([self._score(c) for c in candidates])
            self.optimizer.tell(np.array([c.x for c in candidates]), scores)
            next_index += count * self.resample
            self.told_below = next_index
            self._after_tell(progress)

    def _run_async(self, executor: Executor, progress: Progress | None) -> None:
        in_flight: dict[Future, Candidate] = {}

        def take(future: Future) -> None:
            """Store a finished outcome; its candidate, once complete, is told at once."""
            candidate = self._keep(in_flight, future)
            if candidate.complete:
                self._tell_one(candidate, progress)

        open_candidates = self._unfinished_candidates()
        with self._keeping_finished(in_flight, partial(self._keep, in_flight)):
            for candidate in open_candidates:
                if candidate.complete:
                    self._tell_one(candidate, progress)
                else:
                    self._submit(executor, [candidate], in_flight)
            numbers = self._numbers_to_ask({c.number for c in open_candidates}, len(in_flight))
            number = next(numbers, None)
            while in_flight or (number is not None and not self.stopping):
                while (
                    len(in_flight) < executor.capacity and number is not None and not self.stopping
                ):
                    candidate = Candidate(number, self._ask(number, 1)[0], [None] * self.resample)
                    self._submit(executor, [candidate], in_flight)
                    number = next(numbers, None)
                done, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
                # as submitted, not in the set's order (by address): the same outcomes are told
                # in the same order, and a break or an interrupt among them meets the same ones
                for future in [f for f in in_flight if f in done]:
                    take(future)

    def _numbers_to_ask(self, open_numbers: set[int], started: int) -> Iterator[int]:
        """The candidate numbers an async run asks, in order: on a resume first each one below
        the highest told or stored that is neither (it was in flight when the run stopped), as
        many as the budget has room for beside the ``started`` evaluations (a resume's budget
        may lie below the highest stored index); then new ones up to the budget."""
        known = open_numbers | self.told_extra
        told_below = self.told_below // self.resample
        first_new = max([told_below, *(n + 1 for n in known)])
        missing = (n for n in range(told_below, first_new) if n not in known)
        room = max(0, (self.total - self.stored - started) // self.resample)
        return chain(islice(missing, room), range(first_new, self.total // self.resample))

    @contextmanager
    def _keeping_finished(
        self, futures: dict[Future, Candidate], keep: Callable[[Future], object]
    ) -> Iterator[None]:
        """Where the executor breaks inside (BrokenExecutor), Ctrl-C stops the run
        (KeyboardInterrupt) or the run fails (RunFailed: all failed so far, a screen no bound),
        every future of ``futures`` not yet taken that finished with an outcome is stored
        (``keep``) before the run ends, and a resume reuses it instead of evaluating it again.
        Stored only, neither told nor checkpointed (a resume tells it): rows queued in memory,
        soon done; a second Ctrl-C that cuts it short loses rows, and leaves the store's flush
        to run."""
        try:
            yield
        except (BrokenExecutor, KeyboardInterrupt, RunFailed):
            self.keeping = True
            for future in list(futures):
                if future.done() and not future.cancelled() and future.exception() is None:
                    keep(future)
            raise

    def _keep(self, futures: dict[Future, Candidate], future: Future) -> Candidate:
        """Store a finished future's outcome, taking it out of ``futures``; its candidate."""
        candidate = futures.pop(future)
        self._record(candidate, future.result())
        return candidate

    def _ask(self, first: int, count: int) -> np.ndarray:
        """Candidates number first to first + count - 1: the warm start's points while they
        last, then the optimizer's, which is told the start points as if it had asked them."""
        if first >= len(self.start):  # past the start points (always, without a warm start)
            return self.optimizer.ask(count)
        starting = self.start[first : first + count]
        if len(starting) == count:
            return starting
        return np.concatenate([starting, self.optimizer.ask(count - len(starting))])

    @property
    def stopping(self) -> bool:
        """No more candidates are asked: a fitness at the target or better has been found
        (never without a target), or the run's max time has passed (never without one)."""
        return self.target_met or self.out_of_time

    @property
    def target_met(self) -> bool:
        return self.best_score <= self.target_score

    @property
    def out_of_time(self) -> bool:
        return time.perf_counter() >= self.deadline

    def _tell_one(self, candidate: Candidate, progress: Progress | None) -> None:
        self.optimizer.tell(candidate.x[None, :], np.array([self._score(candidate)]))
        self.told_extra.add(candidate.number)
        self._advance_told_below()
        self._after_tell(progress)

    def _unfinished_candidates(self) -> list[Candidate]:
        """Resumed async runs: candidates stored but not told, with their stored outcomes."""
        grouped: dict[int, Candidate] = {}
        for index, evaluation in sorted(self.reusable.items()):
            number = index // self.resample
            candidate = grouped.setdefault(
                number, Candidate(number, evaluation.x, [None] * self.resample)
            )
            candidate.outcomes[index % self.resample] = outcome = _outcome_of(evaluation)
            self._count(outcome)
        self.reusable.clear()
        return sorted(grouped.values(), key=lambda c: c.number)

    def _advance_told_below(self) -> None:
        while self.told_below // self.resample in self.told_extra:
            self.told_extra.discard(self.told_below // self.resample)
            self.told_below += self.resample

    def _submit(
        self, executor: Executor, candidates: list[Candidate], futures: dict[Future, Candidate]
    ) -> None:
        """Start every missing sample of the candidates, each future into ``futures`` as it is
        started (a later submit may raise); stored ones (resume) are reused."""
        for candidate in candidates:
            for sample in range(self.resample):
                if candidate.outcomes[sample] is not None:
                    continue
                index = candidate.number * self.resample + sample
                stored = self.reusable.pop(index, None)
                if stored is not None and stored.x.tobytes() == candidate.x.tobytes():
                    candidate.outcomes[sample] = outcome = _outcome_of(stored)
                    self._count(outcome)
                    continue
                futures[executor.submit(self._task(candidate, index))] = candidate

    def _task(
        self, candidate: Candidate, index: int, phase: str = "evaluate",
        screened: Evaluation | None = None,
    ) -> EvaluationTask:  # fmt: skip
        return EvaluationTask(
            index, candidate.x, self.seeds(index), self.factory, self.problem_params,
            self.settings.time_limit, self.problem_key, phase, screened,
        )  # fmt: skip

    def _screen_and_complete(self, executor: Executor, candidates: list[Candidate]) -> None:
        """Screen the batch, then complete its candidates best bound first until no other can
        enter the optimizer's selected ranks: candidate j is completed unless ``selected`` of
        those before it scored better than its bound (none after it can: their full fitness
        is no better than their bound). The cut depends on the scores alone, not on timing,
        so a run is the same for any number of workers; those started ahead of the cut
        (one per idle worker) are stored complete, and told their bound like the rest."""
        reused = self._reused_complete(candidates)
        screened = self._screens(executor, candidates)
        for candidate in candidates:
            if screened[candidate.number].fitness is None:  # a failed screen fails it
                self._record(candidate, screened[candidate.number])
        order = sorted(
            (c for c in candidates if screened[c.number].fitness is not None),
            key=lambda c: (self.sign * screened[c.number].fitness, c.number),
        )
        bounds = [self.sign * screened[c.number].fitness for c in order]
        selected = self.optimizer.selected
        assert selected is not None, "_check_screening refuses an optimizer without one"
        done: dict[int, Outcome] = {}
        in_flight: dict[Future, Candidate] = {}
        decided: list[float] = []  # the scores of order[:len(decided)], all completed
        ahead = 0  # order[:ahead] are started (or reused)
        cut = len(order)

        def ranked_out(position: int) -> bool:
            """``selected`` decided candidates beat order[position]'s bound already."""
            return sum(score < bounds[position] for score in decided) >= selected

        def keep(future: Future) -> Candidate:
            """Store a complete phase's outcome, its wall time counting the screen's."""
            candidate = in_flight.pop(future)
            outcome = future.result()
            screen_time = screened[candidate.number].wall_time
            done[candidate.number] = replace(outcome, wall_time=outcome.wall_time + screen_time)
            self._record(candidate, done[candidate.number])
            return candidate

        def finish(future: Future) -> None:
            """Keep a complete phase's outcome at once; its screen must have been a bound."""
            candidate = keep(future)
            self._check_bound(candidate, screened[candidate.number], done[candidate.number])

        def reuse(candidate: Candidate) -> None:
            """Take a complete stored before a stop, checked against its bound now (a stop
            kept it unchecked)."""
            done[candidate.number] = candidate.outcomes[0] = reused[candidate.number]
            self._count(done[candidate.number])
            self._check_bound(candidate, screened[candidate.number], done[candidate.number])

        def decide() -> None:
            """Decide the candidates in order whose outcome is known; cut at the first that
            is ranked out. Called after every outcome, so that no complete starts on stale
            ranks (one that would, on a resumed batch or after a finish, is waste)."""
            nonlocal cut
            while len(decided) < cut:
                position = len(decided)
                if ranked_out(position):
                    cut = position
                elif order[position].number in done:
                    decided.append(self._told_score(done[order[position].number]))
                else:
                    break

        with self._keeping_finished(in_flight, keep):
            while len(decided) < cut:
                while len(in_flight) < executor.workers and ahead < cut and not ranked_out(ahead):
                    candidate = order[ahead]
                    ahead += 1
                    if candidate.number in reused:
                        reuse(candidate)
                        decide()
                        continue
                    screen = _evaluation_of(screened[candidate.number])
                    task = self._task(candidate, candidate.number, "complete", screen)
                    in_flight[executor.submit(task)] = candidate
                decide()
                if len(decided) < cut:
                    assert in_flight, "a candidate still to decide is being completed"
                    finished, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
                    for future in finished:
                        finish(future)
                    decide()
            for future in as_completed(list(in_flight)):  # started ahead of the cut: kept
                finish(future)
        for candidate in order[cut:]:  # told their bound; a stored complete stays complete
            screen = screened[candidate.number]
            candidate.bound = screen.fitness
            if candidate.number in done:
                continue
            if candidate.number in reused:
                reuse(candidate)
            else:
                bound = {**screen.metrics, SCREEN_BOUND: screen.fitness}
                self._record(candidate, replace(screen, screened=True, fitness=None, metrics=bound))

    def _check_bound(self, candidate: Candidate, screen: Outcome, complete: Outcome) -> None:
        """RunFailed where a full fitness beat its screen's: the screen is then no bound, and
        the candidates it cut might have ranked among the selected ones."""
        if complete.fitness is not None and (
            self.sign * complete.fitness < self.sign * screen.fitness
        ):
            raise RunFailed(
                f"run {self.run_id}: candidate {candidate.number}'s fitness "
                f"{complete.fitness:g} is better than its screen's {screen.fitness:g}, so the "
                f"problem's screen is no bound on its fitness (the full fitness must never be "
                "better); fix the screen or run without screening"
            )

    def _reused_complete(self, candidates: list[Candidate]) -> dict[int, Outcome]:
        """A resumed batch's candidates stored complete before the interruption, by number;
        stored screens are done again, since the order needs every bound. So is a failed row:
        the store keeps no phase, and a failed screen (recorded before any complete starts)
        taken as a complete would be counted twice when screened again, or stand for the
        candidate's full evaluation where its screen succeeds this time."""
        reused: dict[int, Outcome] = {}
        for candidate in candidates:
            stored = self.reusable.pop(candidate.number, None)
            if (
                stored is not None and stored.status == "ok"
                and stored.x.tobytes() == candidate.x.tobytes()
            ):  # fmt: skip
                reused[candidate.number] = _outcome_of(stored)
        return reused

    def _screens(self, executor: Executor, candidates: list[Candidate]) -> dict[int, Outcome]:
        """Every candidate's screen, by candidate number (all of them finished)."""
        futures = {executor.submit(self._task(c, c.number, "screen")): c for c in candidates}
        return {candidate.number: future.result() for future, candidate in futures.items()}

    def _told_score(self, outcome: Outcome) -> float:
        """The (minimizing) score of a completed outcome: +inf where it failed."""
        return math.inf if outcome.fitness is None else self.sign * outcome.fitness

    def _evaluate(self, executor: Executor, candidates: list[Candidate]) -> None:
        """Submit the candidates' missing samples and collect their outcomes, storing each as
        soon as it completes (in-process ones without waiting)."""
        futures: dict[Future, Candidate] = {}
        with self._keeping_finished(futures, partial(self._keep, futures)):
            self._submit(executor, candidates, futures)
            waiting = []
            for future in list(futures):
                if future.done():
                    self._keep(futures, future)
                else:
                    waiting.append(future)
            if waiting:  # as_completed costs a lock even with nothing to wait for
                for future in as_completed(waiting):
                    self._keep(futures, future)

    def _record(self, candidate: Candidate, outcome: Outcome) -> None:
        """Store an outcome, then count it: the counts are never ahead of the rows (a second
        Ctrl-C may stop the store)."""
        self.store.add_evaluation(
            self.run_id, outcome.index, candidate.number, candidate.x, outcome.fitness,
            outcome.metrics, outcome.error, self.seeds(outcome.index), outcome.wall_time,
            outcome.screened,
        )  # fmt: skip
        candidate.outcomes[outcome.index % self.resample] = outcome
        self._count(outcome)
        self.first_error = self.first_error or outcome.error
        all_failed = self.failed >= self.stored >= ALL_FAILED_STOP and self.stored < self.total
        if all_failed and not self.keeping:  # the run stops anyway, all it finished kept
            raise RunFailed(self._why_failed() + "; stopped early")

    def _why_failed(self) -> str:
        """The reason a run ends without a result: its failures and the first error."""
        first = f", the first with {self.first_error}" if self.first_error else ""
        if self.failed < self.stored:  # resampled: no candidate had all its samples succeed
            what = (
                f"{self.failed} of {self.stored} evaluations failed and in no candidate did all "
                f"{self.resample} samples succeed"
            )
        else:
            what = f"all {self.stored} evaluations failed"
        return (
            f"run {self.run_id}: {what}{first} (the problem's settings may make every "
            "evaluation fail)"
        )

    def _score(self, candidate: Candidate) -> float:
        """The optimizer's (minimizing) score of a complete candidate, +inf if any sample
        failed; keeps the best candidate so far."""
        outcomes = candidate.outcomes
        if candidate.bound is not None:  # ranked below the selected ones: never the best
            return self.sign * candidate.bound
        if outcomes[0].screened:  # told its bound (resumed: stored as screened)
            return self.sign * outcomes[0].metrics[SCREEN_BOUND]
        if any(o.fitness is None for o in outcomes):
            return math.inf
        aggregate = self.settings.aggregate
        fitness = aggregate_fitness([o.fitness for o in outcomes], aggregate)
        score = self.sign * fitness
        if score < self.best_score:  # metrics are combined only for a new best
            self.best_score = score
            metrics = aggregate_metrics([o.metrics for o in outcomes], aggregate)
            self.best = (fitness, candidate.x.copy(), metrics)
        return score

    def _after_tell(self, progress: Progress | None) -> None:
        now = time.perf_counter()
        if now - self.last_checkpoint >= CHECKPOINT_INTERVAL:
            self.store.flush(checkpoint=(self.run_id, self._checkpoint()))
            self.last_checkpoint = now
        if progress is not None:
            progress.update(self.stored, None if self.best is None else self.best[0])

    def _checkpoint(self) -> dict:
        return {
            "state": self.optimizer.state_dict(),
            "told_below": self.told_below,
            "told_extra": sorted(self.told_extra),
        }

    def _result(self, status: str, wall_time: float) -> RunResult:
        fitness, x, metrics = self.best if self.best is not None else (None, None, {})
        return RunResult(
            run_id=self.run_id,
            status=status,
            evaluations=self.stored,
            failed=self.failed,
            screened=self.screened,
            best_fitness=fitness,
            best_x=x,
            best_metrics=metrics,
            wall_time=wall_time,
            names=self.problem.space.names,
            key_metrics=tuple(self.problem.key_metrics),
        )


def _outcome_of(evaluation: EvaluationRecord) -> Outcome:
    return Outcome(
        evaluation.index, evaluation.fitness, evaluation.metrics, evaluation.error,
        evaluation.wall_time, evaluation.status == "screened",
    )  # fmt: skip


def _evaluation_of(outcome: Outcome) -> Evaluation:
    """A screen's outcome as the Evaluation its complete phase continues from."""
    assert outcome.fitness is not None
    return Evaluation(outcome.fitness, dict(outcome.metrics))
