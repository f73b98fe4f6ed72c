"""``metaopt new optimizer|problem NAME``: start a plugin package from a working template."""

from __future__ import annotations

from pathlib import Path

import click

from metaopt.cli.output import check_output_folder
from metaopt.scaffold import KINDS, create_plugin, plugin_names


@click.command("new")
@click.argument("kind", type=click.Choice(KINDS))
@click.argument("name")
@click.option(
    "--directory",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Where to write the package [./NAME].",
)
def new(kind: str, name: str, directory: Path | None) -> None:
    """Write a plugin package for a new optimizer or problem: code, tests, README."""
    if directory is not None:
        check_output_folder(directory, "--directory")
    target = create_plugin(kind, name, directory)
    names = plugin_names(name)
    click.echo(
        f"Wrote {names.distribution} into {target}/: the {kind} {name!r} "
        f"({names.package}/__init__.py), its tests and a README. Next:\n"
        f"  pip install -e {target}\n"
        f"  metaopt list {name}\n"
        f"  python -m pytest {target}"
    )
