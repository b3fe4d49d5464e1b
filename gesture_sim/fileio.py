"""Atomic output files (write to a temporary file beside the target, then rename) and the one
JSON sanitiser (:func:`jsonable`)."""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from gesture_sim import interrupt
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


def _tmp_prefix(target: Path) -> str:
    """``.tmp-<stem>-`` for a temporary beside ``target``, the stem shortened so that the name
    (with mkstemp's 8 random characters and the suffix) stays within 255 bytes."""
    room = 255 - len(".tmp--") - 8 - len(target.suffix.encode())
    stem = target.stem.encode()[: max(room, 1)].decode(errors="ignore")
    return f".tmp-{stem}-"


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it onto ``path`` on success.

    On an exception the temporary file is removed and ``path`` is left untouched, so a failed
    run never leaves a half-written output; nor is anything renamed once SIGINT/SIGTERM has
    arrived (:func:`gesture_sim.interrupt.check`). The suffix defaults to the target's
    (encoders such as ffmpeg choose the container from it).
    """
    target = Path(path)
    folder = ensure_output_folder(target)
    fd, tmp_name = tempfile.mkstemp(
        prefix=_tmp_prefix(target), suffix=suffix if suffix is not None else target.suffix,
        dir=folder,
    )
    os.close(fd)
    tmp = Path(tmp_name)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    try:
        yield tmp
        interrupt.check()   # a signalled run publishes nothing
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


@contextlib.contextmanager
def atomic_outputs(*paths: str | os.PathLike[str] | None) -> Iterator[list[Path | None]]:
    """Temporary paths for all outputs of one run, renamed onto ``paths`` together at the end.

    Yields one temporary path beside each target (``None`` stays ``None``), with the target's
    suffix. Only when the block finishes without an exception are they renamed, one after the
    other, onto their targets; on any exception (including KeyboardInterrupt and the
    termination the CLI raises for SIGTERM) every temporary is removed and every previous
    file is left as it was. A run thus never leaves some outputs new and others old.
    """
    tmps: list[Path | None] = []
    try:
        for p in paths:
            if p is None:
                tmps.append(None)
                continue
            target = Path(p)
            folder = ensure_output_folder(target)
            fd, name = tempfile.mkstemp(prefix=_tmp_prefix(target), suffix=target.suffix,
                                        dir=folder)
            os.close(fd)
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(name, 0o666 & ~umask)
            tmps.append(Path(name))
        yield tmps
        for tmp, p in zip(tmps, paths, strict=True):
            if tmp is not None and p is not None:
                if not tmp.is_file() or tmp.stat().st_size == 0:
                    raise GestureSimError(f"internal error: output {p} was not written")
        interrupt.check()   # a signalled run publishes nothing
        for tmp, p in zip(tmps, paths, strict=True):
            if tmp is not None and p is not None:
                os.replace(tmp, p)
    finally:
        for tmp in tmps:
            if tmp is not None:
                with contextlib.suppress(OSError):
                    tmp.unlink()


def decoding_exceptions() -> tuple[type[BaseException], ...]:
    """The ways a stored file fails to decode (what :func:`decoding_errors` catches)."""
    import zipfile

    return (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, IndexError, TypeError,
            AttributeError)


def damaged(path: str | os.PathLike[str], what: str, rebuild: str,
            exc: BaseException) -> GestureSimError:
    """The one-line error for a stored file that failed to decode (see :func:`decoding_errors`)."""
    import json
    import zipfile

    if isinstance(exc, FileNotFoundError):
        cause = f"{Path(exc.filename).name if exc.filename else 'a file'} is missing"
    elif isinstance(exc, KeyError):
        cause = f"missing entry {exc.args[0]!r}" if exc.args else "missing entry"
    elif isinstance(exc, (zipfile.BadZipFile, EOFError)):
        cause = "truncated or not a NumPy archive"
    elif isinstance(exc, ValueError) and "pickle" in str(exc):
        cause = "not a NumPy .npz archive"
    elif isinstance(exc, json.JSONDecodeError):
        cause = f"invalid JSON at line {exc.lineno}, column {exc.colno}"
    elif isinstance(exc, UnicodeDecodeError):
        cause = "not UTF-8 text"
    elif isinstance(exc, OSError) and exc.strerror:
        cause = exc.strerror
    elif isinstance(exc, (AttributeError, TypeError)):
        cause = "unexpected structure"
    else:
        first = str(exc).splitlines()[0] if str(exc) else "bad data"
        cause = f"{type(exc).__name__}: {first[:120]}"
    return GestureSimError(f"{path}: damaged {what} ({cause}); {rebuild}")


@contextlib.contextmanager
def decoding_errors(path: str | os.PathLike[str], what: str, rebuild: str) -> Iterator[None]:
    """Turn any failure to decode a stored file into one line naming it and how to rebuild it.

    ``what`` names the thing (``"motion library"``), ``rebuild`` the remedy (``"rebuild it with
    'gesture-sim library build'"``). GestureSimError passes through unchanged; truncated or
    damaged archives (zipfile.BadZipFile, EOFError, numpy's ValueError), bad JSON, missing keys
    and wrong types become ``GestureSimError("PATH: damaged WHAT (...); REBUILD")``.
    """
    try:
        yield
    except GestureSimError:
        raise
    except decoding_exceptions() as exc:
        raise damaged(path, what, rebuild, exc) from exc


def jsonable(value: Any, *, finite: bool = True) -> Any:
    """``value`` as plain JSON types, recursively: numpy scalars become ``int``/``float``/
    ``bool``, numpy arrays, lists and tuples become lists, paths become strings, and dict keys
    JSON cannot take (anything but str, int, float, bool, None) become strings.

    With ``finite`` (the default) NaN and ±inf become ``None`` (JSON has no NaN); with
    ``finite=False`` they stay floats, which ``json.dumps`` writes as ``NaN``/``Infinity`` and
    Python's ``json`` reads back. Other objects are returned unchanged (``json.dumps`` then
    raises, or applies its ``default=``).
    """
    import numpy as np

    if isinstance(value, dict):
        return {k if k is None or isinstance(k, str | int | float | bool) else str(k):
                jsonable(v, finite=finite) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v, finite=finite) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), finite=finite)
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        x = float(value)
        return None if finite and not math.isfinite(x) else x
    if isinstance(value, np.generic):
        return jsonable(value.item(), finite=finite)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value
