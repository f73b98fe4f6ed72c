#!/bin/bash
# The robust-walk search of docs/robustness.md (issue 16, part 4), one seed per call:
#   bash docs/robustness/robust-walk-search.sh SEED     (about 25 minutes on 2 cores)
# The steered controller: the stride one with heading feedback (it steps further with one leg
# than with the other to turn back to the heading it started with).
# Stage 1: four HS runs from random gaits on MuJoCo alone, nominal world, with the flight
#   penalty (a walk, not a run), run seeds 10 SEED + 1 ... + 4: a basin that walks fast on all
#   three engines is found by one run in a few, and four runs on MuJoCo cost less than one on
#   all three engines; stage 2 chooses among their bests. Two candidates per batch, one per
#   worker (HS improvises one at a time by default).
# Stage 2: HS warm-started from the four stage-1 bests (each, then 4 gaits within 5 % of each
#   range around each in turn: the harmony memory of 20), scored on all three engines at once
#   (the worst engine's fitness), each candidate in the
#   same 4 sampled worlds of the standard table (common seeds) at background noise 0.1, with
#   five times the flight penalty (so that flying on one engine costs more than being slowest
#   on another).
# Stage 3: the same from stage 2's best (within 2 %), with the agent's position loop at
#   servo_gain 12 /s instead of 10.
# Then the last stage's best over the whole standard table on fresh seeds.
# This is the fourth search; the third (stage 1 one HS run on all three engines, scored by
# their mean progress) is this script at commit abce00d, the second (stage 1 one run on
# MuJoCo alone, one worker; stage 2 at 1600) at commit 9d03e62.
set -euo pipefail
seed=${1:?usage: [STAGE1_RUNS=N STAGE1_BUDGET=N STAGE2_BUDGET=N] robust-walk-search.sh SEED}
stage1_runs=${STAGE1_RUNS:-4}
stage1_budget=${STAGE1_BUDGET:-1000}
stage2_budget=${STAGE2_BUDGET:-1000}
db=robust-walk-s$seed.db
if [ -e "$db" ]; then echo "$db exists: the stages number their runs from 1" >&2; exit 2; fi
walk=(--set controller=steered)
worlds=(--set flight_penalty=100 --resample 4 --common-seeds --workers 2
        --set backend=mujoco+pybullet+ode --set worlds=standard --set noise=0.1)
starts=()
for run in $(seq "$stage1_runs"); do
    metaopt run -o hs -p nao-walk --budget "$stage1_budget" --seed $((10 * seed + run)) \
        "${walk[@]}" --set flight_penalty=20 --workers 2 --batch 2 --db "$db"
    starts+=(--start-from "$run")
done
metaopt run -o hs -p nao-walk --budget "$stage2_budget" --seed "$seed" "${starts[@]}" \
    "${walk[@]}" "${worlds[@]}" --db "$db"
metaopt run -o hs -p nao-walk --budget 640 --seed "$seed" --start-from $((stage1_runs + 1)) \
    --start-spread 0.02 --set servo_gain=12 "${walk[@]}" "${worlds[@]}" --db "$db"
metaopt robustness $((stage1_runs + 2)) --db "$db" --seeds 10 --workers 2 \
    --csv "robust-walk-s$seed.csv" --figure "robust-walk-s$seed.png"
