"""Atomic output files (write to a temporary file beside the target, then rename) and the one
JSON sanitiser (:func:`jsonable`).

Every output goes to a temporary sibling first (:func:`atomic_path`, :func:`atomic_outputs`;
a folder of files, such as ``eval --report DIR``, to a staging folder inside it:
:func:`atomic_folder`) and is renamed onto its target only once everything is written. The
renames of one run happen together (:func:`_publish`): a target that cannot be replaced undoes
the ones before it, and a signal that arrives meanwhile is acted on once they are done. A
replaced file keeps its permission bits. A write that the environment refuses (a full disk, a
quota, an I/O error, a read-only file system) is one :class:`GestureSimError` naming the output
and the reason; the temporaries and the folders the run created for its outputs are removed.
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import re
import secrets
import shutil
import stat
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

from gesture_sim import interrupt
from gesture_sim.errors import GestureSimError

#: errno values of a write the environment refused: they become one line naming the output.
WRITE_ERRNOS = frozenset(e for e in (
    errno.ENOSPC, getattr(errno, "EDQUOT", None), errno.EFBIG, errno.EIO, errno.EROFS,
    getattr(errno, "ESTALE", None), errno.ETXTBSY, errno.EMLINK) if e is not None)

#: Folders this process created for its outputs (:func:`ensure_output_folder`); a failed
#: write removes those of its outputs again (when they are empty).
_CREATED: set[Path] = set()
#: Live temporaries (files and staging folders) -> the output they become, so that an error
#: names the output, not the temporary.
_TEMPS: dict[Path, Path] = {}


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _missing_folders(folder: Path) -> list[Path]:
    """``folder`` and its ancestors that do not exist yet, outermost first."""
    out = []
    p = folder
    while not os.path.lexists(p):
        out.append(p)
        if p.parent == p:
            break
        p = p.parent
    return out[::-1]


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


def ensure_output_folder(path: str | os.PathLike[str]) -> Path:
    """Create the folder of output ``path`` if needed; GestureSimError if it cannot be written.

    Call it before long work so that a bad output path fails at once, not at the end. The
    folders it creates are remembered: a failed atomic write of an output inside them removes
    them again (:func:`atomic_path`, :func:`atomic_outputs`).
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    _make_folder(folder)
    if not os.access(folder, os.W_OK):
        raise GestureSimError(f"cannot write to {folder}: permission denied")
    return folder


def _make_folder(folder: Path) -> None:
    """Create ``folder`` (and its parents), remembering what was created."""
    if folder.is_dir():
        return
    missing = _missing_folders(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _remove_empty(missing)
        raise GestureSimError(f"cannot create output folder {_public(folder)}: "
                              f"{_reason(exc)}") from exc
    _CREATED.update(missing)


def _remove_empty(folders: Iterable[Path]) -> None:
    """``rmdir`` each of ``folders`` that is empty, innermost first."""
    for d in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        with contextlib.suppress(OSError):
            d.rmdir()


def _within(folder: Path, paths: Iterable[Path]) -> bool:
    return any(p == folder or folder in p.parents for p in paths)


def _remove_created(paths: Iterable[Path]) -> None:
    """Remove the (empty) folders this process created that hold any of ``paths``."""
    paths = list(paths)
    mine = [d for d in _CREATED if _within(d, paths)]
    _remove_empty(mine)
    _CREATED.difference_update(d for d in mine if not os.path.lexists(d))


def _forget_created(paths: Iterable[Path]) -> None:
    """The folders holding ``paths`` now hold outputs: no later failure removes them."""
    paths = list(paths)
    _CREATED.difference_update([d for d in _CREATED if _within(d, paths)])


@contextlib.contextmanager
def new_folders_removed_on_error(path: str | os.PathLike[str]) -> Iterator[None]:
    """On an exception in the block, remove ``path`` and the parents of it that did not exist
    before the block, if they are empty (a folder output whose writer failed)."""
    missing = _missing_folders(Path(path))
    try:
        yield
    except BaseException:
        _remove_empty(missing)
        raise


def _public(path: Path) -> Path:
    """The output a temporary path stands for (``path`` itself if it is none)."""
    for _ in range(8):
        if path in _TEMPS:
            path = _TEMPS[path]
            continue
        stage = next((s for s in _TEMPS if s in path.parents), None)
        if stage is None:
            break
        path = _TEMPS[stage] / path.relative_to(stage)
    return path


def write_error(exc: BaseException, targets: Sequence[Path | None],
                tmps: Sequence[Path | None] = ()) -> GestureSimError | None:
    """The one-line error for an OSError while writing ``targets`` (through ``tmps``), or None
    when ``exc`` is not about writing them (another OSError passes through unchanged).

    An OSError counts when it names one of the targets or temporaries, or when its errno is one
    of :data:`WRITE_ERRNOS` (disk full, quota, I/O error, read-only file system, ...).
    """
    if not isinstance(exc, OSError) or isinstance(exc, GestureSimError):
        return None
    real = [t for t in targets if t is not None]
    named: Path | None = None
    for f in (exc.filename, exc.filename2):
        if f is None or named is not None:
            continue
        try:
            fp = Path(os.fsdecode(f))
        except (TypeError, ValueError):
            continue
        for t, tmp in zip(targets, list(tmps) + [None] * (len(targets) - len(tmps)),
                          strict=True):
            if t is not None and fp in (t, tmp):
                named = t
    if named is None and exc.errno not in WRITE_ERRNOS:
        return None
    if named is not None:
        what = str(_public(named))
    elif len(real) == 1:
        what = str(_public(real[0]))
    else:
        what = "the outputs " + ", ".join(str(_public(t)) for t in real)
    return GestureSimError(f"cannot write {what}: {_reason(exc)}")


# --------------------------------------------------------------------------------------------
# Temporaries' names: the owner in each, and the stale ones of dead owners removed
# --------------------------------------------------------------------------------------------

#: The name of every temporary this package makes (beside an output, ``.tmp-<stem>-``; in the
#: temp dir, ``gesture-sim-<what>-``) goes on with its owner, ``pid<PID>@<HOST>-``, then the 8
#: random characters of :mod:`tempfile` (or :func:`secrets.token_hex`) and a suffix:
#: ``.tmp-out-pid4242@1a2b3c-k2j3h4g5.mp4``, ``gesture-sim-video-pid4242@1a2b3c-x7q1w2e3``.
#: ``HOST`` is a hash of the host name, so that a folder shared between machines is swept only
#: of this machine's dead processes.
_OWNED = re.compile(r"^(?:\.tmp-|gesture-sim-).*-pid(\d+)@([0-9a-f]{6})-[a-z0-9_]{8}"
                    r"(?:\.[A-Za-z0-9_]+)*$")
#: Folders swept by this process already (:func:`remove_stale_temporaries`).
_SWEPT: set[Path] = set()


def _host_tag() -> str:
    import hashlib
    import socket

    return hashlib.sha256(socket.gethostname().encode(errors="replace")).hexdigest()[:6]


def owned_prefix(prefix: str, pid: int | None = None) -> str:
    """``prefix`` followed by the owner: ``<prefix>pid<PID>@<HOST>-``, the start of a temporary's
    name (``tempfile.mkstemp(prefix=...)`` adds the random part); ``pid``: this process's by
    default. ``prefix`` must start with ``.tmp-`` (beside an output) or ``gesture-sim-`` (the
    temp dir) for :func:`remove_stale_temporaries` to know it as this package's."""
    return f"{prefix}pid{os.getpid() if pid is None else int(pid)}@{_host_tag()}-"


def temp_owner(name: str) -> int | None:
    """The owner's pid in a temporary's name made with :func:`owned_prefix` on this machine,
    else None (not this package's, or another machine's)."""
    m = _OWNED.match(name)
    if m is None or m.group(2) != _host_tag():
        return None
    return int(m.group(1))


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (one of another user counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            return fh.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return True


def remove_stale_temporaries(folder: str | os.PathLike[str] | None = None) -> list[Path]:
    """Remove the temporaries in ``folder`` (the temp dir if None) whose owner has died (a run
    killed outright leaves them: SIGKILL, a power cut); returns what was removed.

    Only names this package makes (:func:`owned_prefix`, this machine's) are touched, only
    this user's, never one whose owner lives (nor this process's); a folder is swept once per
    process. Nothing here fails: what cannot be read or removed stays.
    """
    where = Path(tempfile.gettempdir() if folder is None else folder)
    try:
        key = where.resolve()
    except (OSError, RuntimeError):
        return []
    if key in _SWEPT:
        return []
    _SWEPT.add(key)
    removed: list[Path] = []
    me = os.getpid()
    uid = os.geteuid() if hasattr(os, "geteuid") else None
    try:
        entries = list(os.scandir(where))
    except OSError:
        return []
    for entry in entries:
        pid = temp_owner(entry.name)
        if pid is None or pid == me or _alive(pid):
            continue
        try:
            st = entry.stat(follow_symlinks=False)
            if uid is not None and st.st_uid != uid:
                continue
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
            removed.append(Path(entry.path))
        except OSError:
            continue
    return removed


def temp_dir_prefix(what: str) -> str:
    """The name start of a temporary of this process in the temp dir (``what``: ``"video"``,
    ``"kws"``, ...): ``gesture-sim-<what>-pid<PID>@<HOST>-``. The first call also removes the
    temp dir's stale temporaries (:func:`remove_stale_temporaries`)."""
    remove_stale_temporaries(None)
    return owned_prefix(f"gesture-sim-{what}-")


def _tmp_prefix(target: Path) -> str:
    """``.tmp-<stem>-pid<PID>@<HOST>-`` for a temporary beside ``target`` (:func:`owned_prefix`),
    the stem shortened so that the name (with mkstemp's 8 random characters and the suffix)
    stays within 255 bytes."""
    owner = owned_prefix("")
    room = 255 - len(".tmp--") - len(owner) - 8 - len(target.suffix.encode()) - len(".old")
    stem = target.stem.encode()[: max(room, 1)].decode(errors="ignore")
    return owned_prefix(f".tmp-{stem}-")


def _new_temp(target: Path, suffix: str | None = None) -> Path:
    """An empty temporary file beside ``target`` (usual permissions), its folder created (and
    swept of the stale temporaries of dead runs: :func:`remove_stale_temporaries`)."""
    folder = ensure_output_folder(target)
    remove_stale_temporaries(folder)
    try:
        fd, name = tempfile.mkstemp(prefix=_tmp_prefix(target),
                                    suffix=suffix if suffix is not None else target.suffix,
                                    dir=folder)
    except OSError as exc:
        raise GestureSimError(f"cannot write {_public(target)}: cannot create a file in "
                              f"{_public(folder)}: {_reason(exc)}") from exc
    os.close(fd)
    tmp = Path(name)
    with contextlib.suppress(OSError):  # mkstemp makes 0600; give the file the usual ones
        os.chmod(tmp, 0o666 & ~_umask())
    _TEMPS[tmp] = target
    return tmp


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """SIGINT/SIGTERM that arrive in the block are acted on after it (main thread only): the
    renames of one run are never cut in half."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    old: dict[int, Any] = {}
    try:
        for s in (signal.SIGINT, signal.SIGTERM):
            old[s] = signal.signal(s, lambda signum, frame: pending.append(signum))
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        if pending:
            signal.raise_signal(pending[0])


def _backup(dest: Path) -> Path | None:
    """A hard link to ``dest`` beside it (to put it back if a later rename fails), or None."""
    for _ in range(3):
        bak = dest.with_name(f"{_tmp_prefix(dest)}{secrets.token_hex(4)}.old")
        try:
            os.link(dest, bak)
            return bak
        except FileExistsError:
            continue
        except OSError:
            return None
    return None


def _publish(pairs: Sequence[tuple[Path, Path]]) -> None:
    """Rename each temporary onto its target, all or none: every target is checked first; a
    rename that fails puts back the targets renamed before it; a replaced file keeps its
    permission bits; signals wait until the renames are done."""
    for _tmp, dest in pairs:
        if dest.is_dir() and not dest.is_symlink():
            raise GestureSimError(f"cannot write {dest}: it is a folder (it appeared during "
                                  "the run); nothing was replaced")
    done: list[tuple[Path, bool, Path | None]] = []   # (target, existed, its backup)
    backups: list[Path] = []
    with _signals_deferred():
        try:
            for tmp, dest in pairs:
                try:
                    st = os.stat(dest)
                except OSError:
                    st = None
                if st is not None and stat.S_ISREG(st.st_mode):
                    with contextlib.suppress(OSError):
                        os.chmod(tmp, stat.S_IMODE(st.st_mode) & ~(stat.S_ISUID | stat.S_ISGID))
                bak = _backup(dest) if st is not None and len(pairs) > 1 else None
                if bak is not None:
                    backups.append(bak)
                try:
                    os.replace(tmp, dest)
                except OSError as exc:
                    raise GestureSimError(
                        f"cannot replace {_public(dest)}: {_reason(exc)}"
                        + ("; nothing was replaced" if len(pairs) > 1 else "")) from exc
                done.append((dest, st is not None, bak))
        except BaseException:
            for dest, existed, bak in reversed(done):   # put the previous outputs back
                with contextlib.suppress(OSError):
                    if bak is not None:
                        os.replace(bak, dest)
                    elif not existed:
                        os.unlink(dest)
            raise
        finally:
            for bak in backups:
                with contextlib.suppress(OSError):
                    bak.unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it onto ``path`` on success.

    On an exception the temporary file is removed and ``path`` is left untouched, so a failed
    run never leaves a half-written output; nor is anything renamed once SIGINT/SIGTERM has
    arrived (:func:`gesture_sim.interrupt.check`). The suffix defaults to the target's
    (encoders such as ffmpeg choose the container from it). A replaced file keeps its
    permission bits. An OSError of the write (:func:`write_error`: a full disk, ...) becomes
    one GestureSimError naming ``path``; the folders created for it are removed again.
    """
    with _atomic([Path(path)], suffix, check_written=False) as (tmp,):
        yield tmp


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


@contextlib.contextmanager
def atomic_outputs(*paths: str | os.PathLike[str] | None) -> Iterator[list[Path | None]]:
    """Temporary paths for all outputs of one run, renamed onto ``paths`` together at the end.

    Yields one temporary path beside each target (``None`` stays ``None``), with the target's
    suffix. Only when the block finishes without an exception are they renamed onto their
    targets, together (:func:`_publish`); on any exception (including KeyboardInterrupt and
    the termination the CLI raises for SIGTERM) every temporary is removed, every previous
    file is left as it was, and the folders created for the outputs are removed again. A run
    thus never leaves some outputs new and others old. An OSError of the writes (a full disk,
    ...) becomes one GestureSimError naming the output.
    """
    with _atomic([Path(p) if p is not None else None for p in paths], None,
                 check_written=True) as tmps:
        yield tmps


@contextlib.contextmanager
def _atomic(targets: list[Path | None], suffix: str | None,
            check_written: bool) -> Iterator[list[Path | None]]:
    """The body of :func:`atomic_path` and :func:`atomic_outputs`: temporaries beside
    ``targets`` (``suffix``: theirs if None), published together, or removed with the folders
    created for them; ``check_written``: an empty temporary is an internal error."""
    tmps: list[Path | None] = []
    folders = [t.parent for t in targets if t is not None]
    try:
        for t in targets:
            tmps.append(None if t is None else _new_temp(t, suffix))
        yield tmps
        for tmp, t in zip(tmps, targets, strict=True):
            if check_written and tmp is not None and t is not None:
                if not tmp.is_file() or tmp.stat().st_size == 0:
                    raise GestureSimError(f"internal error: output {t} was not written")
        interrupt.check()   # a signalled run publishes nothing
        _publish([(tmp, t) for tmp, t in zip(tmps, targets, strict=True)
                  if tmp is not None and t is not None])
        _forget_created(folders)
    except BaseException as exc:
        for tmp in tmps:
            if tmp is not None:
                with contextlib.suppress(OSError):
                    tmp.unlink()
        _remove_created(folders)
        err = write_error(exc, targets, tmps)
        if err is not None:
            raise err from exc
        raise
    finally:
        for tmp in tmps:
            if tmp is not None:
                _TEMPS.pop(tmp, None)


@contextlib.contextmanager
def atomic_folder(folder: str | os.PathLike[str]) -> Iterator[Path]:
    """A staging folder for the files of a folder output, published into ``folder`` together.

    Yields an empty hidden folder inside ``folder`` (created if needed), on the same file
    system. Whatever files the block writes under it (subfolders included) are renamed to the
    same relative paths in ``folder`` only when the block finishes without an exception, all
    of them together (:func:`_publish`); other files already in ``folder`` stay. On an
    exception (or a signal) nothing in ``folder`` changes; the staging folder, and the folders
    created for the output, are removed either way. An OSError of the writes (a full disk,
    ...) becomes one GestureSimError naming the file.
    """
    folder = Path(folder)
    stage: Path | None = None
    dests: list[Path] = [folder]
    try:
        _make_folder(folder)
        remove_stale_temporaries(folder)
        try:
            stage = Path(tempfile.mkdtemp(prefix=_tmp_prefix(folder), dir=folder))
        except OSError as exc:
            raise GestureSimError(f"cannot write into {_public(folder)}: "
                                  f"{_reason(exc)}") from exc
        with contextlib.suppress(OSError):
            os.chmod(stage, 0o777 & ~_umask())
        _TEMPS[stage] = folder
        yield stage
        interrupt.check()   # a signalled run publishes nothing
        files = [f for f in sorted(stage.rglob("*")) if f.is_file() and not f.is_symlink()]
        pairs = [(f, folder / f.relative_to(stage)) for f in files]
        dests += [d for _, d in pairs]
        for sub in sorted({d.parent for _, d in pairs}, key=lambda p: len(p.parts)):
            if os.path.lexists(sub) and not sub.is_dir():
                raise GestureSimError(f"cannot write {sub}: it is not a folder; nothing "
                                      "was replaced")
            _make_folder(sub)
        _publish(pairs)
        _forget_created(dests)
    except BaseException as exc:
        _cleanup_stage(stage)
        stage = None
        _remove_created(dests)
        err = write_error(exc, [folder])
        if err is not None:
            raise err from exc
        raise
    finally:
        _cleanup_stage(stage)


def _cleanup_stage(stage: Path | None) -> None:
    if stage is not None:
        shutil.rmtree(stage, ignore_errors=True)
        _TEMPS.pop(stage, None)


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
