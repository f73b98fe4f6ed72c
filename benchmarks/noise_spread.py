"""The stored HS gait's distance under noise (docs/nao-walk.md, "Noise"): for each noise level
and engine, the distance in the 12 s walking phase over SEEDS noise seeds (mean ± std,
min – max) and the falls, on every engine that can run here. Usage:

    python benchmarks/noise_spread.py [--gait hs_walk] [--seeds 20] [--noise 0,0.5,1,2,3]
"""

from __future__ import annotations

import argparse

import numpy as np

from metaopt.plugins import registry
from metaopt_problems.nao_walk.stored_gaits import load_gait, replay_over_seeds


def spread(gait: str, engine: str, noise: float, seeds: int) -> str:
    """One table cell: the distances over seeds at noise on engine."""
    runs = replay_over_seeds(load_gait(gait), engine, seeds, noise, run_seed=7)
    distances = np.array([m["distance"] for m in runs])
    falls = sum(int(m["fell"]) for m in runs)
    cell = f"{distances.mean():.3f} ± {distances.std():.3f} ({distances.min():.3f} – "
    cell += f"{distances.max():.3f})"
    return cell + (f", {falls} of {seeds} fell" if falls else "")


def main() -> None:
    """Print the noise-spread table over the engines that can run here (an unavailable one
    would stop it partway)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gait", default="hs_walk")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--noise", default="0,0.5,1,2,3")
    args = parser.parse_args()
    engines = registry().available_physics_backends()
    columns = " | ".join(f"{engine} distance, mean ± std (min – max)" for engine in engines)
    print(f"| noise | {columns} |")
    print("|---|" + "---|" * len(engines))
    for noise in (float(n) for n in args.noise.split(",")):
        cells = [spread(args.gait, engine, noise, args.seeds) for engine in engines]
        print(f"| {noise:g} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
