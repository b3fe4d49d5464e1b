"""The one physics stepping loop of the simulation, shared by every humanoid and scene.

Modelled on dm_control's composer environment: one loop of *control updates*; each update
calls an optional ``before_control(t)`` hook, re-samples every body's targets at stream time
``t`` and sets its actuators (:meth:`Body.control`), advances the shared ``MjData`` by
``control_every`` physics steps with one ``mj_step``, records a row per body every
``record_every`` physics steps (when recording), then calls an optional ``after_update(k)``
hook. The timestep divisibility (``record_every`` a multiple of ``control_every``) is checked
once, when the loop is built.

Stream time is simulation time since :meth:`PhysicsLoop.begin` (s). A loop runs either for a
fixed number of updates (:meth:`PhysicsLoop.run_updates`, a whole run) or until a stream time
(:meth:`PhysicsLoop.run_until`, a streamed run fed in increments: its update counter, and so
the record phase, carries over between calls).

A streamed run fed offline (:func:`gesture_sim.feed.feed`) may let the loop *defer* its
:meth:`PhysicsLoop.run_until` calls (:attr:`PhysicsLoop.defer_s`): each call's target streams
are frozen as they are at the call (:meth:`~gesture_sim.sim.targets.RollingTargets.frozen`)
and the calls are run later, in order, once they span ``defer_s`` seconds of stream time or
when anything reads or changes the state (:meth:`PhysicsLoop.flush`). The physics then steps
exactly as it would have at each call (nothing it computes feeds back into the control steps),
but in longer stretches: the audio analysis and the control steps between two stretches no
longer run with caches the physics step has just filled with its own data. With
:meth:`PhysicsLoop.start_background` the stretches run, in the same order, beside the caller on
a second core: in a forked child process that holds a copy of the state and hands it back
(:meth:`PhysicsLoop.export_state`, :meth:`PhysicsLoop.adopt_state`) at the first
:meth:`PhysicsLoop.flush`, or on a thread of this process (``mj_step`` releases the GIL; the
control law's Python shares it with the caller, at most :data:`MAX_AHEAD` stretches behind).
An error there is raised at the flush; a cancelled worker is ended and reaped.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Protocol

import mujoco
import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.sim.targets import RollingTargets

#: A target stream: stream time (s) -> (q*, qd*), each (n_act,).
Sample = Callable[[float], "tuple[np.ndarray, np.ndarray]"]
#: A hook called at the start of every control update with its stream time (s).
BeforeControl = Callable[[float], None]
#: A hook called after every control update (and its row, if any) with the update's index in
#: the current :meth:`PhysicsLoop.run_updates` / :meth:`PhysicsLoop.run_until` call.
AfterUpdate = Callable[[int], None]


class Body(Protocol):
    """What the loop drives: a controlled body on the loop's ``MjData``."""

    def control(self, q_target: np.ndarray, qd_target: np.ndarray) -> None:
        """Set this body's actuators for the next ``control_every`` physics steps from the
        targets q*, qd* (each (n_act,))."""

    def record_row(self, q_target: np.ndarray) -> None:
        """Record one trace row of the current state, with target q* (n_act,)."""


class PhysicsLoop:
    """Control updates of several bodies on one ``MjData``, then one ``mj_step`` per update.

    Args:
        model, data: the compiled scene and the ``MjData`` every body acts on.
        bodies: the controlled bodies, in the order they are sampled, controlled and recorded.
        control_every: physics steps per control update (>= 1).
        record_every: physics steps per recorded row, a multiple of ``control_every``.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, bodies: Sequence[Body],
                 control_every: int, record_every: int) -> None:
        if control_every < 1 or record_every < 1:
            raise GestureSimError("control_every and record_every must be >= 1")
        if record_every % control_every:
            raise GestureSimError("record_every must be a multiple of control_every")
        self.model, self.data = model, data
        self.bodies = list(bodies)
        self.control_every = int(control_every)
        self.record_every = int(record_every)
        self._updates_per_row = self.record_every // self.control_every
        #: Simulation time (s) at which stream time is 0.
        self.t0 = 0.0
        #: Control updates since :meth:`begin`.
        self.updates = 0
        #: Whether rows are recorded.
        self.recording = False
        #: Time the ``mj_step`` calls (thread CPU seconds into :attr:`step_cpu_s`; for
        #: ``bench pipeline``, off by default: two clock reads per update).
        self.timed = False
        #: CPU seconds spent inside ``mj_step`` while :attr:`timed`.
        self.step_cpu_s = 0.0
        #: Stream seconds of :meth:`run_until` calls the loop may defer (module docstring; 0:
        #: every call runs at once). Only calls without hooks whose target streams are
        #: :meth:`RollingTargets.sample` are deferred; any other call runs the pending ones
        #: first.
        self.defer_s = 0.0
        self._pending: list[tuple[float, list[Sample]]] = []
        #: (samples, t, their samples at t) of the latest recorded row (see :meth:`_update`).
        self._recorded: tuple | None = None
        #: Where the deferred stretches run beside the caller (:meth:`start_background`).
        self._worker: _StretchWorker | _StretchProcess | None = None

    @property
    def time(self) -> float:
        """Stream time (s): simulation time since :meth:`begin`."""
        return float(self.data.time) - self.t0

    def begin(self, record: bool = True) -> None:
        """Start a run at the current state: stream time 0, no update yet; rows are recorded
        (every ``record_every`` physics steps) only with ``record``."""
        self.flush()
        self.t0 = float(self.data.time)
        self.updates = 0
        self._recorded = None
        self.recording = record

    def run_updates(self, n: int, samples: Sequence[Sample],
                    before_control: BeforeControl | None = None,
                    after_update: AfterUpdate | None = None) -> None:
        """Run ``n`` control updates; body k tracks ``samples[k]``."""
        self._check(samples)
        self.flush()
        for k in range(n):
            self._update(samples, before_control)
            if after_update is not None:
                after_update(k)

    def run_until(self, t_end: float, samples: Sequence[Sample],
                  before_control: BeforeControl | None = None,
                  after_update: AfterUpdate | None = None) -> int:
        """Run control updates while one more ends at most half an update after stream time
        ``t_end`` (s); body k tracks ``samples[k]``. Returns the number of updates run now
        (with :attr:`defer_s`, those of earlier calls run now included; 0 when deferred)."""
        self._check(samples)
        if self.defer_s > 0.0 and before_control is None and after_update is None:
            pending = self._pending
            if pending and t_end <= pending[-1][0]:
                return 0                 # runs nothing: the loop is already at or past t_end
            frozen = _frozen(samples)
            if frozen is not None:
                pending.append((t_end, frozen))
                if t_end - pending[0][0] < self.defer_s:
                    return 0
                if self._worker is not None:
                    self._pending = []
                    self._worker.submit(pending)
                    return 0
                return self.flush()
        return self.flush() + self._run_until(t_end, samples, before_control, after_update)

    def flush(self) -> int:
        """Run every deferred :meth:`run_until` call, in order (see :attr:`defer_s`); returns
        the number of updates run."""
        n = 0
        worker = self._worker
        if worker is not None:
            try:
                n = worker.wait()
            finally:
                if worker.finished:      # a process hands its state back once, at the end
                    self._worker = None
        while self._pending:
            pending, self._pending = self._pending, []
            n += self._run_stretch(pending)
        return n

    def start_background(self, mode: str = "thread") -> None:
        """Run the deferred stretches (:attr:`defer_s`) beside the caller from now on, the same
        steps in the same order (bit-identical); :meth:`flush` waits for them.

        ``mode="thread"``: on a background thread (``mj_step`` releases the GIL, so it overlaps
        the caller's work on another core; the control law's Python around it shares the GIL
        with the caller). ``mode="process"``: in a forked child process with a copy of the
        state (its own GIL), which hands the state back (:meth:`export_state`) at the first
        :meth:`flush`; from then on the loop steps here again. A process needs ``os.fork`` and
        bodies with ``export_state``/``adopt_state``; without them the thread is used."""
        if self._worker is not None:
            return
        if mode == "process" and hasattr(os, "fork") and all(
                hasattr(b, "export_state") and hasattr(b, "adopt_state") for b in self.bodies):
            self._worker = _StretchProcess(self)
        else:
            self._worker = _StretchWorker(self._run_stretch)

    def export_state(self, updates_run: int) -> dict:
        """What the stretches changed, to hand back from a child process: the ``MjData``, the
        loop's counters and each body's own state (``body.export_state()``)."""
        return {"updates_run": updates_run, "data": self.data, "updates": self.updates,
                "step_cpu_s": self.step_cpu_s,
                "bodies": [b.export_state() for b in self.bodies]}

    def adopt_state(self, state: dict) -> int:
        """Take :meth:`export_state`'s state as this loop's own; returns the updates run."""
        mujoco.mj_copyData(self.data, self.model, state["data"])
        self.updates, self.step_cpu_s = state["updates"], state["step_cpu_s"]
        self._recorded = None
        for body, own in zip(self.bodies, state["bodies"], strict=True):
            body.adopt_state(own)
        return int(state["updates_run"])

    def stop_background(self, cancel: bool = False) -> None:
        """Stop the background thread or process (after what it was given, or at once with
        ``cancel``: then the stretches not yet run are dropped, and a process's state is not
        taken back) and run deferred stretches here again."""
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.stop(cancel)

    def _run_stretch(self, pending: list[tuple[float, list[Sample]]]) -> int:
        """Run deferred calls ``(t_end, samples)`` in order; returns the updates run."""
        n = 0
        for t_end, samples in pending:
            n += self._run_until(t_end, samples, None, None)
        return n

    def _run_until(self, t_end: float, samples: Sequence[Sample],
                   before_control: BeforeControl | None, after_update: AfterUpdate | None
                   ) -> int:
        d = self.data
        dt = self.model.opt.timestep * self.control_every
        k = 0
        while float(d.time) - self.t0 + 0.5 * dt <= t_end:
            self._update(samples, before_control)
            if after_update is not None:
                after_update(k)
            k += 1
        return k

    def settle(self, poses: Sequence[np.ndarray], seconds: float) -> None:
        """Hold body k at ``poses[k]`` (n_act,) with zero velocity, unrecorded, for ``seconds``
        (rounded to physics steps, then down to whole updates); then simulation time restarts
        at 0 and no run is begun (:meth:`begin` with nothing recorded)."""
        zero = np.zeros_like(np.asarray(poses[0], dtype=float))
        n = max(int(round(seconds / self.model.opt.timestep)) // self.control_every, 0)
        self.begin(record=False)
        self.run_updates(n, [lambda _t, q=q: (q, zero) for q in poses])
        self.data.time = 0.0
        self.begin(record=False)

    def _check(self, samples: Sequence[Sample]) -> None:
        if len(samples) != len(self.bodies):
            raise GestureSimError(f"need {len(self.bodies)} target streams, got {len(samples)}")

    def _update(self, samples: Sequence[Sample], before_control: BeforeControl | None) -> None:
        """One control update (see the module docstring)."""
        d = self.data
        t = float(d.time) - self.t0
        if before_control is not None:
            before_control(t)
        recorded = self._recorded
        reuse = recorded is not None and recorded[0] is samples and recorded[1] == t
        for k, (body, sample) in enumerate(zip(self.bodies, samples, strict=True)):
            q, qd = recorded[2][k] if reuse else sample(t)
            body.control(q, qd)
        self._recorded = None
        if self.timed:
            c0 = time.thread_time()
            mujoco.mj_step(self.model, d, self.control_every)
            self.step_cpu_s += time.thread_time() - c0
        else:
            mujoco.mj_step(self.model, d, self.control_every)
        self.updates += 1
        if self.recording and self.updates % self._updates_per_row == 0:
            t = float(d.time) - self.t0
            got = [sample(t) for sample in samples]
            for body, (q, _qd) in zip(self.bodies, got, strict=True):
                body.record_row(q)
            # the next update of the same call samples the same streams at the same time: it
            # takes these where the streams are RollingTargets (whose samples depend on
            # nothing but their pushes and t; any other callable is called again)
            if all(_is_stream(sample) for sample in samples):
                self._recorded = (samples, t, got)


def _is_stream(sample: Sample) -> bool:
    """Whether ``sample`` is a :meth:`RollingTargets.sample`."""
    return isinstance(getattr(sample, "__self__", None), RollingTargets) \
        and getattr(sample, "__func__", None) is RollingTargets.sample


def _frozen(samples: Sequence[Sample]) -> list[Sample] | None:
    """``samples`` as they sample now, whatever is pushed into their streams later: each must be
    a :meth:`RollingTargets.sample` (None otherwise: the call cannot be deferred)."""
    if not all(_is_stream(sample) for sample in samples):
        return None
    return [sample.__self__.frozen().sample for sample in samples]


#: Deferred stretches a background physics thread may have queued or running before the next
#: submission waits for one to finish (:meth:`PhysicsLoop.start_background`; a child process
#: is held back by its pipe's buffer instead).
MAX_AHEAD = 2


#: Seconds the parent waits on a physics child that makes no progress (no CPU time used,
#: Linux; elsewhere: no answer) before it ends the child and fails with one line; the
#: environment variable ``GESTURE_SIM_PHYSICS_TIMEOUT_S`` overrides it.
PHYSICS_TIMEOUT_S = 30.0
#: Environment variable that sets :data:`PHYSICS_TIMEOUT_S`.
TIMEOUT_VARIABLE = "GESTURE_SIM_PHYSICS_TIMEOUT_S"


def physics_timeout_s() -> float:
    """The deadline (s) of a physics child that stops answering (:data:`PHYSICS_TIMEOUT_S`, or
    ``$GESTURE_SIM_PHYSICS_TIMEOUT_S``: a number above 0, at most a day)."""
    raw = os.environ.get(TIMEOUT_VARIABLE)
    if raw is None or not raw.strip():
        return PHYSICS_TIMEOUT_S
    try:
        value = float(raw)
    except ValueError:
        value = float("nan")
    if not (0.0 < value <= 86400.0):
        raise GestureSimError(f"{TIMEOUT_VARIABLE} must be a number of seconds above 0 and at "
                              f"most 86400, got {raw!r}")
    return value


def _cpu_ticks(pid: int) -> int | None:
    """User + system CPU clock ticks of process ``pid`` (Linux ``/proc``), or None."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            fields = fh.read().rsplit(b")", 1)[1].split()
        return int(fields[11]) + int(fields[12])
    except (OSError, IndexError, ValueError):
        return None


class _Watchdog:
    """Ends a physics child that makes no progress while the parent waits on it.

    While the parent is inside :meth:`waiting` (a send the child's full pipe holds back, or a
    receive of its state), a daemon thread looks at the child every ``min(1, timeout / 4)`` s;
    its deadline moves on whenever the child has used CPU time since the last look (Linux;
    elsewhere it is counted from the start of the wait). Past ``timeout_s`` without progress
    (a child stopped by SIGSTOP, or stuck) the child is killed, which ends the parent's wait
    with an error (:attr:`fired` then says why).
    """

    def __init__(self, pid: int, timeout_s: float) -> None:
        self.pid, self.timeout_s = pid, float(timeout_s)
        self.fired = False
        self._since: float | None = None
        self._ticks: int | None = None
        self._lock = threading.Lock()
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    @contextlib.contextmanager
    def waiting(self):
        """The block is a wait on the child (see the class docstring)."""
        with self._lock:
            self._since, self._ticks = time.monotonic(), _cpu_ticks(self.pid)
        if self._thread is None:
            self._thread = threading.Thread(target=self._watch, name="gesture-sim-physics-watch",
                                            daemon=True)
            self._thread.start()
        try:
            yield
        finally:
            with self._lock:
                self._since = None

    def close(self) -> None:
        self._done.set()

    def _watch(self) -> None:
        step = min(1.0, self.timeout_s / 4.0)
        while not self._done.wait(step):
            with self._lock:
                if self._since is None:
                    continue
                ticks = _cpu_ticks(self.pid)
                now = time.monotonic()
                if ticks is not None and ticks != self._ticks:
                    self._since, self._ticks = now, ticks
                    continue
                if now - self._since < self.timeout_s:
                    continue
                self.fired = True
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)
            return

    def error(self) -> GestureSimError:
        return GestureSimError(
            f"the physics process (pid {self.pid}) stopped answering: no progress for "
            f"{self.timeout_s:g} s (stopped or stuck; the deadline is {TIMEOUT_VARIABLE}); it "
            "was ended")


class _StretchProcess:
    """A forked child running deferred stretches in order; it hands the loop's state back
    when :meth:`wait` ends it (see :meth:`PhysicsLoop.start_background`). A child that stops
    answering ends the run within :func:`physics_timeout_s` (:class:`_Watchdog`)."""

    finished = False

    def __init__(self, loop: PhysicsLoop) -> None:
        import multiprocessing.connection as mpc

        self._loop = loop
        timeout_s = physics_timeout_s()
        parent, child = mpc.Pipe()
        with warnings.catch_warnings():
            # Python >= 3.12 warns on fork() in a process with threads; the child runs only
            # the physics (no logging, no I/O but its pipe) and leaves by os._exit
            warnings.filterwarnings("ignore", category=DeprecationWarning, message=".*fork")
            pid = os.fork()
        if pid == 0:                                  # the child: runs stretches, never returns
            parent.close()
            _child_main(loop, child)
        child.close()
        self._conn, self._pid = parent, pid
        self._watchdog = _Watchdog(pid, timeout_s)

    def submit(self, pending: list) -> None:
        try:
            with self._watchdog.waiting():
                self._conn.send(pending)
        except OSError:                               # the child has ended: say why
            self.wait()
            raise GestureSimError("the physics process ended early") from None

    def wait(self) -> int:
        """End the child after what it was given and adopt its state; the updates it ran."""
        if self.finished:
            return 0
        self.finished = True
        try:
            with self._watchdog.waiting():
                try:
                    self._conn.send(None)
                except OSError:
                    pass                              # ended already: its last word is queued
                kind, payload = self._conn.recv()
        except (OSError, EOFError):
            self._end(kill=True)
            if self._watchdog.fired:
                raise self._watchdog.error() from None
            raise GestureSimError("the physics process ended without its state") from None
        self._end(kill=False)
        if kind != "state":
            raise GestureSimError(f"the physics process failed: {payload}")
        return self._loop.adopt_state(payload)

    def stop(self, cancel: bool) -> None:
        if cancel:
            if not self.finished:
                self.finished = True
                self._end(kill=True)
        else:
            self.wait()

    def _end(self, kill: bool) -> None:
        self._watchdog.close()
        self._conn.close()
        if kill:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self._pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(self._pid, 0)


def _child_main(loop: PhysicsLoop, conn) -> None:
    """The child process of :class:`_StretchProcess`: stretches from ``conn`` until ``None``,
    then the loop's state back (or the error); it leaves by ``os._exit``, running none of the
    parent's exit handlers."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)   # the parent decides; it ends the child
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        n = 0
        while True:
            job = conn.recv()
            if job is None:
                break
            n += loop._run_stretch(job)
        conn.send(("state", loop.export_state(n)))
    except BaseException as exc:                        # noqa: BLE001 - reported to the parent
        code = 1
        with contextlib.suppress(BaseException):
            conn.send(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        os._exit(code)


class _StretchWorker:
    """A daemon thread running deferred stretches in the order they are submitted."""

    finished = False

    def __init__(self, run: Callable[[list], int]) -> None:
        self._run = run
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._idle = threading.Condition()
        self._queued = 0
        self._updates = 0
        self._error: BaseException | None = None
        self._cancel = False
        self._thread = threading.Thread(target=self._loop, name="gesture-sim-physics",
                                        daemon=True)
        self._thread.start()

    def submit(self, pending: list) -> None:
        """Queue a stretch; first wait while :data:`MAX_AHEAD` stretches are queued or running
        (the caller, once that far ahead, yields the GIL to the physics instead of competing
        with it)."""
        if self._error is not None:
            self._raise()
        with self._idle:
            while self._queued >= MAX_AHEAD and self._error is None:
                self._idle.wait()
            self._queued += 1
        self._jobs.put(pending)

    def wait(self) -> int:
        """Block until every submitted stretch has run; the updates run since the last wait."""
        with self._idle:
            while self._queued:
                self._idle.wait()
            n, self._updates = self._updates, 0
        self._raise()
        return n

    def stop(self, cancel: bool) -> None:
        self._cancel = cancel
        self._jobs.put(None)
        self._thread.join()
        if not cancel:
            self._raise()

    def _raise(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def _loop(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            n = 0
            if not self._cancel and self._error is None:
                try:
                    n = self._run(job)
                except BaseException as exc:    # handed to the caller at its next wait
                    self._error = exc
            with self._idle:
                self._queued -= 1
                self._updates += n
                self._idle.notify_all()
