"""One validation layer at the edge: numbers, input files and output paths.

Everything that enters through the command line (or the public API functions that the commands
call) is checked here once, before any work starts, with a one-line
:class:`~gesture_sim.errors.GestureSimError` that names the argument and the accepted range.

* :func:`number` / :func:`integer`: finite, within a range (NaN, inf and absurd magnitudes are
  refused before they reach numpy, mujoco or ffmpeg).
* :func:`input_file`: exists, is a regular file (not a folder, FIFO or device such as
  ``/dev/zero``), is readable.
* :func:`check_outputs`: every output of one run together, before the run — not an existing
  folder, not a special file, a supported extension, not the same file as an input or as another
  output (resolved paths: symlinks and hard links included), not a symlink loop nor through a
  broken symlink, a folder that exists or can be created and where a file can be created (tried),
  and an existing target that a rename may replace (not another user's file in a sticky folder
  such as /tmp, not immutable or append-only). It returns the paths to write (symlinks resolved,
  so that an output symlink keeps pointing at the new file).

This module imports only the standard library and :mod:`gesture_sim.errors` (and, when it
runs, the light :mod:`gesture_sim.fileio` for the temporaries' names), so the commands can
call it before their heavy imports (a bad argument fails in well under a second). Outputs that
pass leave their folders, and the temp dir, swept of the stale temporaries of dead runs
(:func:`gesture_sim.fileio.remove_stale_temporaries`).
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import stat
import sys
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from gesture_sim.errors import GestureSimError

#: Largest seed accepted (numpy's SeedSequence takes any non-negative int; 32 bits is plenty).
SEED_MAX = 2**32 - 1
#: Video / loop frame rates (Hz).
FPS_RANGE = (1.0, 240.0)
#: Frame width and height (pixels); even numbers only (yuv420p).
WIDTH_RANGE = (16, 3840)
HEIGHT_RANGE = (16, 2160)
#: Render worker processes.
WORKERS_RANGE = (1, 64)
#: Video containers the final ffmpeg mux (H.264 + AAC) can write.
VIDEO_EXTENSIONS = (".mp4", ".m4v", ".mov", ".mkv")
#: Figures (matplotlib writes PNG).
PNG_EXTENSIONS = (".png",)
#: JSON documents.
JSON_EXTENSIONS = (".json",)


def _fmt(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _range_text(lo: float | None, hi: float | None, lo_open: bool, integer: bool) -> str:
    kind = "an integer" if integer else "a number"
    if lo is not None and hi is not None:
        if lo_open:
            return f"{kind} above {_fmt(lo)} and at most {_fmt(hi)}"
        return f"{kind} from {_fmt(lo)} to {_fmt(hi)}"
    if lo is not None:
        return f"{kind} above {_fmt(lo)}" if lo_open else f"{kind} of at least {_fmt(lo)}"
    if hi is not None:
        return f"{kind} of at most {_fmt(hi)}"
    return f"a finite {kind[3:] if integer else 'number'}"


def number(name: str, value: float, lo: float | None = None, hi: float | None = None, *,
           lo_open: bool = False, hint: str = "") -> float:
    """``value`` as a float if it is finite and in ``[lo, hi]`` (``(lo, hi]`` with
    ``lo_open``); else GestureSimError naming ``name`` and the range."""
    try:
        x = math.nan if isinstance(value, str | bytes | bool) else float(value)
    except (TypeError, ValueError):
        x = math.nan
    ok = math.isfinite(x) and (lo is None or (x > lo if lo_open else x >= lo)) and (
        hi is None or x <= hi)
    if not ok:
        raise GestureSimError(
            f"{name} must be {_range_text(lo, hi, lo_open, False)}{hint}, got {value!r}")
    return x


def integer(name: str, value: int, lo: int | None = None, hi: int | None = None, *,
            even: bool = False, hint: str = "") -> int:
    """``value`` as an int if it is an integer in ``[lo, hi]`` (and even, if asked)."""
    ok = isinstance(value, int) and not isinstance(value, bool) or (
        isinstance(value, float) and value.is_integer())
    ok = ok and (lo is None or value >= lo) and (hi is None or value <= hi)
    if ok and even and int(value) % 2:
        raise GestureSimError(f"{name} must be an even number{hint}, got {value!r}")
    if not ok:
        raise GestureSimError(
            f"{name} must be {_range_text(lo, hi, False, True)}{hint}, got {value!r}")
    return int(value)


def seed(name: str, value: int) -> int:
    """A seed: an integer in 0 .. 2**32 - 1."""
    return integer(name, value, 0, SEED_MAX)


def style(name: str, value: float) -> float:
    """The style dial as the user sees it: 0 calm ... 1 energetic."""
    return number(name, value, 0.0, 1.0, hint=" (0 calm, 0.5 neutral, 1 energetic)")


def fps(name: str, value: float) -> float:
    """A frame rate in :data:`FPS_RANGE` (Hz)."""
    return number(name, value, *FPS_RANGE, hint=" frames per second")


def frame_size(width: int, height: int) -> tuple[int, int]:
    """``--width``/``--height``: even integers within :data:`WIDTH_RANGE`/:data:`HEIGHT_RANGE`."""
    return (integer("--width", width, *WIDTH_RANGE, even=True, hint=" (pixels)"),
            integer("--height", height, *HEIGHT_RANGE, even=True, hint=" (pixels)"))


def workers(name: str, value: int | None) -> int | None:
    """Render processes: ``None`` (the CPUs) or an integer in :data:`WORKERS_RANGE`."""
    return None if value is None else integer(name, value, *WORKERS_RANGE)


def labels(name: str, items: Sequence[tuple[float, str]],
           duration_s: float | None = None) -> tuple[tuple[float, str], ...]:
    """Semantic gesture requests ``(t_s, label)``: t finite, >= 0 and, when the audio duration
    is known, not past its end."""
    out = []
    for t, label in items:
        hi = duration_s
        hint = f" (seconds within the {duration_s:.2f} s audio)" if hi is not None else \
            " (seconds from the start of the audio)"
        if not label.strip():
            raise GestureSimError(f"{name} {t}:{label!r}: empty label")
        out.append((number(f"{name} time of {label!r}", t, 0.0, hi, hint=hint), label))
    return tuple(out)


#: How far a side file's times (a TextGrid, an RTTM, sign annotations) may run past the end of
#: the audio or motion they belong to (s): the one tolerance every reader applies. Aligners
#: and annotation tools round the last boundary up; half a second more is another recording.
SIDE_FILE_OVERRUN_S = 0.5


def side_file_times(name: str, path: str | os.PathLike[str],
                    items: Iterable[tuple[float, float, str]], duration_s: float,
                    of: str = "the audio", hint: str = "is the file for this recording?"
                    ) -> None:
    """A side file's times must lie within what it annotates: no start before 0 s and no
    start or end after ``duration_s`` + :data:`SIDE_FILE_OVERRUN_S` (the one tolerance rule of
    TextGrids, transcripts, RTTM turns, sign annotations and ``--signals`` labels).

    Args:
        name: the option (``"--textgrid"``) or ``""``; path: the side file.
        items: ``(start_s, end_s, what)`` of each timed item (``what`` names it in the
            message: ``"word 'wave'"``); a point has ``end_s == start_s``.
        duration_s: the length of ``of`` (s), the audio or motion the file describes.

    Raises:
        GestureSimError: one line naming the file, the first item at fault, the length.
    """
    where = f"{name} {path}" if name else str(path)
    limit = duration_s + SIDE_FILE_OVERRUN_S
    for start, end, what in items:
        if not (math.isfinite(start) and math.isfinite(end)):
            raise GestureSimError(f"{where}: {what} has a time that is not a finite number")
        if start < -1e-9:
            raise GestureSimError(
                f"{where}: {what} at {start:.6g} s starts before {of} does (times are seconds "
                "from its start, never negative)")
        if start >= duration_s or end > limit:
            span = f"{start:.6g} s" + ("" if end == start else f" (to {end:.6g} s)")
            raise GestureSimError(
                f"{where}: {what} at {span} lies after {of} ends ({duration_s:.3f} s; a side "
                f"file may run past the end by {SIDE_FILE_OVERRUN_S:g} s at most); {hint}")


# --------------------------------------------------------------------------------------------
# Input files and folders
# --------------------------------------------------------------------------------------------


#: The values of ``GESTURE_SIM_PHYSICS_WORKER`` (:func:`gesture_sim.feed.physics_worker`).
PHYSICS_WORKER_MODES = ("process", "thread", "off")


def physics_worker_env(environ: dict[str, str] | None = None) -> str | None:
    """``GESTURE_SIM_PHYSICS_WORKER`` as given (stripped, lower case; None when unset or
    empty), refusing a value that is none of :data:`PHYSICS_WORKER_MODES` (it used to mean
    "off" without a word)."""
    value = (os.environ if environ is None else environ).get("GESTURE_SIM_PHYSICS_WORKER")
    if value is None or not value.strip():
        return None
    mode = value.strip().lower()
    if mode not in PHYSICS_WORKER_MODES:
        raise GestureSimError(
            f"GESTURE_SIM_PHYSICS_WORKER={value!r}: not a physics worker; set it to "
            f"{', '.join(PHYSICS_WORKER_MODES)} (where the deferred physics runs: a forked "
            "child, a thread, or the feed's own thread), or unset it")
    return mode


def check_environment() -> None:
    """The environment variables the commands read, checked once before any work."""
    physics_worker_env()


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def input_file(name: str, path: str | os.PathLike[str], what: str = "file") -> Path:
    """An existing, readable regular file (GestureSimError otherwise)."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise GestureSimError(f"{name} {p}: {what} not found (no such file)") from None
    except OSError as exc:
        raise GestureSimError(f"{name} {p}: cannot read: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        raise GestureSimError(f"{name} {p}: is {_kind(st.st_mode)}, not {_article(what)}")
    if not os.access(p, os.R_OK):
        raise GestureSimError(f"{name} {p}: permission denied")
    return p


def motion_file(name: str, path: str | os.PathLike[str]) -> Path:
    """A motion capture input: a readable ``.bvh``, or a ``.npz`` that is a zip archive (numpy's
    own error for a damaged one would advise loading it with pickle)."""
    import zipfile

    p = input_file(name, path, "motion file")
    if p.suffix.lower() == ".npz" and not zipfile.is_zipfile(p):
        raise GestureSimError(f"{name} {p}: not a NumPy .npz archive (truncated, damaged, or "
                              "another kind of file named .npz)")
    return p


def input_folder(name: str, path: str | os.PathLike[str], what: str = "folder") -> Path:
    """An existing folder (GestureSimError otherwise)."""
    p = Path(path)
    if not p.exists():
        raise GestureSimError(f"{name} {p}: no such folder")
    if not p.is_dir():
        raise GestureSimError(f"{name} {p}: is a file, not {_article(what)}")
    return p


def _article(what: str) -> str:
    return ("an " if what[:1].lower() in "aeiou" else "a ") + what


# --------------------------------------------------------------------------------------------
# Outputs
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Output:
    """One output of a run.

    Attributes:
        name: the argument that names it (``"-o/--output"``, ``"--metrics"``) for messages.
        path: the path given.
        extensions: accepted suffixes (lower case, with the dot), or ``()`` for any.
        folder: the output is a folder (``eval --report``, ``library build -o``): it may exist
            as a folder, but not as a file.
        within: the folder output this is a file (or subfolder) of, for messages (the report's
            ``DIR/table.md`` is checked as an output of its own).
    """

    name: str
    path: str | os.PathLike[str]
    extensions: tuple[str, ...] = ()
    folder: bool = False
    within: str | os.PathLike[str] | None = None


class _SymlinkLoop(Exception):
    """A path whose symlinks lead back to themselves."""


def _resolve(p: Path) -> Path:
    """``p`` with its symlinks resolved (it need not exist); :class:`_SymlinkLoop` for a loop."""
    try:
        return p.resolve(strict=False)
    except RuntimeError as exc:   # Python < 3.13: "Symlink loop from ..."
        raise _SymlinkLoop(str(p)) from exc
    except OSError as exc:
        if exc.errno == errno.ELOOP:   # Python >= 3.13
            raise _SymlinkLoop(str(p)) from exc
        return Path(os.path.abspath(p))


def _identity(p: Path) -> tuple[Path, tuple[int, int] | None]:
    """(resolved path, (device, inode) if it exists)."""
    try:
        r = _resolve(p)
    except _SymlinkLoop:
        return Path(os.path.abspath(p)), None
    try:
        st = r.stat()
        return r, (st.st_dev, st.st_ino)
    except OSError:
        return r, None


def _check_links(out: Output, given: Path) -> None:
    """Refuse an output path that is (or passes through) a symlink loop or a broken symlink:
    following the link would write (and create folders) wherever it happens to point."""
    try:
        _resolve(given)
    except _SymlinkLoop:
        raise GestureSimError(
            f"{out.name} {given}: is a symbolic link loop (its links lead back to each other); "
            "remove the link or give another path") from None
    parts = given.parts
    for k in range(1, len(parts) + 1):
        prefix = Path(*parts[:k])
        if prefix.is_symlink() and not prefix.exists():
            try:
                to = f" (to {os.readlink(prefix)})"
            except OSError:
                to = ""
            what = "is a broken symbolic link" if prefix == given else \
                f"{prefix} is a broken symbolic link"
            raise GestureSimError(
                f"{out.name} {given}: {what}{to}; refusing to write through it (remove the "
                "link or give another path)")


#: The longest file name (bytes, one path component) and whole path Linux file systems take
#: (``NAME_MAX``, ``PATH_MAX``); the folder's own limit is asked where it exists.
NAME_MAX = 255
PATH_MAX = 4096


def _name_max(folder: Path) -> int:
    """``NAME_MAX`` of the nearest existing folder at or above ``folder``."""
    p = folder
    while not p.exists() and p.parent != p:
        p = p.parent
    try:
        return int(os.pathconf(p, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return NAME_MAX


def _check_name_lengths(out: Output, given: Path) -> None:
    """Refuse a path with a component over the file system's name limit (``File name too
    long`` at the first write, after the work) or a whole path over :data:`PATH_MAX`."""
    absolute = Path(os.path.abspath(given))
    size = len(os.fsencode(str(absolute)))
    if size >= PATH_MAX:
        raise GestureSimError(
            f"{out.name} {str(given)[:60]}...: the path is {size} bytes long, over the "
            f"{PATH_MAX - 1} a path may have; give a shorter one")
    limit = _name_max(absolute.parent)
    for part in given.parts:
        n = len(os.fsencode(part))
        if n > limit:
            raise GestureSimError(
                f"{out.name} {part[:40]}...{part[-12:]}: a file or folder name of {n} bytes, "
                f"over the {limit} the file system takes; give a shorter name")


def check_outputs(outputs: Iterable[Output | None],
                  inputs: Iterable[str | os.PathLike[str] | None] = ()) -> list[Path]:
    """Check every output of a run before the run; return the paths to write, in order.

    ``None`` entries (an option not given) are skipped in the input and kept as ``None`` in the
    result. Symlinks are resolved: writing the returned path updates the link's target.

    Raises:
        GestureSimError: an output that is an existing folder (or a file, for a folder output),
            a FIFO/device/socket, has an unsupported extension, is the same file as an input (or
            as a file inside an input folder, such as a library's manifest) or as another
            output, or lies in a folder that cannot be created or written.
    """
    seen: dict[object, str] = {}
    ins: dict[object, str] = {}
    for i in inputs:
        if i is None:
            continue
        for f in _input_files(Path(i)):
            r, ident = _identity(f)
            ins[r] = str(f)
            if ident is not None:
                ins[ident] = str(f)
    result: list[Path] = []
    written: list[Path] = []   # the folders written to
    for out in outputs:
        if out is None:
            result.append(None)  # type: ignore[arg-type]
            continue
        given = Path(out.path)
        if str(out.path) == "" or (not out.folder and given.name in ("", ".", "..")):
            raise GestureSimError(f"{out.name}: {str(out.path)!r} is not a file name")
        _check_name_lengths(out, given)
        _check_links(out, given)
        resolved, ident = _identity(given)
        try:
            st = resolved.stat() if resolved.exists() else None
        except OSError:
            st = None
        if st is not None:
            if out.folder:
                if not stat.S_ISDIR(st.st_mode):
                    raise GestureSimError(
                        f"{out.name} {given}: exists and is not a folder; give a folder path")
            elif stat.S_ISDIR(st.st_mode) and out.within is not None:
                raise GestureSimError(
                    f"{out.name} {out.within}: {given} is an existing folder where the output "
                    "writes a file; move it away or choose another folder")
            elif stat.S_ISDIR(st.st_mode):
                raise GestureSimError(
                    f"{out.name} {given}: is an existing folder; give a file path such as "
                    f"{given / ('out' + (out.extensions[0] if out.extensions else ''))}")
            elif not stat.S_ISREG(st.st_mode):
                raise GestureSimError(
                    f"{out.name} {given}: is {_kind(st.st_mode)}; refusing to replace it with "
                    "a regular file")
        for key in (resolved, ident):
            if key is None:
                continue
            if key in ins:
                raise GestureSimError(
                    f"{out.name} {given}: is the input file {ins[key]}; writing it would "
                    "destroy the input (choose another output path)")
            if key in seen:
                raise GestureSimError(
                    f"{out.name} {given}: is also the path of {seen[key]}; give each output "
                    "its own path")
        if out.extensions and given.suffix.lower() not in out.extensions:
            raise GestureSimError(
                f"{out.name} {given}: unsupported file type "
                f"{given.suffix or '(no extension)'!r}; use {', '.join(out.extensions)}")
        if out.folder:
            inside = next((f for k, f in ins.items() if isinstance(k, Path)
                           and k != resolved and k.is_relative_to(resolved)), None)
            if inside is not None:
                raise GestureSimError(
                    f"{out.name} {given}: holds the input {inside}; the folder is replaced "
                    "as a whole, which would destroy it (choose another output folder)")
        seen[resolved] = out.name
        if ident is not None:
            seen[ident] = out.name
        _check_folder(out.name, resolved if out.folder else resolved.parent)
        if st is not None and stat.S_ISREG(st.st_mode):
            _check_replaceable(out.name, given, resolved, st)
        result.append(resolved)
        written.append(resolved if out.folder else resolved.parent)
    _remove_stale(written)
    return result


def _remove_stale(folders: Iterable[Path]) -> None:
    """The outputs are good: remove the stale temporaries of dead runs from their (existing)
    folders and from the temp dir (:func:`gesture_sim.fileio.remove_stale_temporaries`)."""
    from gesture_sim.fileio import remove_stale_temporaries

    for folder in {*folders, None}:
        if folder is None or folder.is_dir():
            remove_stale_temporaries(folder)


def _input_files(p: Path, limit: int = 10_000) -> list[Path]:
    """An input path and, for a folder (a library, a model), every file under it (up to
    ``limit``): no output may replace any of them."""
    try:
        if not p.is_dir():
            return [p]
    except OSError:
        return [p]
    out = [p]
    for root, _dirs, files in os.walk(p):
        out.extend(Path(root) / f for f in files)
        if len(out) > limit:
            break
    return out


def inputs_of(args: object, *names: str) -> list[str | os.PathLike[str]]:
    """The input paths a command was given under the argparse ``names`` (attributes that are
    ``None`` are skipped; list-valued ones are flattened): what :func:`check_outputs` protects."""
    out: list[str | os.PathLike[str]] = []
    for n in names:
        val = getattr(args, n, None)
        if val is None:
            continue
        if isinstance(val, (list, tuple)):
            for x in val:
                out.extend(x if isinstance(x, (list, tuple)) else [x])
        else:
            out.append(val)
    return out


def _check_folder(name: str, folder: Path) -> None:
    """The nearest existing ancestor of ``folder`` must be a folder where a file (or, when
    ``folder`` is still to be created, a folder) can be created: tried, with a temporary that
    is removed at once (permissions alone do not tell: root may not write in /proc, a read-only
    or immutable folder refuses everyone)."""
    p = folder
    while not p.exists():
        if p.is_symlink():  # a dangling symlink where a folder is needed
            raise GestureSimError(
                f"cannot create output folder {folder} for {name}: {p} is a broken link")
        if p.parent == p:
            break
        p = p.parent
    if not p.is_dir():
        raise GestureSimError(f"cannot create output folder {folder} for {name}: {p} is a file")
    if not os.access(p, os.W_OK | os.X_OK):
        raise GestureSimError(f"{name}: cannot write to {p}: permission denied")
    flags = _inode_flags(p)
    if flags & (_IMMUTABLE | _APPEND_ONLY):
        raise GestureSimError(
            f"{name}: cannot write to {p}: the folder is "
            f"{'immutable' if flags & _IMMUTABLE else 'append-only'} (chattr)")
    try:
        if p == folder:
            fd, probe = tempfile.mkstemp(prefix=_owned(".tmp-probe-"), dir=p)
            os.close(fd)
            os.unlink(probe)
        else:
            os.rmdir(tempfile.mkdtemp(prefix=_owned(".tmp-probe-"), dir=p))
    except OSError as exc:
        raise GestureSimError(
            f"{name}: cannot create files in {p}: {exc.strerror or exc}") from None


def _owned(prefix: str) -> str:
    from gesture_sim.fileio import owned_prefix

    return owned_prefix(prefix)


#: ``FS_IOC_GETFLAGS`` (Linux ``_IOR('f', 1, long)``) and the inode flags that forbid a rename
#: onto the file (or a new file in the folder).
_FS_IOC_GETFLAGS = (2 << 30) | ((8 if sys.maxsize > 2**32 else 4) << 16) | (ord("f") << 8) | 1
_IMMUTABLE = 0x10
_APPEND_ONLY = 0x20


def _inode_flags(path: Path) -> int:
    """The Linux inode flags (``lsattr``) of ``path``; 0 where they cannot be read."""
    if not sys.platform.startswith("linux"):
        return 0
    import fcntl

    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0))
    except OSError:
        return 0
    try:
        buf = bytearray(8)
        fcntl.ioctl(fd, _FS_IOC_GETFLAGS, buf, True)
        return int.from_bytes(buf[:4], sys.byteorder)
    except OSError:
        return 0
    finally:
        os.close(fd)


def _check_replaceable(name: str, given: Path, target: Path, st: os.stat_result) -> None:
    """An existing output file must be one that a rename may replace: not another user's file
    in a sticky folder (/tmp), not immutable or append-only."""
    folder = target.parent
    with contextlib.suppress(OSError):
        fst = folder.stat()
        euid = os.geteuid() if hasattr(os, "geteuid") else 0
        if fst.st_mode & stat.S_ISVTX and euid != 0 and euid not in (st.st_uid, fst.st_uid):
            raise GestureSimError(
                f"{name} {given}: belongs to another user in the sticky folder {folder}, so it "
                "cannot be replaced; give another path")
    flags = _inode_flags(target)
    if flags & (_IMMUTABLE | _APPEND_ONLY):
        raise GestureSimError(
            f"{name} {given}: is {'immutable' if flags & _IMMUTABLE else 'append-only'} "
            "(chattr), so it cannot be replaced; give another path")
