"""The engine agreement table: every figure of metaopt.physics.agreement on every installed
physics engine, side by side, as a markdown table (docs/nao-walk.md, "Engines that agree").

A cell holds the measured figure, marked ✗ where it is off its prediction by more than the
tolerance; an engine that cannot run here gets a column saying why. Usage:

    python benchmarks/engine_agreement.py [--backends mujoco,pybullet,ode]
"""

from __future__ import annotations

import argparse

from metaopt.errors import MetaoptError
from metaopt.physics.agreement import MEASUREMENTS, Figure, measure
from metaopt.plugins import registry


def figures_of(backend: str) -> list[Figure] | str:
    """Every figure measured on backend, or why the engine cannot run here."""
    try:
        return [figure for name in MEASUREMENTS for figure in measure(backend, name)]
    except (ImportError, OSError, MetaoptError) as error:
        return f"cannot run here: {error}"


def table(backends: list[str]) -> str:
    """The markdown table: a row per figure (an engine with unlimited friction has its own
    friction rows), a column per engine."""
    # Each engine's figures by label, or why it cannot run here.
    columns = {
        backend: column if isinstance(column, str) else {f.label: f for f in column}
        for backend, column in ((b, figures_of(b)) for b in backends)
    }
    rows: dict[str, Figure] = {}
    for column in columns.values():
        for figure in [] if isinstance(column, str) else column.values():
            rows.setdefault(figure.label, figure)
    lines = [
        "| figure | expected | " + " | ".join(backends) + " |",
        "|---|---|" + "---|" * len(backends),
    ]
    for row, (label, figure) in enumerate(rows.items()):
        cells = []
        for column in columns.values():
            if isinstance(column, str):
                cells.append(column if row == 0 else "")
                continue
            measured = column.get(label)
            if measured is None:
                cells.append("–")
            else:
                cells.append(f"{measured.measured:.4g}" + ("" if measured.agrees else " ✗"))
        unit = f" ({figure.unit})" if figure.unit else ""
        lines.append(
            f"| {label}{unit} | {figure.expected:.4g} ± {figure.tolerance:.2g} | "
            + " | ".join(cells)
            + " |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", default=",".join(registry().physics_backends))
    print(table(parser.parse_args().backends.split(",")))


if __name__ == "__main__":
    main()
