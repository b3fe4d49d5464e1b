"""A signal whose raise Python dropped still ends the run, publishes nothing and prints one line.

Python cannot propagate an exception from a weakref callback or ``__del__``: when SIGINT arrives
while one runs (the import system's module-lock callback, during start-up, did so in CI), the
handler's ``Interrupted`` is printed as "Exception ignored" and the program goes on. These tests
reproduce exactly that — the handler called inside a ``__del__`` — and check that the run still
exits 130 with "gesture-sim: interrupted", no traceback, the previous output intact and no
temporary left.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from gesture_sim import interrupt
from gesture_sim.fileio import atomic_outputs, atomic_path
from gesture_sim.progress import progress

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def signalled():
    interrupt.note(signal.SIGTERM)
    try:
        yield
    finally:
        interrupt.reset()


def test_atomic_outputs_publish_nothing_after_a_signal(tmp_path: Path, signalled) -> None:
    old = tmp_path / "out.json"
    old.write_text("previous")
    with pytest.raises(interrupt.Interrupted) as info, atomic_outputs(old) as (tmp,):
        tmp.write_text("new")
    assert info.value.signum == signal.SIGTERM
    assert old.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_atomic_path_publishes_nothing_after_a_signal(tmp_path: Path, signalled) -> None:
    old = tmp_path / "out.txt"
    old.write_text("previous")
    with pytest.raises(interrupt.Interrupted), atomic_path(old) as tmp:
        tmp.write_text("new")
    assert old.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]


def test_long_work_stops_at_its_next_progress_update(signalled) -> None:
    # the bars are disabled here (stderr is not a terminal): the check must not depend on them
    bar = progress(total=10, enabled=False)
    with pytest.raises(interrupt.Interrupted):
        bar.update(1)
    seen = []
    with pytest.raises(interrupt.Interrupted):
        for i in progress(range(10), enabled=True):
            seen.append(i)
    assert seen == []


SCRIPT = textwrap.dedent('''
    import argparse, signal, sys
    from pathlib import Path
    from gesture_sim import cli
    from gesture_sim.fileio import atomic_outputs

    class SignalledDuringCleanup:
        def __del__(self):   # the handler runs here, as it would if the signal came now
            cli._on_signal(signal.SIGINT, None)

    def run(args):
        obj = SignalledDuringCleanup()
        del obj                          # Python drops the handler's Interrupted
        print("carried on", flush=True)  # proof that the raise was dropped
        with atomic_outputs(Path(args.out)) as (tmp,):
            tmp.write_text("new")
        return 0

    def parser():
        p = argparse.ArgumentParser()
        p.add_argument("out")
        p.set_defaults(func=run)
        return p

    cli.build_parser = parser
    sys.exit(cli.main([sys.argv[1]]))
''')


def test_a_dropped_interruption_still_ends_the_command(tmp_path: Path) -> None:
    old = tmp_path / "out.json"
    old.write_text("previous")
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(old)], capture_output=True,
                          text=True, cwd=ROOT, timeout=120)
    where = f"\nstdout: {proc.stdout}\nstderr: {proc.stderr}"
    assert "carried on" in proc.stdout, where
    assert proc.returncode == 128 + signal.SIGINT, where
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, where
    assert proc.stderr.strip().splitlines() == ["gesture-sim: interrupted"], where
    assert old.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


NO_SEMAPHORE = textwrap.dedent('''
    import multiprocessing
    from multiprocessing import resource_tracker
    multiprocessing.set_start_method("spawn", force=True)   # as in a spawned batch worker
    registered = []
    resource_tracker.register = lambda name, rtype: registered.append(rtype)
    from gesture_sim.progress import progress
    bar = progress(total=3, enabled=False)
    bar.update(1)
    bar.close()
    for _ in progress(range(3), enabled=True):
        pass
    print(len(registered))
''')


def test_progress_bars_leave_no_semaphore_to_leak() -> None:
    # tqdm's default lock is a POSIX semaphore in a spawned process: a batch worker killed
    # before its exit handlers left it to the resource tracker ("leaked semaphore" warning)
    proc = subprocess.run([sys.executable, "-c", NO_SEMAPHORE], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "0", proc.stderr


WORKER_SCRIPT = textwrap.dedent('''
    import signal
    from gesture_sim.app import batch
    from gesture_sim.progress import progress

    class SignalledDuringCleanup:
        def __del__(self):   # the worker's handler runs here, as it would if SIGTERM came now
            batch._on_worker_signal(signal.SIGTERM, None)

    def job(k):
        obj = SignalledDuringCleanup()
        del obj                          # Python drops the handler's SystemExit
        print("carried on", flush=True)  # proof that it was dropped
        bar = progress(total=3, enabled=False)
        bar.update(1)                    # long work's next progress update
        return k

    if __name__ == "__main__":
        jobs = [batch.Job(f"job{k}", job, (k,)) for k in range(2)]
        for outcome in batch.run_jobs(jobs, n_jobs=2, show_progress=False):
            print(outcome.label, outcome.value, outcome.error)
''')


def test_a_batch_worker_whose_signal_was_dropped_still_ends(tmp_path: Path) -> None:
    script = tmp_path / "batch_script.py"
    script.write_text(WORKER_SCRIPT)
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          cwd=tmp_path, timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    where = f"\nstdout: {proc.stdout}\nstderr: {proc.stderr}"
    assert proc.returncode == 0, where
    assert proc.stdout.count("carried on") == 2, where
    # each worker ended with its signal's status instead of finishing the job
    assert "job0 None the worker process died (exit code 143)" in proc.stdout, where
    assert "job1 None the worker process died (exit code 143)" in proc.stdout, where
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, where
