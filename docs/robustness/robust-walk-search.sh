#!/bin/bash
# The robust-walk search of docs/robustness.md (issue 16, part 4), one seed per call:
#   [KNOB=VALUE ...] bash docs/robustness/robust-walk-search.sh SEED
# Each design in docs/robustness/searches.md names its knobs or gives its command;
# docs/robustness.md ("How a search runs") walks through design V's. Every run goes to
# robust-walk-sSEED.db in the working folder, which must not exist yet (but with FINALS).
#
# The stages, as they run with no knob set (the thirteenth search: three pipelines, HS):
#   Stage 1: for each pipeline p, STAGE1_RUNS HS runs of 1000 evaluations from random gaits of
#     the steered controller (the stride one with heading feedback), on MuJoCo alone, in the
#     nominal world, flight penalty 20; run seeds 100 SEED + 10 p + 1, 2, ...: cheap gaits that
#     walk (about half the runs find one).
#   Basin race: the runs' bests walk the nominal world on all three engines, 8 seeds each (drawn
#     from 3), ranked by the slowest engine's median speed (robustness --goal speed>=0.44,
#     robust-walk-sSEED[-pP]-basins.csv); stage 1b starts from the winner alone (from four
#     basins at once, most of HS's first 300 harmonies mixed them and fell).
#   Stage 1b: HS from that basin (run seed 10 SEED + p), 600 evaluations on all three engines at
#     noise 0.1, scored by the engines' mean progress, each capped at 6 m (engine_cap: past it
#     an engine stops paying, so a gait fast on MuJoCo is pushed to walk on the others), a fall
#     costing 1 m and the walk it cut short (fitness=progress), flight penalty 50.
#   Re-check: each final stage 1b's TOP best over the standard table, one seed per cell (drawn
#     from 1), ranked by their worst engine's mean robust fitness (flight penalty 100): a run's
#     best is the luckiest of hundreds of one-episode scores (-top.csv, -top-ranking.csv).
#   Race: the re-check's 3 best over the table again at RACE_SEEDS fresh seeds per cell (drawn
#     from 2), ranked by the goal (robustness --goal: the smallest relative margin to part 4's
#     bounds on any engine, the fall bound RACE_FELL), then by fitness (-race.csv,
#     -race-ranking.csv).
#   Table: the race's winner over the standard table on the standard seeds (drawn from 0),
#     robust-walk-sSEED.csv and .png. The basin race and the later stages walk the standard 15 s
#     whatever stage 1 or 1b walked. The standard table is the installed one (nao-walk-3 now).
#
# Knobs (environment variables; bad values stop the search with one line, exit 2):
# Pipelines and their start
#   PIPELINES=N (3) pipelines; STAGE1_RUNS=R (4) stage-1 runs each.
#   STAGE1B_START=raced|all|pool (raced): each pipeline's stage 1b from its own raced basin;
#     from all its stage-1 bests at once (the twelfth search); or every stage 1 first and all
#     their bests raced in one pool, pipeline p starting from the pool's p-th basin (a pipeline
#     whose own runs found no walker takes another's ticket).
#   BASIN_FELL=RATE adds the goal fell<=RATE to the basin race: a basin that falls in more of
#     its nominal episodes on any engine ranks by that margin, not by its speed (measured up to
#     the fall, a fast faller can rank first and leave stage 1b nothing that stands).
#   FLAT_BEST=METRES (pool) starts a pipeline again, from the pool's next basin and run seed
#     10 SEED + k, when its stage 1b's best scores below METRES, while the pool has basins and
#     (with DEADLINE) the pipeline's share of the time left is at least 60 s; FLAT_FELL=SHARE
#     also counts it flat when that share of its last 100 candidates fell. With PIPELINES=1 and
#     DEADLINE the one stage 1b's share is all the time left, so FLAT_BEST acts only on one that
#     spends its budget early.
#   TRIALS=N TRIAL_TIME=SECONDS (pool, DEADLINE, PIPELINES=1, no FLAT_BEST): N trial stage 1bs
#     from the pool's N best basins (run seeds 10 SEED + 1 ... + N), each at most TRIAL_TIME s;
#     the one whose last 300 candidates walk fastest on their slowest engine (metaopt show
#     --recent 300) continues to the deadline (metaopt resume --max-time).
# Stage 1
#   STAGE1_ENGINE=E (mujoco), e.g. mujoco+ode (scored by the worse engine).
#   STAGE1_OPTIMIZER=NAME (hs), STAGE1_BATCH=B (2; 0: the optimizer's own, e.g. a generation).
#   STAGE1_SET="NAME=VALUE ..." adds nao-walk settings to every stage-1 run (replacing the
#     script's value of a name it gives), e.g. worlds=standard (each evaluation in one cell of
#     the table).
#   STAGE1_TIME=SECONDS (pool) gives all stage-1 runs together at most that long, each an even
#     share of what is left (metaopt run --max-time): a slow day cuts stage 1's evaluations,
#     not stage 1b's time. It counts from stage 1's start, after LATER_STAGES=auto's
#     calibration (design AB's stage 1 counted from the script's start, the calibration's 16 s
#     in it).
# Stage 1b
#   STAGE1B_OPTIMIZER=NAME (hs) with its settings in STAGE1B_SET, e.g. cmaes with sigma0=0.05
#     (CMA-ES started at the raced basin, its step 0.05 of each range).
#   STAGE1B_BATCH=B (2): candidates per batch; 0 is the optimizer's own (cmaes: a generation).
#   STAGE1B_BUDGET=N (600): the most it evaluates (with DEADLINE the time usually ends it).
#   STAGE1B_SET="NAME=VALUE ..." adds nao-walk and optimizer settings, winning over the ones
#     above, e.g. engine_score=worst (the slowest engine's score), worlds=pushes (each
#     evaluation pushed once, 1 N·s in a drawn direction and time), flight_allowed=0.035,
#     controller=balanced,
#     population=24, duration=10 engine_cap=3.5 (a 7 s walk capped at the same 0.5 m/s),
#     fitness=robust.
#   STAGE1B_CELLS="NAME,NAME,..." sets world_cells (cell names hold spaces, which STAGE1B_SET
#     splits on): with worlds=pushes each pushed evaluation also walks in one of these cells,
#     with worlds=standard they are the cells drawn from; a cell named k times is drawn k times
#     as often, and a push cell walks its own push.
#   STAGE1B_DURATIONS="NAME=SECONDS,..." sets cell_durations: the named cells walk that long,
#     capped at the same speed (engine_cap scales with the walk), the others STAGE1B_SET's.
#   STAGE1B_RESAMPLE=K scores each candidate over the same K evaluation seeds (--resample K
#     --common-seeds run; STAGE1B_BUDGET counts evaluations, so it tries BUDGET / K candidates).
#   STAGE1B_COMMON=run|batch: --common-seeds; batch gives each batch (a CMA-ES generation) the
#     same fresh seeds, so the candidates ranked against each other meet the same world.
#   STAGE1B_SCREEN=1 (cmaes with engine_score=worst): --screen, each candidate walks MuJoCo and
#     ODE first and PyBullet only where it can still rank in CMA-ES's better half, which
#     changes no step of CMA-ES and buys more candidates (benchmarks/screening.py).
# Time
#   DEADLINE=SECONDS (pool) fits the search to a wall-clock limit: each stage 1b gets an even
#     share of the time left to it, less LATER_STAGES, among the pipelines still to run.
#   LATER_STAGES=SECONDS|auto (390) is the time kept for the re-check, race and table; auto
#     times, before stage 1, a gait that stands (the stored hazard_walk) over the standard table
#     at 3 seeds, and keeps that time per table pass for each pass the later stages walk, a
#     quarter more and 20 s: a fixed time starves stage 1b on a fast day and overruns on a slow
#     one. Design X's searches scaled it from the basin race's seconds per episode instead,
#     which fell short when the basins fell early (seed 142: 172 s kept, 326 s used); design
#     AB's kept the calibration's time without the quarter, and seed 146's later stages took
#     255 s of the 253 kept. The search ends by saying how long its later stages took. If the
#     calibration keeps so much that stage 1b would have no time before DEADLINE, the search
#     stops there (exit 2), before stage 1.
# Later stages
#   TOP=K (3): the re-check takes each final stage 1b's K best; RECHECK_LAST=N only among its
#     N latest candidates (where scores tie at the cap, the K best are otherwise the earliest).
#   RACE_SEEDS=N (10) seeds per cell in the race; RACE_FELL=RATE (0.02) its fall bound (at 0.02
#     a gait falling in 4 % misses as much as one that stands still).
#   FINALS="RUN ..." runs only the later stages, on robust-walk-sSEED.db already here, from
#     these final stage-1b runs (FINALS=8 for one pipeline after seven stage-1 runs): another
#     choice among what a search made, paired with its own. It rewrites the later stages'
#     files: run it in a copy of the search's folder.
#
# Searches logged before a knob existed ran this script at these commits: the second 9d03e62,
# the third abce00d, the fourth ff6956d, the fifth 3c8db53, the sixth 6e1fe34, the seventh
# 3c42de4, the ninth 5ed7043, the tenth 208ebc5, the eleventh 17bbed3, the twelfth and the
# thirteenth's pilot f1b7010 (before d228dc7, where nao-walk charges the flight penalty past
# engine_cap). Designs up to L ran before commit 2144e1a, where nao-walk stopped letting a fall
# in the first 2 s of walking escape the flight penalty.
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
if [ "$later_stages" = auto ]; then later_stages=0; fi  # until the calibration before stage 1
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
standard_walk=(--set duration=15)  # the later stages' episode, whatever stage 1 or 1b walked
with_settings() {  # appends to the array named $1 the script's settings (the rest, NAME=VALUE)
    # that the knob's list $2 does not name, then the knob's own: metaopt run takes each name
    # once, and a knob's value replaces the script's
    local -n into=$1
    local given=" $2 " pair
    shift 2
    for pair in "$@"; do
        case $given in *" ${pair%%=*}="*) ;; *) into+=(--set "$pair") ;; esac
    done
    for pair in $given; do into+=(--set "$pair"); done
}
# Every stage-1 and stage-1b run's settings but its seed, start, time and store; both are
# checked before stage 1 starts (metaopt run --check), so that a bad value is refused in one
# line and costs no search time.
stage1_run=(-o "$stage1_optimizer" -p nao-walk --budget 1000 --workers 2 --batch "$stage1_batch")
with_settings stage1_run "${STAGE1_SET:-}" controller=steered backend="$stage1_engine" \
    flight_penalty=20
stage1b_run=(-o "$stage1b_optimizer" -p nao-walk --budget "$stage1b_budget" --workers 2
    --batch "$stage1b_batch")
if [ -n "${STAGE1B_SCREEN:-}" ]; then stage1b_run+=(--screen); fi
if [ -n "${STAGE1B_RESAMPLE:-}" ]; then
    stage1b_run+=(--resample "$STAGE1B_RESAMPLE" --common-seeds "${STAGE1B_COMMON:-run}")
elif [ -n "${STAGE1B_COMMON:-}" ]; then
    stage1b_run+=(--common-seeds "$STAGE1B_COMMON")
fi
with_settings stage1b_run "${STAGE1B_SET:-}" controller=steered flight_penalty=50 \
    backend=mujoco+pybullet+ode engine_score=mean engine_cap=6 noise=0.1 fitness=progress
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
            limit=(--max-time "$(even_share $((stage1_from + STAGE1_TIME)) \
                $((pipelines * stage1_runs - run)))")
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
calibration_gait=hazard_walk  # stands on every engine in all but a few % of the table's episodes
calibration_seeds=3
later_stages_for() {  # seconds to keep for the later stages, from $1 ms for the calibration's
    # calibration_seeds passes over the standard table: the later stages walk the re-check's TOP
    # per pipeline at one seed per cell, the race's 3 at RACE_SEEDS and the table at 10 seeds,
    # each pass as long as the calibration's, a quarter more and 20 s for the three commands.
    # A gait's pass costs 0.78-1.09 times the calibration's (the later stages of design AB's
    # three seeds and of design X's seed 142 walked again): gaits differ in what they touch,
    # and a quarter more covers the costliest of them with 0.16 to spare
    local passes=$((top * pipelines + 3 * race_seeds + 10))
    echo $(($1 * passes * 5 / (4 * 1000 * calibration_seeds) + 20))
}
milliseconds() {  # the clock, in milliseconds (SECONDS counts whole seconds)
    echo $((${EPOCHREALTIME//[!0-9]/} / 1000))  # its decimal point is the locale's
}
calibrated_later_stages() {  # times calibration_gait over the standard table; its seconds kept
    local started
    started=$(milliseconds)
    metaopt robustness "$calibration_gait" --seeds "$calibration_seeds" --seed 1 \
        "${standard_walk[@]}" --workers 2 > "robust-walk-s$seed-calibration.txt" || return 1
    later_stages_for $(($(milliseconds) - started))
}
refuse_a_calibration_that_leaves_no_stage1b() {  # exit 2 unless the time the calibration
    # kept for the later stages leaves stage 1 its STAGE1_TIME and stage 1b a second before
    # DEADLINE: the check before the calibration could not know what it would keep
    local left=$((DEADLINE - SECONDS - later_stages - ${STAGE1_TIME:-0}))
    if [ "$left" -ge 1 ]; then return; fi
    echo "LATER_STAGES=auto kept $later_stages s for the later stages" \
        "(robust-walk-s$seed-calibration.txt), which with $SECONDS s gone" \
        "and STAGE1_TIME=${STAGE1_TIME:-0} leaves stage 1b no time before DEADLINE=$DEADLINE:" \
        "give a DEADLINE of at least $((DEADLINE - left + 1)), or LATER_STAGES in seconds" >&2
    exit 2
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
    if [ "${LATER_STAGES:-}" = auto ]; then
        later_stages=$(calibrated_later_stages)
        echo "LATER_STAGES=auto: $calibration_gait's table at $calibration_seeds seeds" \
            "(robust-walk-s$seed-calibration.txt) keeps $later_stages s for the later stages" >&2
        refuse_a_calibration_that_leaves_no_stage1b
    fi
    stage1_from=$SECONDS  # STAGE1_TIME counts from here
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
        race_basins "$basins" "${pool[@]}"
        pool_size=${#pool[@]}
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
later_started=$SECONDS
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
if [ -n "${DEADLINE:-}" ] && [ -z "${FINALS:-}" ]; then  # FINALS keeps no time
    echo "the later stages took $((SECONDS - later_started)) s of the $later_stages s kept;" \
        "the search $SECONDS s of its DEADLINE=$DEADLINE" >&2
fi
