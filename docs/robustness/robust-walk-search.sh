#!/bin/bash
# The robust-walk search of docs/robustness.md (issue 16, part 4), one seed per call:
#   bash docs/robustness/robust-walk-search.sh SEED     (about 25 minutes on 2 cores)
# The steered controller: the stride one with heading feedback (it steps further with one leg
# than with the other to turn back to the heading it started with).
# Stage 1: HS from random gaits, with the flight penalty (a walk, not a run), on all three
#   engines in the nominal world, scored by the engines' mean (engine_score=mean) of each
#   one's progress, a fall costing 1 m and the walk it cut short (fitness=progress): a random
#   gait seldom walks on all three, and scored by the worst engine, or with a fall costing a
#   metre per second left, standing beats everything until one does; this score rewards
#   walking further and longer on each engine, so the basin found is one that transfers.
#   Two candidates per batch, one per worker (HS improvises one at a time by default).
# Stage 2: HS warm-started from stage 1's best (it and 19 gaits within 5 % of each range around
#   it), scored on all three engines at once (the worst engine's fitness), each candidate in the
#   same 4 sampled worlds of the standard table (common seeds) at background noise 0.1, with
#   five times the flight penalty (so that flying on one engine costs more than being slowest
#   on another).
# Stage 3: the same from stage 2's best (within 2 %), with the agent's position loop at
#   servo_gain 12 /s instead of 10.
# Then the last stage's best over the whole standard table on fresh seeds.
# The budgets are the third search's; the second search (stage 1 on MuJoCo alone, robust
# fitness, one worker; stage 2 at 1600) is this script at commit 9d03e62.
set -euo pipefail
seed=${1:?usage: [STAGE1_BACKEND=E STAGE1_BUDGET=N STAGE1_WORKERS=N STAGE2_BUDGET=N] robust-walk-search.sh SEED}
stage1_backend=${STAGE1_BACKEND:-mujoco+pybullet+ode}
stage1_budget=${STAGE1_BUDGET:-1000}
stage1_workers=${STAGE1_WORKERS:-2}
stage2_budget=${STAGE2_BUDGET:-1000}
db=robust-walk-s$seed.db
walk=(--set controller=steered)
worlds=(--set flight_penalty=100 --resample 4 --common-seeds --workers 2
        --set backend=mujoco+pybullet+ode --set worlds=standard --set noise=0.1)
metaopt run -o hs -p nao-walk --budget "$stage1_budget" --seed "$seed" "${walk[@]}" \
    --set flight_penalty=20 --set backend="$stage1_backend" --set engine_score=mean \
    --set fitness=progress --workers "$stage1_workers" --batch "$stage1_workers" --db "$db"
metaopt run -o hs -p nao-walk --budget "$stage2_budget" --seed "$seed" --start-from 1 "${walk[@]}" \
    "${worlds[@]}" --db "$db"
metaopt run -o hs -p nao-walk --budget 640 --seed "$seed" --start-from 2 --start-spread 0.02 \
    --set servo_gain=12 "${walk[@]}" "${worlds[@]}" --db "$db"
metaopt robustness 3 --db "$db" --seeds 10 --workers 2 --csv "robust-walk-s$seed.csv" \
    --figure "robust-walk-s$seed.png"
