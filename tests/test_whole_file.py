"""Output files land whole or not at all (metaopt.storage.whole_file), for every writer that
uses it: CSV tables, figures, the report's index."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from click.testing import CliRunner
from matplotlib.figure import Figure

from metaopt.assessment.robustness import write_rows
from metaopt.cli import main
from metaopt.errors import ConfigError
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


def test_a_symlink_is_written_through_to_its_target(tmp_path: Path):
    """The link stays a link and its target gets the content (a rename would replace the link
    with a file and leave the target as it was)."""
    real = tmp_path / "real.csv"
    real.write_text("old\n")
    link = tmp_path / "link.csv"
    link.symlink_to("real.csv")
    with written_whole(link) as handle:
        handle.write("new\n")
    assert link.is_symlink() and os.readlink(link) == "real.csv"
    assert real.read_text() == "new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.csv", "real.csv"]


def test_a_fifo_is_refused_and_left_a_fifo(tmp_path: Path):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file"), written_whole(fifo) as handle:
        handle.write("a\n")
    assert fifo.is_fifo()
    assert [p.name for p in tmp_path.iterdir()] == ["pipe.csv"]


def test_export_writes_through_a_symlink_and_refuses_a_fifo_in_one_line(tmp_path: Path):
    store = str(tmp_path / "runs.db")
    runner = CliRunner()
    done = runner.invoke(
        main, ["run", "-o", "random", "-p", "sphere", "--budget", "5", "--set", "dim=2",
               "--seed", "1", "--db", store],
    )  # fmt: skip
    assert done.exit_code == 0, done.output
    real, link, fifo = tmp_path / "real.csv", tmp_path / "link.csv", tmp_path / "pipe.csv"
    real.write_text("old\n")
    link.symlink_to(real)
    done = runner.invoke(main, ["export", "1", "--output", str(link), "--db", store])
    assert done.exit_code == 0, done.output
    assert link.is_symlink() and real.read_text().startswith("index,candidate")
    os.mkfifo(fifo)
    done = runner.invoke(main, ["export", "1", "--output", str(fifo), "--db", store])
    assert done.exit_code == 2, done.output
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), done.stderr
    assert "pipe.csv is not a regular file" in lines[0]
    assert fifo.is_fifo()
