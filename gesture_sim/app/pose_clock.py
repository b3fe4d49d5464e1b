"""The pose stream on its own clock: `live --stream` sends at a fixed rate, not at the viewer's.

:class:`ClockedStream` wraps a pose sender (:class:`gesture_sim.export.vmc.VmcSender`,
:class:`gesture_sim.export.json_stream.JsonSender`, or anything with ``send(model, qpos, t)``
that never blocks nor raises, and ``stats()``). The live loop *publishes* the simulated state
after each physics advance (:meth:`ClockedStream.publish`: a copy of ``qpos`` and the
simulation time, a few microseconds under a lock); a thread of its own wakes on a fixed
schedule (``rate_hz``, 60 Hz by default: ``live --stream-rate``) and sends the latest published
state, stamped with its simulation time (VMC ``/VMC/Ext/T``, JSON ``t``). The sending rate is
therefore the clock's, not the viewer's: a window that draws 13 frames a second under software
GL still gives the receiver 60 frames a second (the pose between two of the loop's frames is
repeated, its time unchanged; with ``live --headless`` the loop runs at its full rate).

Where the OS forks (Linux, macOS) the sender runs in a **forked child process** (``mode=
"process"``), not a thread: a thread of the loop's process waits for the interpreter lock
behind the loop's physics and the speech analysis (measured: 48 Hz sent, gaps up to 136 ms
on the loaded 2-core machine), a process of its own is scheduled by the OS alone. The state
crosses in shared memory (an anonymous shared mapping made before the fork) under a sequence
lock: :meth:`ClockedStream.publish` writes the sequence number odd, the time and ``qpos``, then
even; the child copies and checks the number (a publish under way: it sends the previous copy,
never spinning on the publisher). The child ignores Ctrl-C (the parent stops it), leaves by
``os._exit`` when told to stop or when its parent is gone, and hands its figures back through a
pipe. It starts a session of its own (on Linux with scheduler autogroups, its own scheduling
group, so that the loop's own work and a busy process started in the loop's session do not
share its slice) and, where the OS allows it (root or ``CAP_SYS_NICE``), raises its priority to
niceness :data:`CHILD_NICE` (a frame is ~1 ms of work every 16.7 ms); elsewhere it keeps the
parent's. ``mode="thread"`` runs the same schedule on a thread.

The schedule is absolute (tick ``k`` is due at ``start + k / rate_hz``): a late tick does not
shift the ones after it; when the thread is more than one period late (a stall of the whole
process) the missed ticks are skipped, counted, rather than sent in a burst.

Figures (:meth:`ClockedStream.stats`, the live statistics' ``stream``): the sender's own
(frames sent and dropped, bytes, ms per frame, the last error) plus ``rate_hz`` (asked),
``sent_rate_hz`` (frames that went out per second of the stream's run), ``gap_max_ms`` and
``gap_p99_ms`` (the largest and 99th-percentile wall time between two consecutive frames that
went out), ``ticks_skipped``, ``frames_repeated`` (frames whose pose had not advanced since the
previous one) and ``sim_t_backwards`` (frames whose simulation time went back: only after a
reset).

When every frame fails (an address the system refuses every datagram to: a broadcast address,
no route), :attr:`ClockedStream.failed` turns true once ``fail_after_s`` has passed since the
first try without one frame going out, so that the live loop can stop and say so instead of
running on silently.
"""

from __future__ import annotations

import contextlib
import gc
import mmap
import os
import signal
import threading
import time
import warnings
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np

from gesture_sim.app.live_stats import RunningWindow
from gesture_sim.errors import GestureSimError

#: The stream's default rate (Hz): ``live --stream-rate``.
DEFAULT_RATE_HZ = 60.0
#: Highest rate accepted (Hz); a frame costs ~0.5-2.5 ms, so 1000 Hz would be a core's work.
MAX_RATE_HZ = 500.0
#: Wall intervals kept for the gap percentiles (10 min at 60 Hz).
GAP_WINDOW = 36_000
#: The sending child's niceness where the OS allows a raise (root or CAP_SYS_NICE; otherwise
#: it keeps the parent's): it sleeps all but ~1 ms of each frame, and on a loaded machine its
#: wake-ups come first.
CHILD_NICE = -10
#: Tries at a consistent copy of the published state before a frame sends the previous one.
TAKE_TRIES = 3
#: Seconds the parent waits for the child's figures when it stops it.
STOP_TIMEOUT_S = 5.0

# the shared block (float64 slots): the sequence number, the pose's time, the stop flag, the
# frames that went out, the first try's wall time (0: none yet), then qpos (nq,)
_SEQ, _T, _STOP, _OK, _FIRST, _HEAD = 0, 1, 2, 3, 4, 8


def _own_scheduling() -> None:
    """The sending child's place with the scheduler: a session of its own (on Linux with
    autogroups, its own scheduling group: the busy processes of the loop's session, a busy
    loop started beside it, no longer share its slice) and, where the OS lets it (root or
    ``CAP_SYS_NICE``), niceness :data:`CHILD_NICE` for the process and its group. Each step
    that the OS refuses is left out."""
    with contextlib.suppress(OSError, AttributeError):
        os.setsid()
    with contextlib.suppress(OSError, AttributeError):
        os.setpriority(os.PRIO_PROCESS, 0, CHILD_NICE)
    with contextlib.suppress(OSError):
        with open("/proc/self/autogroup", "w") as f:         # Linux autogroups only
            f.write(str(CHILD_NICE))


class _Figures:
    """What the sending schedule counts (in the thread or the child)."""

    def __init__(self) -> None:
        self.gaps = RunningWindow(GAP_WINDOW)
        self.ticks = 0
        self.ticks_skipped = 0
        self.frames_ok = 0
        self.frames_repeated = 0
        self.sim_t_backwards = 0
        self.started_at: float | None = None
        self.ended_at: float | None = None
        self.error = ""

    def to_dict(self, now: float) -> dict[str, Any]:
        run_s = 0.0
        if self.started_at is not None:
            end = self.ended_at if self.ended_at is not None else now
            run_s = max(end - self.started_at, 0.0)
        n = self.gaps.count
        out = {
            "run_s": round(run_s, 3),
            "sent_rate_hz": round(self.frames_ok / run_s, 2) if run_s > 0 else 0.0,
            "gap_max_ms": round(1e3 * self.gaps.max, 2) if n else 0.0,
            "gap_p99_ms": round(1e3 * self.gaps.pct(99), 2) if n else 0.0,
            "gap_mean_ms": round(1e3 * self.gaps.mean, 2) if n else 0.0,
            "ticks": self.ticks,
            "ticks_skipped": self.ticks_skipped,
            "frames_repeated": self.frames_repeated,
            "sim_t_backwards": self.sim_t_backwards,
        }
        if self.error:
            out["stream_error"] = self.error
        return out


class ClockedStream:
    """Sends the latest published pose at a fixed rate on its own clock (module docstring).

    Args:
        sender: the pose sender (``send(model, qpos, t) -> bool``, ``stats()``; ``prepare
            (model)`` and ``close()`` where it has them; ``address`` for the messages).
        rate_hz: frames a second (0 < rate <= :data:`MAX_RATE_HZ`).
        fail_after_s: when not one frame has gone out this long (s) after the first try,
            :attr:`failed` turns true.
        mode: ``"process"`` (a forked child; the default where the OS forks) or
            ``"thread"``.
        clock: the wall clock (s; ``time.perf_counter``, monotonic and shared by the
            processes), replaceable in tests of the thread mode.

    Call :meth:`start` with the model and data, :meth:`publish` after each physics advance,
    and :meth:`stop` at the end (idempotent; :meth:`close` also closes the sender).
    """

    def __init__(self, sender: Any, rate_hz: float = DEFAULT_RATE_HZ,
                 fail_after_s: float = 1.0, mode: str | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        rate_hz = float(rate_hz)
        if not (np.isfinite(rate_hz) and 0.0 < rate_hz <= MAX_RATE_HZ):
            raise GestureSimError(f"stream rate must be in (0, {MAX_RATE_HZ:g}] Hz, got "
                                  f"{rate_hz:g}")
        if mode is None:
            mode = "process" if hasattr(os, "fork") else "thread"
        if mode not in ("process", "thread"):
            raise GestureSimError(f"stream mode must be 'process' or 'thread', got {mode!r}")
        self.sender = sender
        self.rate_hz = rate_hz
        self.period = 1.0 / rate_hz
        self.fail_after_s = float(fail_after_s)
        self.mode = mode
        self.clock = clock
        self.address = getattr(sender, "address", "")
        self._map: mmap.mmap | None = None
        self._buf: np.ndarray | None = None
        self._model: mujoco.MjModel | None = None
        self._thread: threading.Thread | None = None
        self._pid: int | None = None
        self._conn: Any = None
        self._figures = _Figures()          # the thread's, or the child's once handed back
        self._child_stats: dict[str, Any] | None = None
        self.running = False

    # ------------------------------------------------------------------ the loop's side
    def prepare(self, model: mujoco.MjModel) -> None:
        """The sender's set-up for ``model`` (its rig calibration), before the first frame
        (and before the fork: the child inherits it)."""
        prep = getattr(self.sender, "prepare", None)
        if prep is not None:
            prep(model)

    def publish(self, data: mujoco.MjData) -> None:
        """The state the next frames send: ``data.qpos`` (nq,) at ``data.time`` (s), copied
        into the shared block under the sequence lock (microseconds); after each physics
        advance. Before :meth:`start`: nothing."""
        buf = self._buf
        if buf is None:
            return
        buf[_SEQ] += 1.0                  # odd: being written
        buf[_HEAD:] = data.qpos
        buf[_T] = data.time
        buf[_SEQ] += 1.0                  # even: consistent

    def start(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Publish ``data``'s state and start sending (a child process or a thread)."""
        if self.running:
            return
        self._model = model
        nq = int(model.nq)
        self._map = mmap.mmap(-1, 8 * (_HEAD + nq))           # anonymous, shared on fork
        self._buf = np.frombuffer(self._map, dtype=np.float64)
        self.publish(data)
        self.running = True
        if self.mode == "thread":
            self._thread = threading.Thread(target=self._run_thread,
                                            name="gesture-sim-pose-stream", daemon=True)
            self._thread.start()
            return
        import multiprocessing.connection as mpc

        parent, child = mpc.Pipe()
        parent_pid = os.getpid()
        with warnings.catch_warnings():
            # Python >= 3.12 warns on fork() with threads; the child runs only the sender
            # (numpy, MuJoCo's kinematics, its socket and its pipe) and leaves by os._exit
            warnings.filterwarnings("ignore", category=DeprecationWarning, message=".*fork")
            pid = os.fork()
        if pid == 0:                                           # the child: never returns
            parent.close()
            self._child_main(child, parent_pid)
        child.close()
        self._pid, self._conn = pid, parent

    @property
    def failed(self) -> bool:
        """True when not one frame has gone out ``fail_after_s`` after the first try."""
        buf = self._buf
        if buf is None or buf[_FIRST] == 0.0 or buf[_OK] > 0:
            return False
        return self.clock() - float(buf[_FIRST]) >= self.fail_after_s

    def stop(self) -> None:
        """Stop sending: the thread joined, or the child told to stop and its figures taken
        (killed after :data:`STOP_TIMEOUT_S`); idempotent."""
        if not self.running:
            return
        self.running = False
        assert self._buf is not None
        self._buf[_STOP] = 1.0
        if self._thread is not None:
            self._thread.join(timeout=STOP_TIMEOUT_S)
            self._thread = None
            return
        stats: dict[str, Any] | None = None
        try:
            if self._conn.poll(STOP_TIMEOUT_S):
                stats = self._conn.recv()
        except (OSError, EOFError):
            stats = None
        finally:
            self._conn.close()
            self._end_child(kill=stats is None)
        self._child_stats = stats if isinstance(stats, dict) else {
            "stream_error": "the stream process ended without its figures"}

    def _end_child(self, kill: bool) -> None:
        pid, self._pid = self._pid, None
        if pid is None:
            return
        if kill:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(pid, 0)

    def close(self) -> None:
        """Stop and close the sender's socket."""
        self.stop()
        close = getattr(self.sender, "close", None)
        if close is not None:
            close()

    # ------------------------------------------------------------------ the sending side
    def _run_thread(self) -> None:
        try:
            self._schedule(self._figures, lambda: True)
        except Exception as exc:  # noqa: BLE001 - reported in the stats, never a dead loop
            self._figures.error = f"{type(exc).__name__}: {exc}"

    def _child_main(self, conn: Any, parent_pid: int) -> None:
        """The child process: the schedule until told to stop or orphaned, then its figures
        (and the sender's) to the parent; leaves by ``os._exit``, running none of the
        parent's exit handlers."""
        code = 0
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)   # the parent decides; it stops us
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            gc.freeze()                                     # the inherited heap: never scanned
            _own_scheduling()
            figures = _Figures()
            try:
                self._schedule(figures, lambda: os.getppid() == parent_pid)
            except Exception as exc:  # noqa: BLE001 - reported to the parent
                figures.error = f"{type(exc).__name__}: {exc}"
                code = 1
            with contextlib.suppress(BaseException):
                conn.send({**self.sender.stats(), **figures.to_dict(self.clock())})
        finally:
            os._exit(code)

    def _take(self, out: np.ndarray, scratch: np.ndarray,
              last: tuple[float, float] | None) -> tuple[float, float] | None:
        """Copy the latest published qpos into ``out`` (nq,) and return (its time s, its
        sequence number), when a consistent copy comes within :data:`TAKE_TRIES` tries; else
        ``out`` keeps the previous copy and ``last`` (its time and number) is returned. Never
        waits for the publisher: a sender that spun on a publish under way would, at a higher
        priority, keep the publishing loop from finishing it."""
        buf = self._buf
        assert buf is not None
        for _ in range(TAKE_TRIES):
            seq = float(buf[_SEQ])
            if seq % 2.0 == 0.0:
                scratch[:] = buf[_HEAD:]
                t = float(buf[_T])
                if float(buf[_SEQ]) == seq:
                    out[:] = scratch
                    return t, seq
        return last

    def _schedule(self, fig: _Figures, alive: Callable[[], bool]) -> None:
        """Send on the absolute schedule until the stop flag (or ``alive()`` false)."""
        clock, period, buf = self.clock, self.period, self._buf
        assert buf is not None
        qpos = np.empty(len(buf) - _HEAD)
        scratch = np.empty_like(qpos)
        taken: tuple[float, float] | None = None
        start = clock()
        fig.started_at = start
        due = start
        last_ok: float | None = None
        last_seq = last_t = None
        while buf[_STOP] == 0.0 and alive():
            now = clock()
            if now < due:
                time.sleep(min(due - now, 0.05))
                continue
            if now - due > period:                  # a stall: skip, do not burst
                missed = int((now - due) / period)
                fig.ticks_skipped += missed
                due += missed * period
            due += period
            taken = self._take(qpos, scratch, taken)
            if taken is None:                # nothing consistent yet: the next tick
                continue
            t, seq = taken
            sent_at = clock()
            if buf[_FIRST] == 0.0:
                buf[_FIRST] = sent_at
            fig.ticks += 1
            if not self.sender.send(self._model, qpos, t):
                continue
            fig.frames_ok += 1
            buf[_OK] = fig.frames_ok
            if last_ok is not None:
                fig.gaps.add(sent_at - last_ok)
            last_ok = sent_at
            if seq == last_seq:
                fig.frames_repeated += 1
            if last_t is not None and t < last_t:
                fig.sim_t_backwards += 1
            last_seq, last_t = seq, t
        fig.ended_at = clock()

    # ------------------------------------------------------------------ figures
    def stats(self) -> dict[str, Any]:
        """The sender's figures plus the clock's (module docstring), JSON-ready: from the
        child once it has stopped (its copy of the sender counted the frames)."""
        if self._child_stats is not None:
            out = dict(self._child_stats)
        else:
            out = {**self.sender.stats(), **self._figures.to_dict(self.clock())}
        out.update({"rate_hz": self.rate_hz, "mode": self.mode, "failed": self.failed})
        return out
