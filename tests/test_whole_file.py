"""Output files land whole or not at all (metaopt.storage.whole_file), for every writer that
uses it: CSV tables, figures, the report's index."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from matplotlib.figure import Figure

from metaopt.assessment.robustness import write_rows
from metaopt.reporting.plots import save_figure
from metaopt.storage.whole_file import written_whole


def test_a_failed_write_keeps_the_previous_file_and_leaves_nothing_beside_it(tmp_path: Path):
    target = tmp_path / "table.csv"
    target.write_text("finished,table\n")
    with pytest.raises(RuntimeError), written_whole(target) as handle:
        handle.write("half,")
        raise RuntimeError("killed mid-write")
    assert target.read_text() == "finished,table\n"
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]


def test_a_new_file_appears_only_when_the_block_succeeds(tmp_path: Path):
    target = tmp_path / "new.csv"
    with written_whole(target) as handle:
        handle.write("a,b\n")
        assert not target.exists()
    assert target.read_text() == "a,b\n"
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask  # as open() makes it


class _Unwritable:
    def __str__(self) -> str:
        raise RuntimeError("a cell that cannot be written")


def test_csv_rows_and_figures_are_written_through_it(tmp_path: Path):
    write_rows(tmp_path / "rows.csv", ["x", "y"], [[1, 2.5], [3, "z"]])
    assert (tmp_path / "rows.csv").read_text().splitlines() == ["x,y", "1,2.5", "3,z"]
    figure = Figure()
    figure.add_subplot().plot([0, 1], [1, 0])
    path = save_figure(figure, tmp_path / "figure.png")
    png = path.read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure.png", "rows.csv"]
    # a write that fails part-way leaves each finished file as it was, and nothing beside it
    with pytest.raises(RuntimeError):
        write_rows(tmp_path / "rows.csv", ["x", "y"], [[5, 6], [_Unwritable(), 7]])
    assert (tmp_path / "rows.csv").read_text().splitlines() == ["x,y", "1,2.5", "3,z"]
    broken = Figure()
    broken.text(0.5, 0.5, r"$\frac{$")  # fails as it is drawn (before any byte is written)
    with pytest.raises(ValueError):
        save_figure(broken, tmp_path / "figure.png")
    assert path.read_bytes() == png
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure.png", "rows.csv"]
