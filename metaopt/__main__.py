"""`python -m metaopt` runs the command line."""

from metaopt.cli import main

main()
