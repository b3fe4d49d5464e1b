"""Many files at once: jobs run serially, in a pool of worker processes, or on a Dask cluster.

``gesture-sim render A.wav B.wav ... --jobs N`` and ``gesture-sim eval ... --jobs N`` (and
``--dask ADDRESS``) hand their work to :func:`run_jobs` as a list of :class:`Job` (a picklable
function, its arguments and a label, the input's name, for messages). It returns one
:class:`Outcome` per job **in the order of the jobs**, whatever the order they finished in: the
function's value, or a one-line error. A job that fails never stops the others (unless
``fail_fast``), so a batch reports every failing file and still writes all the others.

Where the jobs run:

* ``n_jobs=1`` and no Dask: one after the other in this process.
* ``n_jobs=N``: N worker processes (:mod:`multiprocessing`'s *spawn* start method: fresh
  interpreters that inherit no GL context, thread or lock from this one), each working one job
  at a time and one core each: BLAS/OpenMP at one thread, software GL (llvmpipe) at its share of
  the CPUs. The workers run in their own sessions, so a terminal's Ctrl-C reaches only this
  process; on the way out (the command line raises ``Interrupted`` for SIGINT and SIGTERM, see
  :mod:`gesture_sim.cli`) every worker is sent SIGTERM, which raises :class:`SystemExit` in it
  so that its ``finally``/``with`` blocks run (its ffmpeg is ended, its temporaries removed),
  and whatever is still alive after :data:`STOP_TIMEOUT_S` is killed with its whole process
  group. A worker whose parent disappears ends itself within a second. A worker that dies (a
  crash in native code) fails only its own job; a new worker takes over the rest.
* ``dask="ADDRESS"``: the jobs are submitted to a :mod:`dask.distributed` scheduler at ADDRESS
  (``tcp://host:8786``), or to a :class:`distributed.LocalCluster` started for the batch with
  ``dask="local"`` (as many single-threaded worker processes as CPUs) or ``"local:N"``. Paths are
  passed as given: a remote cluster's workers must see the same files (a shared file system).
  A local cluster's workers run in their own sessions (:func:`dask_setup`), like the pool's.
  On an interrupt the jobs still running on the workers are aborted (an asynchronous
  :class:`JobAborted` in their threads, so that their cleanup runs) before the futures are
  cancelled and the client (and a local cluster) closed. ``dask[distributed]`` is an optional
  dependency (``pip install 'gesture_sim[dask]'``).

One progress bar counts the finished jobs (:func:`gesture_sim.progress.progress`); the jobs
themselves should be called without their own bars.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import logging
import multiprocessing as mp
import multiprocessing.connection
import os
import signal
import sys
import tempfile
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from gesture_sim import interrupt
from gesture_sim.cpus import software_gl_threads, usable_cpus
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import temp_dir_prefix

__all__ = ["DASK_HINT", "DaskTarget", "Job", "JobAborted", "Outcome", "check_dask",
           "check_jobs", "execute", "run_jobs"]

#: What to install for ``--dask``.
DASK_HINT = "install gesture_sim[dask] (pip install 'gesture_sim[dask]')"
#: Largest ``--jobs`` and ``local:N``.
MAX_JOBS = 64
#: Seconds the workers get to clean up after SIGTERM before they are killed (s).
STOP_TIMEOUT_S = 10.0
#: Thread-count variables set to 1 in every worker (one core per job); a value the user set in
#: the environment is kept.
_ONE_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


@dataclass(frozen=True)
class Job:
    """One unit of work: ``fn(*args, **kwargs)`` in a worker.

    Attributes:
        label: what the job is about (the input file), for progress and error lines.
        fn: a module-level function (it is pickled by reference to reach the worker).
        args, kwargs: its arguments (picklable).
    """

    label: str
    fn: Callable[..., Any]
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)


@dataclass
class Outcome:
    """What one job gave: its ``value``, or ``error``, a one-line message (``None`` on success).

    ``wall_s``: wall-clock seconds of the job in its worker.
    """

    label: str
    value: Any = None
    error: str | None = None
    wall_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.error is None

    def line(self) -> str:
        """The error as one line that names the job (its label first unless the message
        names it already)."""
        message = self.error or ""
        return message if self.label and self.label in message else f"{self.label}: {message}"


class JobAborted(BaseException):
    """Raised asynchronously in a Dask worker's thread to abort a running job (an interrupt of
    the batch). A BaseException, so that no ``except Exception`` in the job swallows it."""


@dataclass(frozen=True)
class DaskTarget:
    """Where ``--dask`` sends the jobs: a scheduler ``address``, or ``local_workers`` worker
    processes of a local cluster started for the batch (``address`` is then ``None``)."""

    address: str | None
    local_workers: int | None = None

    def describe(self) -> str:
        if self.local_workers is not None:
            return f"a local Dask cluster of {self.local_workers} workers"
        return f"the Dask scheduler at {self.address}"


# --------------------------------------------------------------------------------------------
# Checks (before any work: standard library only)
# --------------------------------------------------------------------------------------------


def check_jobs(name: str, value: int) -> int:
    """``--jobs``: an integer from 1 to :data:`MAX_JOBS`."""
    from gesture_sim import validation as v

    return v.integer(name, value, 1, MAX_JOBS, hint=" worker processes")


def dask_available() -> bool:
    """Whether :mod:`distributed` can be imported (without importing it)."""
    if "distributed" in sys.modules:
        return sys.modules["distributed"] is not None
    try:
        return importlib.util.find_spec("distributed") is not None
    except (ImportError, ValueError):
        return False


def check_dask(name: str, address: str) -> DaskTarget:
    """``--dask ADDRESS``: ``local``, ``local:N`` or a scheduler address, with
    :mod:`dask.distributed` installed; GestureSimError (one line) otherwise."""
    from gesture_sim import validation as v

    text = str(address).strip()
    if text == "local" or text.startswith("local:"):
        count = text.partition(":")[2]
        if not count:
            target = DaskTarget(None, min(usable_cpus(), MAX_JOBS))
        else:
            try:
                n = int(count)
            except ValueError:
                raise GestureSimError(
                    f"{name} {text}: local:N needs a number of worker processes, such as "
                    "local:4") from None
            target = DaskTarget(None, v.integer(f"{name} local:N", n, 1, MAX_JOBS,
                                                hint=" worker processes"))
    elif not text or any(c.isspace() for c in text):
        raise GestureSimError(
            f"{name} must be local, local:N (N worker processes on this machine) or a "
            f"scheduler address such as tcp://host:8786; got {address!r}")
    else:
        target = DaskTarget(text)
    if not dask_available():
        raise GestureSimError(f"{name}: dask.distributed is not installed; {DASK_HINT}")
    return target


# --------------------------------------------------------------------------------------------
# Running one job (in whichever process or thread runs it)
# --------------------------------------------------------------------------------------------

#: thread id -> batch token of the jobs running in this process (for :func:`_abort_running`).
_RUNNING: dict[int, str] = {}
_RUNNING_LOCK = threading.Lock()


def one_line(exc: BaseException) -> str:
    """An exception as one line: a GestureSimError's message, else ``Type: message``."""
    text = " ".join(str(exc).split())
    if isinstance(exc, GestureSimError):
        return text or "error"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def execute(job: Job, token: str = "") -> Outcome:
    """Run ``job`` here; an exception becomes the outcome's one-line error.

    KeyboardInterrupt and SystemExit (an interrupt of this process) pass through, after the
    job's own cleanup; :class:`JobAborted` (a Dask job aborted by the batch) becomes the error
    ``interrupted``.
    """
    t0 = time.perf_counter()
    ident = threading.get_ident()
    with _RUNNING_LOCK:
        _RUNNING[ident] = token
    try:
        try:
            value = job.fn(*job.args, **job.kwargs)
        finally:
            with _RUNNING_LOCK:
                _RUNNING.pop(ident, None)
    except JobAborted:
        return Outcome(job.label, error="interrupted", wall_s=time.perf_counter() - t0)
    except Exception as exc:  # noqa: BLE001 - one job's failure is data for the batch
        return Outcome(job.label, error=one_line(exc), wall_s=time.perf_counter() - t0)
    return Outcome(job.label, value=value, wall_s=time.perf_counter() - t0)


# --------------------------------------------------------------------------------------------
# The batch
# --------------------------------------------------------------------------------------------


def run_jobs(
    jobs: Sequence[Job], *, n_jobs: int = 1, dask: DaskTarget | str | None = None,
    desc: str = "batch", unit: str = "file", show_progress: bool = True,
    fail_fast: bool = False, on_done: Callable[[int, Outcome], None] | None = None,
) -> list[Outcome]:
    """Run ``jobs`` and return their outcomes in the order of ``jobs``.

    Args:
        jobs: the work; each job's function must be importable by the workers.
        n_jobs: worker processes (1: serially in this process). Ignored with ``dask``.
        dask: a :class:`DaskTarget` or an ``--dask`` address (``local``, ``local:N``, a
            scheduler address).
        desc, unit, show_progress: the one progress bar (finished jobs of the batch).
        fail_fast: stop at the first failing job (the others are abandoned) and raise its
            error as a GestureSimError; otherwise every job runs and failures are outcomes.
        on_done: called in this process with (index, outcome) as each job finishes.

    Raises:
        GestureSimError: ``fail_fast`` and a job failed; Dask not installed or its scheduler
            unreachable.
    """
    from gesture_sim.progress import progress

    jobs = list(jobs)
    if isinstance(dask, str):
        dask = check_dask("dask", dask)
    n_jobs = check_jobs("n_jobs", n_jobs)
    outcomes: list[Outcome | None] = [None] * len(jobs)
    if not jobs:
        return []
    with progress(total=len(jobs), desc=desc, unit=unit, enabled=show_progress) as bar:
        def report(i: int, outcome: Outcome) -> None:
            outcomes[i] = outcome
            bar.update(1)
            bar.set_postfix_str(jobs[i].label[-40:], refresh=False)
            if on_done is not None:
                on_done(i, outcome)
            if fail_fast and not outcome.ok:
                raise GestureSimError(outcome.line())

        if dask is not None:
            _run_dask(jobs, dask, report)
        elif n_jobs == 1 or len(jobs) == 1:
            for i, job in enumerate(jobs):
                report(i, execute(job))
        else:
            _run_pool(jobs, min(n_jobs, len(jobs)), report)
    return [o if o is not None else Outcome(j.label, error="not run")
            for o, j in zip(outcomes, jobs, strict=True)]


# --------------------------------------------------------------------------------------------
# Worker processes
# --------------------------------------------------------------------------------------------


@contextlib.contextmanager
def _worker_environment(n_workers: int) -> Iterator[None]:
    """The environment the workers started inside this block inherit: one BLAS/OpenMP thread,
    the software rasteriser's share of the CPUs (0: in the worker's own thread), and the
    physics in the feed's own thread (:func:`gesture_sim.feed.physics_worker`) unless each
    worker has two cores of its own."""
    wanted = {name: "1" for name in _ONE_THREAD_VARS}
    share = usable_cpus() // max(1, n_workers)
    wanted["LP_NUM_THREADS"] = software_gl_threads(share)
    if share < 2:
        wanted["GESTURE_SIM_PHYSICS_WORKER"] = "off"
    added = [k for k in wanted if k not in os.environ]
    for k in added:
        os.environ[k] = wanted[k]
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def _on_worker_signal(signum: int, frame: object) -> None:
    interrupt.take(signum)
    raise SystemExit(128 + signum)


def _worker_main(conn: mp.connection.Connection, parent_pid: int) -> None:
    """A worker process: receive jobs until ``None`` (or the pipe closes), send outcomes."""
    with contextlib.suppress(OSError):
        os.setsid()   # a terminal's Ctrl-C reaches the parent only; it ends the workers
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _on_worker_signal)
    sys.unraisablehook = interrupt.quiet_dropped(sys.unraisablehook)
    interrupt.watch_parent(parent_pid)   # the batch was killed outright: end too
    try:
        while True:
            try:
                job = conn.recv()
            except (EOFError, OSError):
                return
            if job is None:
                return
            outcome = execute(job)
            interrupt.check()   # signalled during the job: end as the signal would have
            try:
                conn.send(outcome)
            except (OSError, EOFError):
                return
            except Exception as exc:  # noqa: BLE001 - an unpicklable value
                conn.send(Outcome(job.label, wall_s=outcome.wall_s,
                                  error=f"its result cannot be sent back: {one_line(exc)}"))
    except KeyboardInterrupt:
        # a check (a progress update, an atomic output, the line above) found a signal whose
        # SystemExit Python had dropped: exit with the signal's status, no traceback
        if not interrupt.received():
            raise
        raise SystemExit(128 + interrupt.received()) from None


class _Worker:
    """One worker process and its end of the pipe; ``index``: the job it is working on."""

    def __init__(self, ctx: Any) -> None:
        self.conn, child = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_worker_main, args=(child, os.getpid()), daemon=True,
                                name="gesture-sim-batch-worker")
        self.proc.start()
        child.close()
        self.index: int | None = None

    def give(self, index: int, job: Job) -> bool:
        """Send a job; False if the worker is gone."""
        if not self.proc.is_alive():
            return False
        try:
            self.conn.send(job)
        except (OSError, EOFError):
            return False
        self.index = index
        return True

    def receive(self) -> Outcome | None:
        """The outcome sent back, or None when the worker died without one."""
        try:
            if self.conn.poll():
                return self.conn.recv()
        except (EOFError, OSError):
            pass
        return None


def _exit_text(code: int | None) -> str:
    if code is None:
        return "no exit status"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


def _run_pool(jobs: list[Job], n: int, report: Callable[[int, Outcome], None]) -> None:
    """The jobs over ``n`` spawned worker processes (see the module docstring)."""
    ctx = mp.get_context("spawn")
    todo = deque(range(len(jobs)))
    workers: list[_Worker] = []
    graceful = False

    def start() -> _Worker:
        with _worker_environment(n):
            worker = _Worker(ctx)
        workers.append(worker)
        return worker

    def feed(worker: _Worker) -> None:
        while todo:
            i = todo[0]
            if worker.give(i, jobs[i]):
                todo.popleft()
                return
            workers.remove(worker)   # gone before its next job: a fresh one takes it
            _stop([worker], graceful=False)
            worker = start()

    try:
        for _ in range(n):
            start()
        for w in list(workers):
            feed(w)
        while True:
            interrupt.check()   # a signal whose raise was dropped still ends the batch
            busy = [w for w in workers if w.index is not None]
            if not busy:
                break
            waits: list[Any] = [w.conn for w in busy] + [w.proc.sentinel for w in busy]
            ready = set(mp.connection.wait(waits, timeout=1.0))
            for w in busy:
                if w.conn not in ready and w.proc.sentinel not in ready:
                    continue
                i, outcome = w.index, w.receive()
                assert i is not None
                w.index = None
                if outcome is None:   # died with the job
                    w.proc.join(1.0)
                    outcome = Outcome(jobs[i].label, error="the worker process died "
                                      f"({_exit_text(w.proc.exitcode)})")
                    workers.remove(w)
                    _stop([w], graceful=False)
                    if todo:
                        feed(start())
                else:
                    feed(w)
                report(i, outcome)
        graceful = True
    finally:
        _stop(workers, graceful=graceful)


def _stop(workers: list[_Worker], graceful: bool) -> None:
    """End the workers: idle ones are told to exit; otherwise SIGTERM (their cleanup runs),
    then, after :data:`STOP_TIMEOUT_S`, SIGKILL to each one's whole process group."""
    for w in workers:
        if graceful and w.index is None:
            with contextlib.suppress(OSError, EOFError, ValueError):
                w.conn.send(None)
        elif w.proc.pid is not None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(w.proc.pid, signal.SIGTERM)
    deadline = time.monotonic() + STOP_TIMEOUT_S
    for w in workers:
        w.proc.join(max(0.0, deadline - time.monotonic()))
    for w in workers:
        if w.proc.pid is not None and not graceful:
            # the worker leads its own session: this also ends anything it started
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(w.proc.pid, signal.SIGKILL)
        if w.proc.is_alive():
            w.proc.kill()
            w.proc.join()
        with contextlib.suppress(OSError):
            w.conn.close()


# --------------------------------------------------------------------------------------------
# Dask
# --------------------------------------------------------------------------------------------


def dask_setup(worker: object) -> None:
    """Dask preload of the local cluster's worker processes (``preload=[this module]``).

    The worker leaves the batch's session, as the pool's workers do: a terminal's Ctrl-C, or a
    TERM to the process group, reaches the batch only, which aborts the running jobs (their
    cleanup runs: ffmpeg ended, temporaries removed) and then closes the cluster. A worker
    that received the signal itself would die mid-job (temporaries left) or print its
    tracebacks. It ends itself once the batch is gone (killed outright).
    """
    with contextlib.suppress(OSError):
        os.setsid()
    # a job's failure comes back as its outcome; the worker's own complaints while the batch
    # shuts the cluster down (a scheduler gone before the worker) are not the user's business
    for name in ("distributed", "tornado", "asyncio"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    sys.unraisablehook = _abort_again_if_dropped(sys.unraisablehook)
    interrupt.watch_parent(os.getppid())


def _raise_in(ident: int) -> None:
    """Raise :class:`JobAborted` asynchronously in thread ``ident``."""
    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(ident),
                                               ctypes.py_object(JobAborted))


def _abort_again_if_dropped(previous: Callable[[Any], object]) -> Callable[[Any], None]:
    """A ``sys.unraisablehook`` for Dask workers: an asynchronous :class:`JobAborted` that landed
    in a ``__del__`` or a weakref callback (where Python prints and drops it, and the job would
    carry on) is raised again in its job's thread, a moment later, and nothing is printed."""
    def hook(unraisable: Any) -> None:
        if not isinstance(unraisable.exc_value, JobAborted):
            previous(unraisable)
            return
        ident = threading.get_ident()
        with _RUNNING_LOCK:
            running = ident in _RUNNING
        if running:  # from a timer: the hook itself must have returned before it lands
            threading.Timer(0.005, _raise_in, args=(ident,)).start()
    return hook


def _abort_running(token: str, timeout_s: float = STOP_TIMEOUT_S) -> int:
    """On a Dask worker: raise :class:`JobAborted` in the threads running this batch's jobs and
    wait (up to ``timeout_s``) until their cleanup is done. Returns the jobs aborted."""
    with _RUNNING_LOCK:
        idents = [i for i, t in _RUNNING.items() if t == token]
    for ident in idents:
        _raise_in(ident)
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        with _RUNNING_LOCK:
            if not any(t == token for t in _RUNNING.values()):
                break
        time.sleep(0.02)
    return len(idents)


@contextlib.contextmanager
def _quiet_dask() -> Iterator[None]:
    """Dask's own log lines (connections closing at shutdown) only from ERROR up."""
    loggers = [logging.getLogger(n) for n in ("distributed", "tornado", "asyncio")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.ERROR)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def _run_dask(jobs: list[Job], target: DaskTarget,
              report: Callable[[int, Outcome], None]) -> None:
    """The jobs as futures of a :class:`distributed.Client` (see the module docstring)."""
    if not dask_available():
        raise GestureSimError(f"--dask: dask.distributed is not installed; {DASK_HINT}")
    import dask
    import distributed

    token = uuid.uuid4().hex
    cluster = client = None
    futures: list[Any] = []
    with _quiet_dask(), contextlib.ExitStack() as stack:
        try:
            if target.local_workers is not None:
                # the workers' scratch space: removed (after the cluster has closed) on the way out
                scratch = stack.enter_context(
                    tempfile.TemporaryDirectory(prefix=temp_dir_prefix("dask")))
                stack.enter_context(dask.config.set({"temporary-directory": scratch}))
                with _worker_environment(target.local_workers):
                    cluster = distributed.LocalCluster(
                        n_workers=target.local_workers, threads_per_worker=1, processes=True,
                        preload=[__name__],  # dask_setup below: the workers' own session
                        # ":0": a free port for its HTTP server (8787 is taken when two run)
                        dashboard_address=":0", silence_logs=logging.ERROR,
                        local_directory=scratch)
                client = distributed.Client(cluster, set_as_default=False)
            else:
                try:
                    client = distributed.Client(target.address, timeout=30,
                                                set_as_default=False)
                except (OSError, TimeoutError, ValueError) as exc:
                    raise GestureSimError(f"--dask {target.address}: cannot reach the Dask "
                                          f"scheduler ({one_line(exc)})") from None
            futures = [client.submit(execute, job, token, key=f"gesture-sim-{token}-{i}",
                                     pure=False) for i, job in enumerate(jobs)]
            where = {f.key: i for i, f in enumerate(futures)}
            for future in distributed.as_completed(futures, loop=client.loop):
                i = where[future.key]
                if future.status == "finished":
                    outcome = future.result()
                else:
                    exc = future.exception()
                    outcome = Outcome(jobs[i].label, error=f"the Dask job failed: "
                                      f"{one_line(exc) if exc else future.status}")
                future.release()
                report(i, outcome)
        except BaseException:
            if client is not None:
                # cancel first, so that no queued job starts while the running ones are aborted;
                # abort twice, for a job that had started just as the cancel went out
                with contextlib.suppress(Exception):
                    client.cancel(futures, force=True)
                for _ in range(2):
                    with contextlib.suppress(Exception):
                        client.run(_abort_running, token)
            raise
        finally:
            if client is not None:
                with contextlib.suppress(Exception):
                    client.close()
            if cluster is not None:
                with contextlib.suppress(Exception):
                    cluster.close()
