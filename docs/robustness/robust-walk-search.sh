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
set -euo pipefail
seed=${1:?usage: robust-walk-search.sh SEED}
db=robust-walk-s$seed.db
walk=(--set controller=steered)
worlds=(--set flight_penalty=100 --resample 4 --common-seeds --workers 2
        --set backend=mujoco+pybullet+ode --set worlds=standard --set noise=0.1)
metaopt run -o hs -p nao-walk --budget 1000 --seed "$seed" "${walk[@]}" --set flight_penalty=20 \
    --set backend=mujoco --db "$db"
metaopt run -o hs -p nao-walk --budget 1600 --seed "$seed" --start-from 1 "${walk[@]}" \
    "${worlds[@]}" --db "$db"
metaopt run -o hs -p nao-walk --budget 640 --seed "$seed" --start-from 2 --start-spread 0.02 \
    --set servo_gain=12 "${walk[@]}" "${worlds[@]}" --db "$db"
metaopt robustness 3 --db "$db" --seeds 10 --workers 2 --csv "robust-walk-s$seed.csv" \
    --figure "robust-walk-s$seed.png"
