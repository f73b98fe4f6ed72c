"""`metaopt new`: the packages it writes install, pass their own tests and appear in metaopt."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from metaopt.errors import ConfigError
from metaopt.scaffold import create_plugin, plugin_names
from tests.conftest import metaopt_cli, pip_install_isolated


def test_new_plugins_install_pass_their_own_tests_and_run(tmp_path: Path):
    for kind, name in (("optimizer", "tiny-es"), ("problem", "tilted-bowl")):
        created = metaopt_cli("new", kind, name, cwd=tmp_path)
        assert created.returncode == 0, created.stderr
        assert f"pip install -e {name}" in created.stdout
    site = tmp_path / "site"
    pip_install_isolated(site, tmp_path / "tiny-es", tmp_path / "tilted-bowl")
    own_tests = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tiny-es", "tilted-bowl"],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(site)},
        capture_output=True,
        text=True,
    )
    assert own_tests.returncode == 0, own_tests.stdout + own_tests.stderr
    assert " passed" in own_tests.stdout and "skipped" not in own_tests.stdout
    listing = metaopt_cli("list", cwd=tmp_path, extra_path=site)
    assert "metaopt-tiny-es" in listing.stdout and "metaopt-tilted-bowl" in listing.stdout
    db = str(tmp_path / "runs.db")
    run = metaopt_cli(
        "run", "-o", "tiny-es", "-p", "tilted-bowl", "--budget", "500", "--seed", "1", "--db", db,
        cwd=tmp_path, extra_path=site,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr


def test_new_refuses_an_existing_directory_without_writing(tmp_path: Path):
    (tmp_path / "taken").mkdir()
    refused = metaopt_cli("new", "problem", "my-bowl", "--directory", "taken", cwd=tmp_path)
    assert refused.returncode == 2
    assert "taken already exists" in refused.stderr
    assert list((tmp_path / "taken").iterdir()) == []


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("My ES", "is not accepted; use lowercase letters"),
        ("es-", "is not accepted"),
        ("2es", "is not accepted"),
        ("class", "is a Python keyword"),
        ("hs", r"already provides the optimizer 'hs' \(metaopt\)"),
        ("sphere", r"already provides the problem 'sphere' \(metaopt\)"),  # the other kind
        ("plugins", "module 'metaopt_plugins' is already importable"),
    ],
)
def test_bad_names_are_refused(tmp_path: Path, name: str, message: str):
    with pytest.raises(ConfigError, match=message):
        create_plugin("optimizer", name, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_names_derive_from_the_plugin_name():
    names = plugin_names("my-es_2")
    assert (names.distribution, names.package, names.entry_point, names.class_name) == (
        "metaopt-my-es-2",
        "metaopt_my_es_2",
        "my_es_2",
        "MyEs2",
    )
