"""Atomic output files: write to a temporary file beside the target, then rename."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from gesture_sim.errors import GestureSimError


def ensure_output_folder(path: str | os.PathLike[str]) -> Path:
    """Create the folder of output ``path`` if needed; GestureSimError if it cannot be written.

    Call it before long work so that a bad output path fails at once, not at the end.
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise GestureSimError(f"cannot create output folder {folder}: {exc.strerror}") from exc
    if not os.access(folder, os.W_OK):
        raise GestureSimError(f"cannot write to {folder}: permission denied")
    return folder


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it onto ``path`` on success.

    On an exception the temporary file is removed and ``path`` is left untouched, so a failed
    run never leaves a half-written output. The suffix defaults to the target's (encoders such
    as ffmpeg choose the container from it).
    """
    target = Path(path)
    folder = ensure_output_folder(target)
    fd, tmp_name = tempfile.mkstemp(
        prefix=f".tmp-{target.stem}-", suffix=suffix if suffix is not None else target.suffix,
        dir=folder,
    )
    os.close(fd)
    tmp = Path(tmp_name)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
