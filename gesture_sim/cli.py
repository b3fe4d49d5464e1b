"""The ``gesture-sim`` command line.

Each subcommand lives in its own module under :mod:`gesture_sim.commands` and exposes
``register(subparsers)``; heavy imports happen inside the command's run function so that
``--help`` stays fast; every module of :data:`COMMAND_MODULES` must import. A
:class:`~gesture_sim.errors.GestureSimError` becomes a one-line message and exit status 2. The
model fits a command runs report their convergence problems to
:mod:`gesture_sim.inference.fitlog` instead of printing them; one summary line follows on stderr.

Signals: SIGINT (Ctrl-C) and SIGTERM (``kill``, ``timeout``, systemd, docker) both raise
:class:`Interrupted` in the main thread, so that every ``finally``/``with`` on the way out runs:
render workers and ffmpeg are ended, temporaries removed, previous outputs left intact. While
that cleanup runs, further signals are ignored (a second Ctrl-C cannot cut it short and never
prints a traceback). Exit status 130 after SIGINT, 143 after SIGTERM. Python drops an
exception raised inside a weakref callback or ``__del__``, so the signal is also recorded in
:mod:`gesture_sim.interrupt`, whose check the long loops and every atomic output make again.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import signal
import sys
import warnings
from collections.abc import Callable
from typing import NoReturn

from gesture_sim import __version__, interrupt
from gesture_sim.errors import GestureSimError
from gesture_sim.inference import fitlog
from gesture_sim.interrupt import Interrupted

#: Subcommand modules, in the order ``--help`` lists them.
COMMAND_MODULES = (
    "demo",
    "render",
    "export",
    "live",
    "prosody",
    "words",
    "library",
    "train",
    "listener",
    "eval",
    "bench",
)


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (``gesture-sim render: error: ...
    (see --help)``) and exit status 2, like every other error of the command line; its
    subcommand parsers are of the same class."""

    def error(self, message: str) -> NoReturn:
        msg = " ".join(message.split())
        self.exit(2, f"{self.prog}: error: {msg} (see {self.prog} --help)\n")

    def _get_value(self, action: argparse.Action, arg_string: str) -> object:
        # Path("") is Path("."): an empty path argument (`-o ''`) would become the current
        # folder and be reported as "'.' is not a file name"; refuse it as what it is
        if arg_string == "" and (_is_path_type(action.type) or "--output" in
                                 action.option_strings):
            raise argparse.ArgumentError(action, "'' is not a file name (an empty path)")
        return super()._get_value(action, arg_string)


def _is_path_type(kind: object) -> bool:
    import pathlib

    return isinstance(kind, type) and issubclass(kind, pathlib.PurePath)


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every available subcommand registered."""
    parser = OneLineParser(
        prog="gesture-sim",
        description=(
            "Body language from speech: a MuJoCo humanoid gestures along with a recording or a "
            "live microphone (prosody -> CRF belief -> MDP: which motion; accents -> timing "
            "layer: when; face and head signals; keywords -> semantic gestures -> PD-tracked "
            "physics)."
        ),
    )
    parser.add_argument("--version", action="version", version=f"gesture-sim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        # No fallback: a command module that fails to import is an error (its traceback), never
        # a command silently missing from --help.
        module = importlib.import_module(f"gesture_sim.commands.{name}")
        module.register(sub)
    return parser


__all__ = ["Interrupted", "build_parser", "install_signal_handlers", "main"]


def _on_signal(signum: int, frame: object) -> None:
    # the first signal ends the run; later ones must not interrupt the cleanup it starts
    interrupt.take(signum)
    raise Interrupted(signum)


def install_signal_handlers() -> dict[int, object]:
    """SIGINT and SIGTERM raise :class:`Interrupted` (main thread only); returns the previous
    handlers (empty outside the main thread)."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return {}
    return {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    previous = install_signal_handlers()
    previous_hook = sys.unraisablehook
    sys.unraisablehook = interrupt.quiet_dropped(previous_hook)
    try:
        return _main(argv)
    finally:  # main() called in-process (tests, scripts) leaves the caller's handlers as found
        sys.unraisablehook = previous_hook
        interrupt.reset()   # reported by now; a later in-process main() starts clean
        for s, handler in previous.items():
            if signal.getsignal(s) is _on_signal:  # after a signal they stay ignored to the end
                signal.signal(s, handler)


def _main(argv: list[str] | None) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 1
        from gesture_sim.validation import check_environment

        check_environment()    # a garbage GESTURE_SIM_PHYSICS_WORKER: one line, before any work
        with fitlog.collect() as fits, warnings.catch_warnings():
            # text in a script the fonts lack (a file name such as 日本語.wav in a figure
            # title) would make matplotlib warn once per character and per draw; the titles
            # this package sets are made drawable (gesture_sim.audio.plot.drawable), this
            # keeps any other such text quiet
            warnings.filterwarnings("ignore", message=r"Glyph \d+ .*missing from font",
                                    category=UserWarning)
            # the package's own warnings as one line (restored by catch_warnings)
            previous = warnings.showwarning      # Python's own: every warning one line
            warnings.showwarning = functools.partial(one_line_warning, other=None if (
                previous is getattr(warnings, "_showwarning_orig", None)) else previous)
            result = args.func(args)
        interrupt.check()   # a signal whose raise Python dropped still ends the run as one
        if fits.summary():
            print(f"gesture-sim: note: {fits.summary()}", file=sys.stderr)
    except GestureSimError as exc:
        message = " ".join(str(exc).split("\n")).strip()
        print(f"gesture-sim: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        return _interrupted(getattr(exc, "signum", signal.SIGINT))
    except BrokenPipeError:  # e.g. `gesture-sim ... --json | head`
        return 1
    except Exception:
        # a signal that arrives inside a C call (ctypes during an import, say) surfaces as
        # that call's own error (ctypes.ArgumentError: "Interrupted: SIGINT"): after a signal,
        # any error on the way out is the interruption's
        if interrupt.received():
            return _interrupted(interrupt.received())
        gl = _gl_backend_error()
        if gl is not None:   # mujoco refuses the MUJOCO_GL it was given, on import
            print(f"gesture-sim: error: {gl}", file=sys.stderr)
            return 2
        raise
    return int(result or 0)


def one_line_warning(message: Warning | str, category: type[Warning], filename: str,
                     lineno: int, file: object = None, line: str | None = None, *,
                     other: Callable[..., None] | None = None) -> None:
    """:func:`warnings.showwarning` for the command line: the package's own warnings (the
    ``--text`` aligner's notes, say) as one line ``gesture-sim: warning: MESSAGE`` on stderr,
    never Python's two lines with the source line; another library's go to ``other`` (the
    handler in place before, so a test's warning capture still sees them), or, without one,
    one line with their category and module."""
    import os

    text = " ".join(str(message).split())
    own = os.path.dirname(os.path.abspath(__file__))
    if not os.path.abspath(filename).startswith(own + os.sep):
        if other is not None:
            other(message, category, filename, lineno, file, line)
            return
        module = os.path.splitext(os.path.basename(filename))[0]
        text = f"{category.__name__} in {module}: {text}"
    print(f"gesture-sim: warning: {text}", file=sys.stderr if file is None else file)


#: The MUJOCO_GL values worth suggesting (mujoco accepts a few more spellings of "on"/"off").
GL_BACKENDS = {"egl": "headless, GPU or Mesa", "osmesa": "headless, software",
               "glfw": "a window on a display"}


def _gl_backend_error() -> str | None:
    """The one-line message for the error in flight when it is mujoco's refusal of the
    ``MUJOCO_GL`` environment variable (``RuntimeError: invalid value for environment variable
    MUJOCO_GL: ...``, raised while mujoco is imported), else None."""
    import os

    exc, seen = sys.exc_info()[1], set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, RuntimeError) and "environment variable MUJOCO_GL" in str(exc):
            value = os.environ.get("MUJOCO_GL", "")
            choices = ", ".join(f"{k} ({v})" for k, v in GL_BACKENDS.items())
            return (f"MUJOCO_GL={value!r} is not an OpenGL back-end MuJoCo knows; set "
                    f"MUJOCO_GL to one of {choices}, or unset it")
        exc = exc.__cause__ or exc.__context__
    return None


def _interrupted(signum: int) -> int:
    print("gesture-sim: interrupted" + (" (SIGTERM)" if signum == signal.SIGTERM else ""),
          file=sys.stderr)
    return 128 + int(signum)


if __name__ == "__main__":
    sys.exit(main())
