"""How the stored gaits use their feet on each engine (problems/nao_walk/footfalls.py): contact,
flight, stride frequency and length, and slip, as a Markdown table.

    python scripts/footfalls.py                      # every stored gait
    python scripts/footfalls.py stride_mujoco hs_walk
"""

from __future__ import annotations

import sys

from metaopt_problems.nao_walk.footfalls import footfalls
from metaopt_problems.nao_walk.stored_gaits import (
    ENGINES,
    gait_problem,
    gait_vector,
    load_gait,
    stored_gait_names,
)


def main(names: list[str]) -> None:
    print("| gait | engine | contact L / R | flight | double support | stride frequency "
          "| stride length | slip (median) |")  # fmt: skip
    print("|---|---|--:|--:|--:|--:|--:|--:|")
    for name in names or stored_gait_names():
        record = load_gait(name)
        for engine in ENGINES:
            problem = gait_problem(record["problem_params"], engine)
            try:
                feet = footfalls(problem.runner, problem.gait(gait_vector(record)))
            except ValueError as error:  # it fell before there was anything to measure
                print(f"| {name} | {engine} | {error} | | | | | |")
                continue
            finally:
                problem.close()
            left, right = feet.contact
            print(f"| {name} | {engine} | {left:.0%} / {right:.0%} | {feet.flight:.0%} "
                  f"| {feet.double_support:.0%} | {feet.stride_frequency:.1f} Hz "
                  f"| {feet.stride_length:.3f} m | {feet.slip_speed:.2f} m/s |")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
