"""Progress bars for long work (tqdm on stderr, silent when asked or when not a terminal).

Every update is also a check for SIGINT/SIGTERM (:func:`gesture_sim.interrupt.check`): long
work reports progress, so a signal whose first raise Python dropped still stops it promptly.
The bars share a thread lock, not tqdm's default multiprocessing one: that is a POSIX
semaphore in every spawned batch worker, and a worker killed before its exit handlers ran left
it to the resource tracker, which then printed a "leaked semaphore" warning after the batch's
one line.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

from gesture_sim import interrupt

T = TypeVar("T")


class _Bar(tqdm):
    """tqdm whose every update checks for an interruption."""

    def update(self, n: float | None = 1) -> bool | None:
        interrupt.check()
        return super().update(n)

    def __iter__(self) -> Iterator[T]:
        for item in super().__iter__():
            interrupt.check()
            yield item


_Bar.set_lock(threading.RLock())


def progress(
    iterable: Iterable[T] | None = None, *, desc: str = "", total: int | float | None = None,
    enabled: bool = True, unit: str = "it",
) -> Iterator[T] | tqdm:
    """A tqdm bar on stderr; disabled when ``enabled`` is false or stderr is not a terminal.
    Each update and each item checks for SIGINT/SIGTERM (see the module docstring)."""
    return _Bar(
        iterable, desc=desc, total=total, unit=unit, file=sys.stderr, leave=False,
        disable=(not enabled) or (not sys.stderr.isatty()), dynamic_ncols=True,
    )
