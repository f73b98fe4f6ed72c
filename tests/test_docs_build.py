"""The documentation builds with mkdocs in strict mode, and strict mode catches broken docs."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]


def build(config: Path, site: Path) -> subprocess.CompletedProcess:
    """`mkdocs build --strict` of config into site; warnings (broken links, pages) fail it."""
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config),
         "--site-dir", str(site)],
        capture_output=True,
        text=True,
        timeout=120,
    )  # fmt: skip


def test_the_docs_build_without_warnings(tmp_path):
    done = build(ROOT / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "site" / "writing-plugins" / "index.html").exists()


@pytest.mark.parametrize(
    "page, text, complaint",
    [
        ("index.md", "\nSee [the missing page](no-such-page.md).\n", "no-such-page.md"),
        ("index.md", "\nSee [the code](../problems/bbob.py).\n", "../problems/bbob.py"),
        ("index.md", "\nSee [a section](bbob.md#no-such-section).\n", "no-such-section"),
        ("unlisted.md", "# A page the nav does not list\n", "unlisted.md"),
    ],
)
def test_a_broken_copy_of_the_docs_fails_to_build(tmp_path, page, text, complaint):
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    shutil.copy(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    with open(tmp_path / "docs" / page, "a") as handle:
        handle.write(text)
    done = build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0
    assert complaint in done.stderr
