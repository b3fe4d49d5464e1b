"""Progress bars for long work (tqdm on stderr, silent when asked or when not a terminal)."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(
    iterable: Iterable[T] | None = None, *, desc: str = "", total: int | float | None = None,
    enabled: bool = True, unit: str = "it",
) -> Iterator[T] | tqdm:
    """A tqdm bar on stderr; disabled when ``enabled`` is false or stderr is not a terminal."""
    return tqdm(
        iterable, desc=desc, total=total, unit=unit, file=sys.stderr, leave=False,
        disable=(not enabled) or (not sys.stderr.isatty()), dynamic_ncols=True,
    )
