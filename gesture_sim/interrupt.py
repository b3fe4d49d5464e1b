"""The one record of a SIGINT/SIGTERM that ended the run, readable by every stage.

The command line's signal handler (:mod:`gesture_sim.cli`) calls :func:`note` and raises
:class:`Interrupted`. Python drops an exception raised where it cannot propagate — a weakref
callback or ``__del__`` that happened to run when the signal arrived (the import system's
module-lock callback, for one) prints "Exception ignored in ..." and carries on — so the raise
alone can be lost and the run would finish as if nothing happened, replacing the user's previous
outputs. :func:`check` raises the interruption again: long loops call it, and every atomic output
calls it before its rename, so a run that was signalled never publishes an output.

A child process of the command line that must not outlive it (a worker killed with its parent
by SIGKILL would run on under init, for minutes) calls :func:`end_with_parent` once at its start.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

#: The signal that ended the run, once one has arrived (0 before).
_received = 0


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (see the module docstring); ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def note(signum: int) -> None:
    """Record that ``signum`` ended the run."""
    global _received
    _received = int(signum)


def take(signum: int) -> None:
    """A signal handler's first step: ignore further SIGINT/SIGTERM (the cleanup that follows
    must not be cut short) and record ``signum`` (kept where a raise would be dropped)."""
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, signal.SIG_IGN)
    note(signum)


def received() -> int:
    """The signal that ended the run, or 0 if none has arrived."""
    return _received


def check() -> None:
    """Raise :class:`Interrupted` if a signal has arrived (even one whose first raise was lost)."""
    if _received:
        raise Interrupted(_received)


def reset() -> None:
    """Forget a recorded signal (for in-process callers that handled it, such as tests)."""
    global _received
    _received = 0


def quiet_dropped(previous_hook: Callable[[Any], object]) -> Callable[[Any], None]:
    """A ``sys.unraisablehook`` that says nothing of the signal's own exception where Python had
    to drop it (a KeyboardInterrupt or SystemExit once a signal is recorded: it is acted on by
    :func:`check`) and passes every other unraisable exception to ``previous_hook``."""
    def hook(unraisable: Any) -> None:   # a sys.UnraisableHookArgs
        if not (_received and isinstance(unraisable.exc_value, KeyboardInterrupt | SystemExit)):
            previous_hook(unraisable)
    return hook


#: Seconds between two looks at the parent by :func:`watch_parent`'s thread.
PARENT_POLL_S = 1.0
#: ``PR_SET_PDEATHSIG`` of Linux's ``prctl(2)``.
_PR_SET_PDEATHSIG = 1


def watch_parent(parent_pid: int, signum: int = signal.SIGTERM) -> None:
    """Send this process ``signum`` once its parent ``parent_pid`` is gone (checked every
    :data:`PARENT_POLL_S` s by a daemon thread: ``os.getppid()`` then names another process)."""
    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os.kill(os.getpid(), signum)

    threading.Thread(target=watch, name="gesture-sim-parent-watch", daemon=True).start()


def end_with_parent(parent_pid: int, signum: int = signal.SIGTERM) -> None:
    """Make this process receive ``signum`` when its parent ``parent_pid`` ends, however it ends
    (SIGKILL included).

    On Linux the kernel sends it (``prctl(PR_SET_PDEATHSIG)``, at once); it is sent at once too
    when the parent is already gone by the time of the call (the race between the fork and this
    call). Everywhere, :func:`watch_parent` is the fallback. Call it from the process's main
    thread, in a child whose parent's forking thread lives as long as the parent (the
    death signal follows the thread that forked the child).
    """
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signum), 0, 0, 0)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os.kill(os.getpid(), signum)
        return
    watch_parent(parent_pid, signum)
