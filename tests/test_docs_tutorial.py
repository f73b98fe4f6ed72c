"""docs/writing-plugins.md runs as written: every fenced block is written out or executed.

The convention, read from the Markdown (HTML comments do not show on the rendered page):

- a block preceded by ``<!-- file: PATH -->`` is written to PATH in a fresh workspace folder;
- a ``bash`` block is run with ``bash -euo pipefail`` in the workspace;
- a ``python`` block is run with ``python -c`` in the workspace (it asserts what it shows);
- any other block fails the test, so nothing in the tutorial goes unexecuted.

Commands run with shims first on PATH: ``metaopt`` and ``python`` are this interpreter, and
``pip install [-e] DIR`` becomes ``pip install --no-deps --no-build-isolation --no-index
--target SITE DIR`` into the workspace's own SITE folder (on PYTHONPATH). So the tutorial
installs nothing into the real site-packages and needs no network; ``-e`` becomes a plain
install, which is the same for a package installed once.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

TUTORIAL = Path(__file__).parents[1] / "docs" / "writing-plugins.md"
MARK = re.compile(r"<!--\s*(file):\s*(\S+)\s*-->")

PIP_SHIM = """#!/bin/sh
if [ "$1" != install ]; then echo "tutorial pip shim: only 'pip install' is mapped" >&2; exit 2; fi
shift
if [ "$1" = -e ]; then shift; fi
exec "{python}" -m pip install --quiet --no-deps --no-build-isolation --no-index \\
    --target "{site}" "$@"
"""
COMMAND_SHIM = '#!/bin/sh\nexec "{python}" {args} "$@"\n'


@dataclass(frozen=True)
class Block:
    """One fenced block of the tutorial and the marks that precede it."""

    line: int
    language: str
    body: str
    file: str | None = None


def read_blocks(markdown: str) -> list[Block]:
    """Every fenced block in order, with the ``<!-- file: PATH -->`` mark just above it."""
    blocks: list[Block] = []
    marks: dict[str, str] = {}
    lines = markdown.splitlines()
    index = 0
    while index < len(lines):
        line = lines[index]
        mark = MARK.fullmatch(line.strip())
        if mark:
            marks[mark.group(1)] = mark.group(2)
        elif line.startswith("```"):
            end = lines.index("```", index + 1)
            body = "\n".join(lines[index + 1 : end]) + "\n"
            blocks.append(Block(index + 1, line[3:].strip(), body, **marks))
            marks, index = {}, end
        elif line.strip():
            marks = {}
        index += 1
    return blocks


class Workspace:
    """An empty folder where the tutorial's files are written and its commands run."""

    def __init__(self, root: Path, tutorial: Path = TUTORIAL) -> None:
        self.tutorial = tutorial
        self.root = root / "work"
        self.site = root / "site"
        shims = root / "bin"
        for folder in (self.root, self.site, shims):
            folder.mkdir()
        for name, text in (
            ("pip", PIP_SHIM.format(python=sys.executable, site=self.site)),
            ("python", COMMAND_SHIM.format(python=sys.executable, args="")),
            ("metaopt", COMMAND_SHIM.format(python=sys.executable, args="-m metaopt")),
        ):
            (shims / name).write_text(text)
            (shims / name).chmod(0o755)
        self.env = {
            key: value for key, value in os.environ.items() if key != "METAOPT_LOAD_PLUGINS"
        }
        self.env.update(
            PATH=f"{shims}{os.pathsep}{os.environ['PATH']}",
            PYTHONPATH=str(self.site),
            COLUMNS="200",
            PIP_DISABLE_PIP_VERSION_CHECK="1",
        )
        #: (block, what it printed) for every block executed so far.
        self.ran: list[tuple[Block, str]] = []

    def execute(self, block: Block) -> None:
        """Write or run one block; a failing command fails the test with its output."""
        if block.file is not None:
            path = self.root / block.file
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(block.body)
            self.ran.append((block, ""))
            return
        commands = {"bash": ["bash", "-euo", "pipefail", "-c"], "python": [sys.executable, "-c"]}
        if block.language not in commands:
            pytest.fail(
                f"{self.tutorial.name}:{block.line}: a {block.language or 'plain'} block with no "
                "'<!-- file: PATH -->' mark cannot be executed; mark it or make it bash/python"
            )
        done = subprocess.run(
            [*commands[block.language], block.body],
            cwd=self.root,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        output = done.stdout + done.stderr
        assert done.returncode == 0, (
            f"{self.tutorial.name}:{block.line} failed:\n{block.body}\n{output}"
        )
        self.ran.append((block, output))

    def output_of(self, command: str) -> str:
        """What the executed block containing ``command`` printed."""
        return next(output for block, output in self.ran if command in block.body)


BLOCKS = read_blocks(TUTORIAL.read_text())


@pytest.fixture(scope="module")
def walkthrough(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    """The tutorial done once, in order."""
    workspace = Workspace(tmp_path_factory.mktemp("tutorial"))
    for block in BLOCKS:
        workspace.execute(block)
    return workspace


def test_the_tutorial_runs_as_written(walkthrough: Workspace):
    fences = [line for line in TUTORIAL.read_text().splitlines() if line.lstrip().startswith("```")]
    assert len(fences) == 2 * len(BLOCKS)  # every block was read (none indented or unclosed)
    assert [block for block, _ in walkthrough.ran] == BLOCKS
    kinds = {"file" if b.file else b.language for b, _ in walkthrough.ran}
    assert kinds == {"file", "bash", "python"}

    listing = walkthrough.output_of("metaopt list\n")
    assert "hill-climb" in listing and "bowl" in listing
    assert "(from my-metaopt-plugin)" in listing

    own = walkthrough.output_of("-o hill-climb -p bowl")
    assert "best fitness" in own and "distance" in own and "200 (0 failed)" in own
    assert "300 (0 failed)" in own  # hs on the bowl, the second command of the block

    only = walkthrough.output_of("METAOPT_LOAD_PLUGINS=")
    assert "hill-climb" in only and "bowl" in only and "sphere" in only
    assert "harmony" not in only.lower()
    assert only.count("finished") >= 2  # `metaopt runs` lists both runs

    assert "Evaluation(fitness=-9.0" in walkthrough.output_of("from my_plugin.problem import")

    kit = walkthrough.output_of("python -m pytest -q my-metaopt-plugin/tests")
    assert "2 passed" in kit
    scaffold = walkthrough.output_of("metaopt new optimizer my-es")
    assert "passed" in scaffold and "my-es" in scaffold
