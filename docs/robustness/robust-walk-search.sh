#!/bin/bash
# The robust-walk search of docs/robustness.md (issue 16, part 4), one seed per call:
#   bash docs/robustness/robust-walk-search.sh SEED     (about 25 minutes on 2 cores)
# The steered controller: the stride one with heading feedback (it steps further with one leg
# than with the other to turn back to the heading it started with).
# Stage 1: HS on MuJoCo alone, with the flight penalty (a walk, not a run), from random gaits.
# Stage 2: HS warm-started from stage 1's best (it and 19 gaits within 5 % of each range around
#   it), scored on all three engines at once (the worst engine's fitness), each candidate in the
#   same 4 sampled worlds of the standard table (common seeds) at background noise 0.1, with
#   five times the flight penalty (so that flying on one engine costs more than being slowest
#   on another).
# Stage 3: the same from stage 2's best (within 2 %), with the agent's position loop at
#   servo_gain 12 /s instead of 10.
# Then the last stage's best over the whole standard table on fresh seeds.
# The budgets are the second search's; a one-seed pilot of a wider stage 1 ran with
# STAGE1_BUDGET=3000 STAGE1_WORKERS=2 STAGE2_BUDGET=1000 (docs/robustness.md).
set -euo pipefail
seed=${1:?usage: [STAGE1_BUDGET=N STAGE1_WORKERS=N STAGE2_BUDGET=N] robust-walk-search.sh SEED}
stage1_budget=${STAGE1_BUDGET:-1000}
stage1_workers=${STAGE1_WORKERS:-1}
stage2_budget=${STAGE2_BUDGET:-1600}
db=robust-walk-s$seed.db
walk=(--set controller=steered)
worlds=(--set flight_penalty=100 --resample 4 --common-seeds --workers 2
        --set backend=mujoco+pybullet+ode --set worlds=standard --set noise=0.1)
metaopt run -o hs -p nao-walk --budget "$stage1_budget" --seed "$seed" "${walk[@]}" \
    --set flight_penalty=20 --set backend=mujoco --workers "$stage1_workers" --db "$db"
metaopt run -o hs -p nao-walk --budget "$stage2_budget" --seed "$seed" --start-from 1 "${walk[@]}" \
    "${worlds[@]}" --db "$db"
metaopt run -o hs -p nao-walk --budget 640 --seed "$seed" --start-from 2 --start-spread 0.02 \
    --set servo_gain=12 "${walk[@]}" "${worlds[@]}" --db "$db"
metaopt robustness 3 --db "$db" --seeds 10 --workers 2 --csv "robust-walk-s$seed.csv" \
    --figure "robust-walk-s$seed.png"
