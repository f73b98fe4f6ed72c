"""docs/python-api.md runs as written, by the conventions of tests/test_docs_tutorial.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.test_docs_tutorial import Workspace, read_blocks

TUTORIAL = Path(__file__).parents[1] / "docs" / "python-api.md"
BLOCKS = read_blocks(TUTORIAL.read_text())


@pytest.fixture(scope="module")
def walkthrough(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    """The page done once, in order."""
    workspace = Workspace(tmp_path_factory.mktemp("python-api"), TUTORIAL)
    for block in BLOCKS:
        workspace.execute(block)
    return workspace


def test_the_python_api_page_runs_as_written(walkthrough: Workspace):
    fences = [line for line in TUTORIAL.read_text().splitlines() if line.lstrip().startswith("```")]
    assert len(fences) == 2 * len(BLOCKS)  # every block was read (none indented or unclosed)
    assert [block for block, _ in walkthrough.ran] == BLOCKS

    assert "5000 evaluations, 0 failed" in walkthrough.output_of("def shifted_sphere")
    misspelt = walkthrough.output_of("populaton=30")
    assert "no parameter 'populaton'. Did you mean 'population'" in misspelt

    listing = walkthrough.output_of("metaopt runs --db runs.db")
    assert "python:rastrigin" in listing and "4000/4000" in listing and "finished" in listing
    assert (walkthrough.root / "figures" / "convergence.png").stat().st_size > 0
    assert "Traceback" not in listing

    assert "as without the bound: True" in walkthrough.output_of("def costly")

    for name in ("hs", "ga"):
        assert f"{name}: best" in walkthrough.output_of("create_optimizer")
