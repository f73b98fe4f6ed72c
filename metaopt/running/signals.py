"""How a run is stopped from outside: Ctrl-C or SIGTERM, and the exception that reports it."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM stopped a run; everything finished is stored."""

    def __init__(self, run_id: int, stored: int) -> None:
        super().__init__(f"run {run_id} interrupted with {stored} evaluations stored")
        self.run_id = run_id
        self.stored = stored

    def __reduce__(self) -> tuple[type, tuple[int, int]]:
        # picklable as raised in a worker process (compare --jobs) and re-raised in the parent
        return (type(self), (self.run_id, self.stored))


@contextmanager
def stop_on_sigterm() -> Iterator[None]:
    """Turn SIGTERM into KeyboardInterrupt while a run (or a compare --jobs) goes on (main
    thread only)."""

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, interrupt)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
