#!/bin/bash
# The robust-walk search of docs/robustness.md (issue 16, part 4), one seed per call:
#   bash docs/robustness/robust-walk-search.sh SEED     (about 25 minutes on 2 cores)
# Three independent pipelines, then a choice among their best candidates over the whole table.
# Each pipeline (p = 1, 2, 3), with the steered controller (the stride one with heading
# feedback: it steps further with one leg than with the other to turn back to its heading):
#   Stage 1: four HS runs from random gaits on MuJoCo alone, nominal world, with the flight
#     penalty (a walk, not a run), run seeds 100 SEED + 10 p + 1 ... + 4, two candidates per
#     batch, one per worker (HS improvises one at a time by default): gaits that walk, found
#     cheaply; about half the runs find a walker.
#   Basins: the four runs' bests raced in the nominal world on all three engines, 8 seeds
#     each (drawn from 3), ranked by the slowest engine's median speed (--goal speed>=0.44):
#     stage 1b starts from the winner alone, so its memory holds one basin (started from all
#     four, most of its first 300 harmonies mixed them and fell).
#   Stage 1b: HS (run seed 10 SEED + p) from that best (then gaits within 5 % of each range
#     around it) on all three engines at noise 0.1, scored by the mean of
#     the engines' progress, each capped at 6 m (engine_cap: 0.5 m/s over the 12 s walked; past
#     it an engine's progress stops paying, so a gait MuJoCo already walks fast is pushed to
#     walk on PyBullet and ODE), a fall costing 1 m and the walk it cut short
#     (fitness=progress), at flight penalty 50, charged past the cap too; 600 evaluations.
# Re-check: each stage 1b's 3 best candidates (9 in all) over the standard table, one seed per
#   cell (drawn from 1), ranked by their worst engine's mean fitness (robust fitness, flight
#   penalty 100): a run's best is the luckiest of hundreds of one-episode scores, and which
#   pipeline's basin holds best is only seen over the table.
# Race: the re-check's 3 best again over the table, 10 fresh seeds per cell (drawn from 2),
#   ranked by the goal (metaopt robustness --goal): the smallest relative margin to part 4's
#   bounds on any engine, with a fall bound of 2 % rather than the goal's 5 %, room for the
#   noise of a fall rate estimated from 110 episodes; then by fitness. One seed per cell cannot
#   tell a gait that falls 1 time in 20 from one that falls 1 time in 10, and the winner of 9
#   noisy scores is the luckiest: fresh seeds for the few best correct the luck (racing, as in
#   successive halving). Each choice reads the previous one's --ranking CSV.
# Then the chosen candidate over the whole standard table on the standard seeds (drawn from 0).
# The standard table is the installed one: every search of the log ran with nao-walk-1; from
# commit "table nao-walk-2" on, the re-check, the race and the final table leave ODE's friction
# cells out (ODE's unlimited friction has none to scale), as docs/robustness.md says.
# Knobs for the pilots after the twelfth search (docs/robustness/searches.md): TOP=10 (the
# re-check takes each stage 1b's 10 best), STAGE1_ENGINE=ode (stage 1 on ODE).
# STAGE1_SET="NAME=VALUE ..." adds problem settings to every stage-1 run (the basin race
# walks the whole 15 s episode whatever stage 1 walked): STAGE1_SET=duration=9 (6 s of walking,
# half the cost) with STAGE1B_BUDGET=900 gives stage 1b the time stage 1 saves.
# STAGE1B_SET="NAME=VALUE ..." adds problem settings to every stage 1b: the pilots after the
# thirteenth (docs/robustness/searches.md) ran STAGE1B_SET=worlds=standard (sampled worlds),
# STAGE1B_SET=flight_allowed=0.02 (a flight margin), both, and STAGE1B_SET=flight_allowed=0.035
# (a milder margin), which also ran as whole searches on fresh seeds 4-6; the one-seed pilot
# after the half walk ran STAGE1B_SET="flight_allowed=0.035 engine_score=worst" on seeds 10-11 (a
# later --set of a name wins over the script's engine_score=mean); the whole searches on fresh
# seeds 12-14 ran STAGE1B_SET="flight_allowed=0.035 engine_score=worst worlds=pushes" (every
# stage-1b evaluation pushed once, 1 N·s in a seed-drawn direction and time).
# STAGE1B_RESAMPLE=K scores every stage-1b candidate over the same K evaluation seeds (--resample
# K --common-seeds, the mean of the K scores; STAGE1B_BUDGET counts evaluations, so it tries
# STAGE1B_BUDGET / K candidates): with worlds=standard, K fixed cells of the table, the same for
# every candidate, in place of one cell drawn per evaluation. The whole searches on fresh seeds
# 15-16 (17 was stopped) ran STAGE1B_RESAMPLE=3 STAGE1B_BUDGET=540 STAGE1B_SET="flight_allowed=0.035
# engine_score=worst worlds=standard".
# STAGE1B_COMMON=batch gives the candidates of each stage-1b batch (a CMA-ES generation) the same
# evaluation seeds, fresh ones per batch (--common-seeds batch): the candidates CMA-ES ranks
# against each other meet the same world, push and noise. With STAGE1B_RESAMPLE it replaces the
# run-wide seeds (run). Design T is design S with STAGE1B_COMMON=batch and LATER_STAGES=540.
# Design U is design T with LATER_STAGES=auto and STAGE1B_BUDGET=6000 (the deadline ends stage
# 1b), on fresh seeds 104-106 (within part 4's goal as their median), 107 and 108-110 (not).
# Design V is design U with STAGE1B_CELLS="nominal,nominal,nominal,servo gain x1.2,servo gain
# x1.2,latency 1" (servo gain x1.2 drawn twice as often), on fresh seeds 111-113 (one PyBullet
# fall in 110 episodes short of the goal as their median) and 114-116 (two falls short).
# STAGE1B_DURATIONS="NAME=SECONDS,..." (with STAGE1B_CELLS) sets nao-walk's cell_durations in
# stage 1b: the named cells walk that long, capped at the same speed (engine_cap scales with the
# walking time), the others STAGE1B_SET's duration. Design X is design V with
# STAGE1B_DURATIONS="servo gain x1.2=15,latency 1=15" (a 12 s walk in the cells where V's gaits
# fell late, 7 s in the nominal world).
# Design Y is design X with STAGE1_RUNS=4 STAGE1_TIME=280 (stage 1b gets the 210 s of three
# stage-1 runs), on fresh seeds 126-128 (PyBullet's and ODE's speed missed as their median; seed
# 126 within the goal).
# TRIALS=N TRIAL_TIME=SECONDS (with STAGE1B_START=pool, PIPELINES=1 and DEADLINE) starts N trial
# stages 1b, one from each of the pool's N best basins (run seeds 10 SEED + 1 ... + N), each for
# at most TRIAL_TIME s, then continues the one whose last 300 evaluations (candidates, without
# STAGE1B_RESAMPLE) walk fastest on their slowest engine (metaopt show --recent 300: each
# engine's median speed; the slowest of them)
# to the deadline (metaopt resume --max-time); the re-check takes that run. Two basins of one seed
# climb to levels apart by 0.08-0.16 m/s on PyBullet after 1 500 candidates (measurement M4 in
# docs/robustness/searches.md), and the basin race's nominal speed does not tell which.
# Design Z is design Y without FLAT_BEST (it cannot act with PIPELINES=1 under DEADLINE) with
# TRIALS=2 TRIAL_TIME=300, on fresh seeds 129-131.
# Design AA is design V with fitness=robust added to STAGE1B_SET (a later --set wins over the
# script's fitness=progress: a fall costs 1 m more for every second the walk had left), on fresh
# seeds 135-137 (missed: PyBullet's and ODE's speed and PyBullet's falls as their median).
# RECHECK_LAST=N re-checks each final stage 1b's TOP best among its N latest candidates
# (metaopt robustness --last N) rather than among all: where stage 1b's scores tie at the cap,
# its TOP best are otherwise the earliest of the tied. Design W is design V with
# RECHECK_LAST=1000, on fresh seeds 117-119 (not within the goal; no stage 1b reached the cap).
# FINALS="RUN ..." runs the later stages alone (re-check, race, table) on the store
# robust-walk-sSEED.db already in the working folder, from these final stage-1b runs (FINALS=8
# for a search with one pipeline and seven stage-1 runs): another choice among what a search
# made (TOP, RECHECK_LAST, RACE_SEEDS, RACE_FELL), paired with its own, since the later stages
# never feed back into stage 1 or 1b. It writes the later stages' files again: run it in a copy
# of the search's folder. Selection W on designs V's and U's stores is FINALS=8 TOP=6
# RACE_FELL=0.05 RECHECK_LAST=1000 (docs/robustness/searches.md).
# STAGE1B_SCREEN=1 screens stage 1b (metaopt run --screen; with STAGE1B_OPTIMIZER=cmaes and
# engine_score=worst in STAGE1B_SET): each candidate walks on MuJoCo and ODE first, and on
# PyBullet only where it can still rank in CMA-ES's better half, which changes no step of
# CMA-ES but buys stage 1b more candidates in its time (benchmarks/screening.py). Design Q is
# design O with STAGE1B_SCREEN=1. FLAT_FELL's share is then over the completed candidates.
# STAGE1B_OPTIMIZER=NAME runs stage 1b with another optimizer than hs (its settings through
# STAGE1B_SET): STAGE1B_OPTIMIZER=cmaes STAGE1B_SET="sigma0=0.05 ..." is CMA-ES started at the
# raced basin, its first generation the basin and 11 points around it (a generation is 12 for the
# steered controller's 15 parameters), its step 0.05 of each range.
# STAGE1B_BATCH=B asks B candidates per batch in stage 1b instead of 2 (two workers, HS's one at a
# time); 0 is the optimizer's own (cmaes: a generation, 12, the same run as 2, with less waiting).
# PIPELINES=N runs N pipelines instead of 3 (run seeds as above, p = 1 ... N).
# STAGE1_RUNS=R runs R stage-1 runs per pipeline instead of 4 (run seeds 100 SEED + 10 p + 1 ... + R).
# STAGE1B_START=pool runs every pipeline's stage 1 first and races all their bests together in one
# basin race (robust-walk-sSEED-basins.csv); pipeline p's stage 1b starts from the p-th of that
# ranking: the pipelines share their tickets, so a pipeline whose own runs found no walker takes
# one from another's. The pooled-basins searches (docs/robustness/searches.md) ran STAGE1B_START=pool
# STAGE1_RUNS=2 STAGE1B_BUDGET=480 STAGE1B_OPTIMIZER=cmaes STAGE1B_BATCH=0
# STAGE1B_SET="sigma0=0.05 flight_allowed=0.035 engine_score=worst worlds=pushes" on fresh seeds
# 22-24; seed 21 ran it with STAGE1_SET=duration=9 and STAGE1B_BUDGET=600 (the lean stage 1).
# STAGE1_OPTIMIZER=NAME runs stage 1 with another optimizer than hs (its settings through
# STAGE1_SET), STAGE1_BATCH=B with B candidates per batch instead of 2 (0: the optimizer's own):
# STAGE1_OPTIMIZER=cmaes STAGE1_BATCH=0 is CMA-ES from a random first generation at its default
# step, 0.3 of each range (docs/robustness/searches.md, CMA-ES in stage 1).
# BASIN_FELL=RATE adds the goal fell<=RATE to every basin race (a rate from 0 to 1): a basin
# that falls in more of its nominal episodes on any engine ranks by that margin, not by its
# speed alone (a speed is measured up to the fall, so a fast gait that falls on two engines
# ranked first; stage 1b from such a basin found no candidate that stays up).
# RACE_SEEDS=N races the re-check's 3 best over N seeds per cell instead of 10 (the race costs
# about 3 x 10 episodes per cell, 270-330 s of design Q's later stages).
# RACE_FELL=RATE is the race's fall bound instead of 0.02: at 0.02 a gait falling in 4 % of
# the race's episodes misses by as much as one that stands still (the margins are relative to
# the bound), so the race chose slower, safer gaits over faster ones that fall now and then.
# The CMA-ES stage-1 searches (docs/robustness/searches.md) ran STAGE1_OPTIMIZER=cmaes
# STAGE1_BATCH=0 BASIN_FELL=0.25 RACE_FELL=0.05 with the pooled-basins searches' knobs on fresh
# seeds 26-28; seed 25 ran it without BASIN_FELL and RACE_FELL; the one-seed pilot on seed 29
# added STAGE1_ENGINE=mujoco+ode STAGE1_RUNS=1 (stage 1 scored by the worse of two engines).
# DEADLINE=SECONDS fits the search to a wall-clock limit (with STAGE1B_START=pool, where every
# stage 1 comes first): each stage 1b gets the time left to the deadline, less LATER_STAGES
# seconds (390 unless set) for the re-check, race and final table, shared among the pipelines
# still to run (metaopt run --max-time; STAGE1B_BUDGET stays the most it evaluates).
# Seeds 30-35 ran with 330 s (those stages took 253-294 s on seeds 22-24); on seed 34 they
# took 330 s and the search 1801 s.
# Seeds 36-58 ran with 360 s; on seed 56 they took 365 s and the search 1810 s.
# LATER_STAGES=auto sets that time from the basin race, which walks the same 15 s episodes on
# the same three engines just before stage 1b: its seconds per episode, times the later stages'
# episodes, a fifth more, and 20 s for their three commands. The later stages took 0.92-1.09
# times the basin race's time per episode in designs H and R (H: race 42-52 s for 240 episodes,
# later stages 272-340 s for 1426; R: 74-84 s, 405-459 s), so a fixed LATER_STAGES starves
# stage 1b on a fast day and overruns on a slow one.
# STAGE1_TIME=SECONDS (with STAGE1B_START=pool) gives every stage-1 run together at most that
# long: each run gets an even share of the stage-1 time left (metaopt run --max-time), so that a
# slower day cuts stage 1's evaluations, not stage 1b's time. Design D's stage 1 took 668-747 s,
# F's 825-905 s and G's (seed 59) 976 s with the same code and settings.
# FLAT_BEST=METRES (with STAGE1B_START=pool) starts a pipeline again when its stage 1b's best
# scores below METRES (no candidate walks that far): another stage 1b, run seed 10 SEED + k, from
# the pool's k-th basin (k = PIPELINES + 1, + 2, ...), while the pool has basins left and, with
# DEADLINE, the pipeline's share of the time left is at least 60 s; the re-check takes the last
# run of each pipeline. A flat basin (seeds 31 and 32 of the deadline searches: every candidate
# fell, best below 0 m, against 2.4-5.7 m for the rest) otherwise costs a third of the tickets.
# With PIPELINES=1 and DEADLINE the one stage 1b's share is all the time left, so FLAT_BEST acts
# only on a stage 1b that spends its budget before the deadline (design P's seed 87 kept a flat
# basin to the end).
# FLAT_FELL=SHARE (with FLAT_BEST) also counts a stage 1b as flat when at least SHARE of its last
# 100 candidates fell (metaopt show --recent 100: the share of the metric fell), whatever its
# best: design J's seed 67 ran its 1400 evaluations in 156 s, all of the last 100 falling, with a
# lucky best of 2.39 m, and left 595 s of its 30 minutes unused.
# The flat-basin searches (docs/robustness/searches.md) ran FLAT_BEST=1 with the deadline
# searches' knobs on fresh seeds 33-35, and with STAGE1_SET=duration=9 on seed 36 (a pilot).
# The two-pipeline searches ran PIPELINES=2 STAGE1_RUNS=5 with the flat-basin searches' knobs on
# fresh seeds 37-39 (design A: ten stage-1 runs, each stage 1b about 300 s), and with
# RACE_FELL=0.05 besides on fresh seeds 40-41 (design B, whose seed 39 is A's own).
# The one-pipeline searches ran RACE_FELL=0.05 PIPELINES=1 STAGE1_RUNS=10 TOP=6
# STAGE1B_BUDGET=1400 with design A's other knobs on fresh seeds 42-44 (design C: one stage 1b
# from the pool's first basin, given the time of two and cut by the deadline), and again,
# unchanged, on fresh seeds 45-47.
# The sampled-worlds searches ran design C with STAGE1_SET=worlds=standard (design D: every
# stage-1 evaluation walks in one cell of the standard table, on MuJoCo) on fresh seeds 48-50,
# then 51-52.
# Design E is design D with its stage 1b in sampled worlds too: STAGE1B_SET="sigma0=0.05
# flight_allowed=0.035 engine_score=worst worlds=standard", on fresh seeds 53-55.
# STAGE1B_CELLS="NAME,NAME,..." (cell names of the standard table, joined by commas; they hold
# spaces, which STAGE1B_SET splits on) sets nao-walk's world_cells in stage 1b: with worlds=pushes
# each pushed evaluation also walks in one of these cells, drawn from its seed; with
# worlds=standard the cells drawn from. Design F is design D with STAGE1B_CELLS="nominal,servo
# gain x1.2,latency 1" (the cells where design D's gaits fell on PyBullet, besides the pushes
# stage 1b already walks through), on fresh seeds 56-58. A cell named k times is drawn k times
# as often: design G is design D with STAGE1B_CELLS="nominal,nominal,nominal,nominal,servo gain
# x1.2,latency 1" (a third of stage 1b's evaluations in the two cells, F's dose halved); it ran
# seed 59 and was stopped (stage 1 took 976 s that day). Design H is design G with
# STAGE1_TIME=700, on fresh seeds 60-62. With worlds=pushes a push cell's evaluations walk the
# cell's own push instead of a drawn one: design I is design H with STAGE1B_CELLS="nominal,
# nominal,nominal,push forward,servo gain x1.2,latency 1" (a sixth of stage 1b's evaluations
# pushed as the table pushes forward), on fresh seeds 63-65.
# Design J is design H without STAGE1B_CELLS, both stages on the balanced controller (the
# steered one with a stepping strategy; a later --set of a name wins): STAGE1_SET="worlds=standard
# controller=balanced" and controller=balanced added to STAGE1B_SET, on fresh seeds 66-68.
# Design K is design J with its stage 1 on the steered controller, as design H's (STAGE1_SET=
# worlds=standard): stage 1b starts the balanced controller from the steered basins, its two
# gains at their neutral 0 (a start may lack variables with a neutral value), on fresh seeds 69-71.
# Pilot L is design H (STAGE1B_CELLS above) with controller=balanced added to STAGE1B_SET, on
# fresh seed 72; design L is the same on fresh seeds 73-75. Every design up to L ran before
# commit 2144e1a, where nao-walk stopped letting a fall in the first 2 s of walking escape the
# flight penalty (the cause of the stage 1bs that FLAT_BEST and FLAT_FELL restart).
# Design M is design L at that commit, on fresh seeds 76-78; its later stages took 406-476 s on
# a slower day, past the 390 s kept for them. Design N is design M with population=24 added to
# STAGE1B_SET (CMA-ES's step shrank under noise with 12) and LATER_STAGES=480, on fresh seeds
# 79-81. Design O is design N with STAGE1_RUNS=7 STAGE1_TIME=490 (each stage-1 run keeps its
# 70 s; stage 1b gets the time of the three runs left out), on fresh seeds 82-84. Design P is
# design O with STAGE1_ENGINE=mujoco+ode STAGE1_RUNS=6 STAGE1_TIME=420 LATER_STAGES=620, on fresh
# seeds 85-87 (pilot R: design O's command on seed 84 with only STAGE1_ENGINE=mujoco+ode added).
# Design R is design H's command at commit 2144e1a's fixed score, with LATER_STAGES=360 (H's
# split of the time), on fresh seeds 95-97.
# Design S is design Q with STAGE1B_SET's "duration=10 engine_cap=3.5" (stage 1b walks 7 s, not
# 12, capped at the same 0.5 m/s) and STAGE1B_BUDGET=3000, on fresh seeds 98-100. Whatever stage 1
# or stage 1b walked, the basin race, the re-check, the race and the table walk the standard 15 s.
# This is the thirteenth search, run after commit d228dc7 (nao-walk charges the flight
# penalty past engine_cap). STAGE1B_START=all gives the twelfth's stage 1b, from all four
# stage-1 bests; the twelfth (commit f1b7010) and the thirteenth's pilot ran before d228dc7.
# The eleventh is the twelfth with a race at 5 seeds per cell ranked by fitness (commit
# 17bbed3), the tenth the same without the race (commit 208ebc5).
# The ninth (one pipeline of 800 evaluations in stage 1b, its 8 best re-checked) is this
# script at commit 5ed7043, the seventh at 3c42de4, the sixth at 6e1fe34, the fifth at
# 3c8db53, the fourth at ff6956d, the third at abce00d, the second at 9d03e62.
set -euo pipefail
seed=${1:?usage: [DEADLINE=SECONDS LATER_STAGES=SECONDS|auto STAGE1_TIME=SECONDS STAGE1_OPTIMIZER=NAME STAGE1_BATCH=B BASIN_FELL=RATE RACE_FELL=RATE RACE_SEEDS=N STAGE1B_BUDGET=N STAGE1B_OPTIMIZER=NAME STAGE1B_BATCH=B STAGE1B_SCREEN=1 PIPELINES=N STAGE1_RUNS=R STAGE1B_RESAMPLE=K STAGE1B_COMMON=run|batch TOP=K RECHECK_LAST=N STAGE1_ENGINE=E STAGE1_SET="NAME=VALUE ..." STAGE1B_START=all|raced|pool STAGE1B_SET="NAME=VALUE ..." STAGE1B_CELLS="NAME,..." STAGE1B_DURATIONS="NAME=SECONDS,..." FLAT_BEST=METRES FLAT_FELL=SHARE TRIALS=N TRIAL_TIME=SECONDS FINALS="RUN ..."] robust-walk-search.sh SEED}
stage1b_budget=${STAGE1B_BUDGET:-600}
stage1b_optimizer=${STAGE1B_OPTIMIZER:-hs}
stage1b_batch=${STAGE1B_BATCH:-2}
pipelines=${PIPELINES:-3}
stage1_runs=${STAGE1_RUNS:-4}
stage1_optimizer=${STAGE1_OPTIMIZER:-hs}
stage1_batch=${STAGE1_BATCH:-2}
for knob in PIPELINES STAGE1_RUNS DEADLINE LATER_STAGES STAGE1_TIME RACE_SEEDS RECHECK_LAST \
    TRIALS TRIAL_TIME; do
    if [ "$knob" = LATER_STAGES ] && [ "${LATER_STAGES:-}" = auto ]; then continue; fi
    if ! [[ ${!knob:-1} =~ ^[1-9][0-9]*$ ]]; then
        or_auto=""
        if [ "$knob" = LATER_STAGES ]; then or_auto=", or auto"; fi
        echo "$knob must be a whole number, 1 or more$or_auto; got '${!knob}'" >&2
        exit 2
    fi
done
for knob in BASIN_FELL RACE_FELL; do
    if ! [[ ${!knob:-0} =~ ^(0(\.[0-9]+)?|1(\.0*)?|\.[0-9]+)$ ]]; then
        echo "$knob must be a fall rate from 0 to 1, e.g. 0.25; got '${!knob}'" >&2
        exit 2
    fi
done
if [ -n "${FINALS+set}" ] && ! [[ $FINALS =~ ^\ *[1-9][0-9]*(\ +[1-9][0-9]*)*\ *$ ]]; then
    echo "FINALS must be the final stage-1b runs' ids, whole numbers 1 or more separated by" \
        "spaces, e.g. FINALS=8; got '$FINALS'" >&2
    exit 2
fi
basin_goals=(--goal "speed>=0.44")
if [ -n "${BASIN_FELL:-}" ]; then basin_goals+=(--goal "fell<=$BASIN_FELL"); fi
race_fell=${RACE_FELL:-0.02}
race_seeds=${RACE_SEEDS:-10}
top=${TOP:-3}
recheck_pool=(--top "$top")  # the re-check's candidates: each final stage 1b's TOP best
if [ -n "${RECHECK_LAST:-}" ]; then recheck_pool+=(--last "$RECHECK_LAST"); fi
stage1_engine=${STAGE1_ENGINE:-mujoco}
stage1b_start=${STAGE1B_START:-raced}
case $stage1b_start in
    raced | all | pool) ;;
    *) echo "STAGE1B_START must be raced, all or pool; got '$stage1b_start'" >&2; exit 2 ;;
esac
if [ -n "${DEADLINE:-}" ] && [ "$stage1b_start" != pool ]; then
    echo "DEADLINE needs STAGE1B_START=pool (every stage 1 before the first stage 1b); got" \
        "STAGE1B_START=$stage1b_start" >&2
    exit 2
fi
if [ -n "${STAGE1_TIME:-}" ] && [ "$stage1b_start" != pool ]; then
    echo "STAGE1_TIME needs STAGE1B_START=pool (every stage 1 in one stretch); got" \
        "STAGE1B_START=$stage1b_start" >&2
    exit 2
fi
if [ -n "${FLAT_BEST:-}" ]; then
    if ! [[ $FLAT_BEST =~ ^[0-9]+(\.[0-9]+)?$ ]]; then
        echo "FLAT_BEST must be a fitness in metres, 0 or more, e.g. 1; got '$FLAT_BEST'" >&2
        exit 2
    fi
    if [ "$stage1b_start" != pool ]; then
        echo "FLAT_BEST needs STAGE1B_START=pool (the pool's next basin replaces a flat one);" \
            "got STAGE1B_START=$stage1b_start" >&2
        exit 2
    fi
fi
if [ -n "${FLAT_FELL:-}" ]; then
    if ! [[ $FLAT_FELL =~ ^(0(\.[0-9]+)?|1(\.0+)?)$ ]]; then
        echo "FLAT_FELL must be a share of candidates from 0 to 1, e.g. 0.9; got '$FLAT_FELL'" >&2
        exit 2
    fi
    if [ -z "${FLAT_BEST:-}" ]; then
        echo "FLAT_FELL needs FLAT_BEST (it widens FLAT_BEST's test of a flat stage 1b), e.g." \
            "FLAT_BEST=1 FLAT_FELL=0.9" >&2
        exit 2
    fi
fi
later_stages=${LATER_STAGES:-390}  # seconds DEADLINE keeps for the re-check, race and table
if [ "$later_stages" = auto ]; then later_stages=0; fi  # until the basin race has been timed
if [ -n "${LATER_STAGES:-}" ] && [ -z "${DEADLINE:-}" ]; then
    echo "LATER_STAGES needs DEADLINE (it is the part of DEADLINE kept for the later stages)," \
        "e.g. DEADLINE=1800 LATER_STAGES=480" >&2
    exit 2
fi
if [ -n "${DEADLINE:-}" ] && [ "$later_stages" -ge "$DEADLINE" ]; then
    echo "DEADLINE must leave time after the $later_stages s kept for the later stages" \
        "(LATER_STAGES): more than $later_stages; got '$DEADLINE'" >&2
    exit 2
fi
if [ -n "${STAGE1_TIME:-}" ] && [ -n "${DEADLINE:-}" ] \
    && [ "$STAGE1_TIME" -ge $((DEADLINE - later_stages)) ]; then
    kept=" less the $later_stages s kept for the later stages"
    if [ "${LATER_STAGES:-}" = auto ]; then kept=""; fi
    echo "STAGE1_TIME must leave stage 1b time before DEADLINE$kept:" \
        "at most $((DEADLINE - later_stages - 1)); got '$STAGE1_TIME'" >&2
    exit 2
fi
if [ -n "${TRIALS:-}" ]; then
    if [ "$stage1b_start" != pool ] || [ -z "${DEADLINE:-}" ] || [ "$pipelines" != 1 ]; then
        echo "TRIALS needs STAGE1B_START=pool, DEADLINE and PIPELINES=1 (the trials share one" \
            "pipeline's time from the pool's best basins); got STAGE1B_START=$stage1b_start" \
            "DEADLINE=${DEADLINE:-} PIPELINES=$pipelines" >&2
        exit 2
    fi
    if [ -z "${TRIAL_TIME:-}" ] || [ -n "${FLAT_BEST:-}" ]; then
        echo "TRIALS needs TRIAL_TIME (each trial's seconds), and no FLAT_BEST (a flat trial is" \
            "simply not continued), e.g. TRIALS=2 TRIAL_TIME=300" >&2
        exit 2
    fi
elif [ -n "${TRIAL_TIME:-}" ]; then
    echo "TRIAL_TIME needs TRIALS (it is each trial stage 1b's time), e.g. TRIALS=2" \
        "TRIAL_TIME=300" >&2
    exit 2
fi
least_retry=60  # seconds: FLAT_BEST starts a pipeline again only with this much time to give it
walk=(--set controller=steered)
standard_walk=(--set duration=15)  # the later stages' episode, whatever stage 1 or 1b walked
# Every stage-1 and stage-1b run's settings but its seed, start, time and store, the knobs' --set
# after the script's (a later --set of a name wins); both are checked before stage 1 starts
# (metaopt run --check), so that a bad value is refused in one line and costs no search time.
stage1_run=(-o "$stage1_optimizer" -p nao-walk --budget 1000 --workers 2 --batch "$stage1_batch"
    "${walk[@]}" --set backend="$stage1_engine" --set flight_penalty=20)
for pair in ${STAGE1_SET:-}; do stage1_run+=(--set "$pair"); done
stage1b_run=(-o "$stage1b_optimizer" -p nao-walk --budget "$stage1b_budget" --workers 2
    --batch "$stage1b_batch" "${walk[@]}" --set flight_penalty=50
    --set backend=mujoco+pybullet+ode --set engine_score=mean --set engine_cap=6 --set noise=0.1
    --set fitness=progress)
if [ -n "${STAGE1B_SCREEN:-}" ]; then stage1b_run+=(--screen); fi
if [ -n "${STAGE1B_RESAMPLE:-}" ]; then
    stage1b_run+=(--resample "$STAGE1B_RESAMPLE" --common-seeds "${STAGE1B_COMMON:-run}")
elif [ -n "${STAGE1B_COMMON:-}" ]; then
    stage1b_run+=(--common-seeds "$STAGE1B_COMMON")
fi
for pair in ${STAGE1B_SET:-}; do stage1b_run+=(--set "$pair"); done
if [ -n "${STAGE1B_CELLS:-}" ]; then stage1b_run+=(--set "world_cells=$STAGE1B_CELLS"); fi
if [ -n "${STAGE1B_DURATIONS:-}" ]; then
    stage1b_run+=(--set "cell_durations=$STAGE1B_DURATIONS")
fi
db=robust-walk-s$seed.db
if [ -n "${FINALS:-}" ]; then
    if ! [ -e "$db" ]; then
        echo "FINALS runs the later stages on a search's store: no $db here (run it in a copy" \
            "of the search's folder)" >&2
        exit 2
    fi
else
    if [ -e "$db" ]; then echo "$db exists: the stages number their runs from 1" >&2; exit 2; fi
    metaopt run "${stage1_run[@]}" --check
    metaopt run "${stage1b_run[@]}" --check
fi
first() { awk -F, -v n="$2" 'NR > 1 && NR <= n + 1 {print $2}' "$1"; }  # a ranking's N best
run=0
finals=()
even_share() {  # seconds: an even share of the time left to second $1 among $2 runs, at least 1
    local share=$((($1 - SECONDS) / $2))
    echo $((share > 1 ? share : 1))
}
stage1() {  # pipeline $1's stage-1 runs; their run ids go to ids
    ids=()
    local limit=()
    for r in $(seq 1 "$stage1_runs"); do
        if [ -n "${STAGE1_TIME:-}" ]; then  # stage 1 is the first runs (STAGE1B_START=pool)
            limit=(--max-time "$(even_share "$STAGE1_TIME" $((pipelines * stage1_runs - run)))")
        fi
        metaopt run "${stage1_run[@]}" --seed $((100 * seed + 10 * $1 + r)) \
            ${limit[@]+"${limit[@]}"} --db "$db"
        run=$((run + 1))
        ids+=("$run")
    done
}
race_basins() {  # $1: the ranking CSV; the rest: the runs whose bests are raced
    local ranking=$1
    shift
    metaopt robustness "$@" --cells nominal \
        --seeds 8 --seed 3 "${basin_goals[@]}" --set fitness=progress \
        --set flight_penalty=50 "${standard_walk[@]}" --workers 2 --db "$db" \
        --ranking "$ranking"
}
#: episodes of one candidate over the standard table at one seed per cell (nao-walk-3: 11 cells
#: on MuJoCo and PyBullet, 9 on ODE, whose two friction cells are left out)
table_episodes=31
auto_later_stages() {  # seconds to keep for the later stages, from the basin race's $1 seconds
    # for $2 basins (8 seeds, nominal, 3 engines: 24 episodes each): the later stages walk the
    # re-check's TOP per pipeline at one seed per cell, the race's 3 at RACE_SEEDS and the table
    # at 10 seeds, 15 s episodes as the race's; a fifth more and 20 s for the three commands.
    local episodes=$((table_episodes * (top * pipelines + 3 * race_seeds + 10)))
    echo $(($1 * episodes * 6 / (5 * 24 * $2) + 20))
}
time_share() {  # pipeline $1's share of the time left to DEADLINE, seconds (a day without one)
    if [ -z "${DEADLINE:-}" ]; then echo 86400; return; fi
    even_share $((DEADLINE - later_stages)) $((pipelines - $1 + 1))
}
stage1b() {  # pipeline $1's stage 1b, run seed $2, from the basin(s) in starts; with $3, for at
    # most $3 seconds of the pipeline's share (a trial)
    local limit=() seconds
    if [ -n "${DEADLINE:-}" ]; then
        seconds=$(time_share "$1")
        if [ -n "${3:-}" ] && [ "$3" -lt "$seconds" ]; then seconds=$3; fi
        limit=(--max-time "$seconds")
    fi
    metaopt run "${stage1b_run[@]}" --seed "$2" ${starts[@]+"${starts[@]}"} \
        ${limit[@]+"${limit[@]}"} --db "$db"
    run=$((run + 1))
}
flat() {  # yes when run $1's best scored below FLAT_BEST (or none scored), or when at least
    # FLAT_FELL (if set) of its last 100 candidates fell; no otherwise
    metaopt show "$1" --recent 100 --db "$db" --format json | python3 -c 'import json, sys
shown = json.load(sys.stdin)
best, recent = shown["best"], shown["recent"] or {"metrics": {}}  # None: no evaluation
fell = recent["metrics"].get("fell", {}).get("share")
flat = best is None or best["fitness"] < float(sys.argv[1])
flat = flat or (sys.argv[2] != "" and fell is not None and fell >= float(sys.argv[2]))
print("yes" if flat else "no")' "$FLAT_BEST" "${FLAT_FELL:-}"
}
trial_window=300  # evaluations: a trial's last ones, where its climb stands
slowest_speed() {  # run $1's last trial_window evaluations: the median speed on the engine
    # where it is slowest (metaopt show --recent: each speed@ENGINE's median), -inf if none
    metaopt show "$1" --recent "$trial_window" --db "$db" --format json | python3 -c 'import json, sys
recent = json.load(sys.stdin)["recent"] or {"metrics": {}}  # None: no evaluation
speeds = [m["median"] for name, m in recent["metrics"].items()
          if name.startswith("speed@") and m.get("median") is not None]
print(repr(min(speeds)) if speeds else "-inf")'
}
fastest_trial() {  # the run among $@ whose slowest_speed is highest (the first of ties)
    for trial in "$@"; do
        speed=$(slowest_speed "$trial") || exit 1  # an unread store stops the search
        echo "trial stage 1b (run $trial): its last $trial_window candidates walk $speed m/s" \
            "on their slowest engine" >&2
        echo "$speed $trial"
    done | sort -g -r -s -k 1,1 | head -n 1 | cut -d " " -f 2
}
if [ -n "${FINALS:-}" ]; then
    read -r -a finals <<< "$FINALS"
else
    spare=$pipelines  # the pool's basins handed out so far
    pipelines_left=$pipelines
    pool_size=0
    if [ "$stage1b_start" = pool ]; then
        pool=()
        for p in $(seq 1 "$pipelines"); do
            stage1 "$p"
            pool+=("${ids[@]}")
        done
        basins="robust-walk-s$seed-basins.csv"
        race_started=$SECONDS
        race_basins "$basins" "${pool[@]}"
        pool_size=${#pool[@]}
        if [ "${LATER_STAGES:-}" = auto ]; then
            race_seconds=$((SECONDS - race_started))  # read once: the estimate and its message agree
            later_stages=$(auto_later_stages "$race_seconds" "$pool_size")
            echo "LATER_STAGES=auto: the basin race took $race_seconds s for $pool_size basins;" \
                "$later_stages s kept for the later stages" >&2
        fi
    fi
    if [ -n "${TRIALS:-}" ]; then  # one pipeline: trials from the pool's best basins, then the best
        trials=()
        for k in $(seq 1 $((TRIALS < pool_size ? TRIALS : pool_size))); do
            starts=(--start-from "$(first "$basins" "$k" | tail -n 1)")
            stage1b 1 $((10 * seed + k)) "$TRIAL_TIME"
            trials+=("$run")
        done
        chosen=$(fastest_trial "${trials[@]}")  # on its own line: an unread store stops the search
        echo "continuing trial stage 1b (run $chosen) to the deadline" >&2
        metaopt resume "$chosen" --max-time "$(time_share 1)" --workers 2 --db "$db"
        finals+=("$chosen")
        pipelines_left=0  # the trials were the pipeline
    fi
    for p in $(seq 1 "$pipelines_left"); do
        case $stage1b_start in
            pool) starts=(--start-from "$(first "$basins" "$p" | tail -n 1)") ;;
            raced)
                stage1 "$p"
                basins="robust-walk-s$seed-p$p-basins.csv"
                race_basins "$basins" "${ids[@]}"
                starts=(--start-from "$(first "$basins" 1)")
                ;;
            all)
                stage1 "$p"
                starts=()
                for id in "${ids[@]}"; do starts+=(--start-from "$id"); done
                ;;
        esac
        run_seed=$((10 * seed + p))
        while :; do
            stage1b "$p" "$run_seed"
            [ -n "${FLAT_BEST:-}" ] || break
            verdict=$(flat "$run")  # on its own line: a store that cannot be read stops the search
            [ "$verdict" = yes ] || break
            spare=$((spare + 1))
            if [ "$spare" -gt "$pool_size" ] || [ "$(time_share "$p")" -lt "$least_retry" ]; then
                break
            fi
            echo "stage 1b (run $run) found no candidate scoring $FLAT_BEST: pipeline $p starts" \
                "again from the pool's basin $spare" >&2
            starts=(--start-from "$(first "$basins" "$spare" | tail -n 1)")
            run_seed=$((10 * seed + spare))
        done
        finals+=("$run")
    done
fi
metaopt robustness "${finals[@]}" "${recheck_pool[@]}" --seeds 1 --seed 1 --set fitness=robust \
    --set flight_penalty=100 "${standard_walk[@]}" --workers 2 --db "$db" \
    --csv "robust-walk-s$seed-top.csv" --ranking "robust-walk-s$seed-top-ranking.csv" \
    | tee "robust-walk-s$seed-top.txt"
# shellcheck disable=SC2046  # one word per finalist
metaopt robustness $(first "robust-walk-s$seed-top-ranking.csv" 3) --seeds "$race_seeds" --seed 2 \
    --set fitness=robust --set flight_penalty=100 "${standard_walk[@]}" \
    --goal "speed>=0.44" --goal "fell<=$race_fell" --goal "|drift|<=0.3" --goal "flight<=0.05" \
    --workers 2 --db "$db" --csv "robust-walk-s$seed-race.csv" \
    --ranking "robust-walk-s$seed-race-ranking.csv" | tee "robust-walk-s$seed-race.txt"
metaopt robustness "$(first "robust-walk-s$seed-race-ranking.csv" 1)" --seeds 10 \
    "${standard_walk[@]}" --workers 2 --db "$db" --csv "robust-walk-s$seed.csv" \
    --figure "robust-walk-s$seed.png"
