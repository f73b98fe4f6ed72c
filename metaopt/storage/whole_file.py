"""Files written whole or not at all: a killed run or a failed write never leaves a
half-written CSV, figure or index where a reader would take it for a finished one."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from metaopt.errors import ConfigError


def check_regular(path: Path) -> None:
    """ConfigError if ``path`` exists but is not a regular file (a FIFO, device, socket), which
    a whole-file write would replace rather than write to; a symlink is judged by its target."""
    if Path(path).exists() and not Path(path).is_file() and not Path(path).is_dir():
        raise ConfigError(
            f"{path} is not a regular file (a FIFO, device or socket); "
            "give a regular file's path, a new one, or a symlink to a regular file"
        )


def temporary_beside(path: Path, suffix: str = "") -> tuple[int, Path]:
    """A hidden temporary file in ``path``'s folder, its descriptor and path, with the
    permissions open() gives a new file (not mkstemp's 0600): what a whole-file write fills,
    then renames over ``path``."""
    descriptor, temporary = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.name}.", suffix=suffix
    )
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(temporary, 0o666 & ~umask)
    return descriptor, Path(temporary)


@contextmanager
def written_whole(path: Path, binary: bool = False) -> Iterator[IO]:
    """A handle (text, or bytes with ``binary``) whose content lands at ``path`` only when the
    block succeeds: written to a hidden temporary file beside it, then renamed over it. A
    symlink is written through (its target replaced); a FIFO, device or socket is refused."""
    check_regular(path)
    path = Path(os.path.realpath(path))
    descriptor, temporary = temporary_beside(path)
    text = {} if binary else {"newline": "", "encoding": "utf-8"}
    try:
        with open(descriptor, "wb" if binary else "w", **text) as handle:
            yield handle
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
