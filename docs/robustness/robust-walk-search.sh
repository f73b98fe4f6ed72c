#!/bin/bash
# The robust-walk search of docs/robustness.md (issue 16, part 4), one seed per call:
#   bash docs/robustness/robust-walk-search.sh SEED     (about 20 minutes on 2 cores)
# The steered controller: the stride one with heading feedback (it steps further with one leg
# than with the other to turn back to the heading it started with).
# Stage 1: four HS runs from random gaits on MuJoCo alone, nominal world, with the flight
#   penalty (a walk, not a run), run seeds 10 SEED + 1 ... + 4, two candidates per batch, one
#   per worker (HS improvises one at a time by default): gaits that walk, found cheaply.
# Stage 1b: HS from their four bests (each, then 4 gaits within 5 % of each range around each
#   in turn) on PyBullet and ODE, scored by the worse of the two (engine_score=worst) of
#   each one's progress, a fall costing 1 m and the walk it cut short (fitness=progress), at
#   the later stages' flight penalty. Why: of the gaits earlier searches evaluated on all
#   three engines, one that walks 4 m on PyBullet walks as far on MuJoCo 9 times in 10, one
#   that walks 4 m on MuJoCo does so on PyBullet 1 time in 4 (docs/robustness.md, fourth
#   search): MuJoCo finds walkers, PyBullet and ODE select them. From random gaits PyBullet
#   and ODE find nothing (0.29 m after 843 evaluations); from MuJoCo's walkers, scored by
#   their mean at flight penalty 20, they found a gait at 0.52 / 0.45 / 0.32 m/s over the
#   standard table, flying 7 % of the time on PyBullet (the fifth search's seed 1).
# Stage 2: HS warm-started from stage 1b's best (it and 19 gaits within 5 % of each range
#   around it), scored on all three engines at once (the worst engine's fitness), each
#   candidate in the same 4 sampled worlds of the standard table (common seeds) at background
#   noise 0.1, with five times stage 1's flight penalty (so that flying on one engine costs
#   more than being slowest on another).
# Then stage 2's best over the whole standard table on fresh seeds.
# This is the sixth search. The fifth (stage 1b scored by the engines' mean at flight penalty
# 20; a stage 3 at servo gain 12) is this script at commit 3c8db53, the fourth (no stage 1b)
# at ff6956d, the third (stage 1 one run on all three engines) at abce00d, the second (stage
# 1 one run on MuJoCo alone, one worker; stage 2 at 1600) at 9d03e62.
set -euo pipefail
seed=${1:?usage: [STAGE1B_BUDGET=N STAGE2_BUDGET=N] robust-walk-search.sh SEED}
stage1b_budget=${STAGE1B_BUDGET:-800}
stage2_budget=${STAGE2_BUDGET:-1000}
db=robust-walk-s$seed.db
if [ -e "$db" ]; then echo "$db exists: the stages number their runs from 1" >&2; exit 2; fi
walk=(--set controller=steered)
worlds=(--set flight_penalty=100 --resample 4 --common-seeds --workers 2
        --set backend=mujoco+pybullet+ode --set worlds=standard --set noise=0.1)
for run in 1 2 3 4; do
    metaopt run -o hs -p nao-walk --budget 1000 --seed $((10 * seed + run)) "${walk[@]}" \
        --set flight_penalty=20 --workers 2 --batch 2 --db "$db"
done
metaopt run -o hs -p nao-walk --budget "$stage1b_budget" --seed "$seed" --start-from 1 \
    --start-from 2 --start-from 3 --start-from 4 "${walk[@]}" --set flight_penalty=100 \
    --set backend=pybullet+ode --set engine_score=worst --set fitness=progress --workers 2 \
    --batch 2 --db "$db"
metaopt run -o hs -p nao-walk --budget "$stage2_budget" --seed "$seed" --start-from 5 "${walk[@]}" \
    "${worlds[@]}" --db "$db"
metaopt robustness 6 --db "$db" --seeds 10 --workers 2 --csv "robust-walk-s$seed.csv" \
    --figure "robust-walk-s$seed.png"
