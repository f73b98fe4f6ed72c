"""The ``metaopt`` command line; ``main`` is the console script's entry point."""

from metaopt.cli.commands import main

__all__ = ["main"]
