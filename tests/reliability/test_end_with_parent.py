"""A child that calls :func:`gesture_sim.interrupt.end_with_parent` (or only the fallback,
:func:`~gesture_sim.interrupt.watch_parent`) ends when its parent is killed outright
(issue 49)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHILD = ("import os, sys, time\n"
         "from gesture_sim import interrupt\n"
         "getattr(interrupt, sys.argv[1])(os.getppid())\n"
         "print(os.getpid(), flush=True)\n"
         "time.sleep(120)\n")
PARENT = ("import subprocess, sys, time\n"
          "subprocess.Popen([sys.executable, '-c', sys.argv[1], sys.argv[2]])\n"
          "time.sleep(120)\n")


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state in ("Z", "X")


@pytest.mark.parametrize("how", ["end_with_parent", "watch_parent"])
def test_the_child_ends_with_its_killed_parent(how: str) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    parent = subprocess.Popen([sys.executable, "-c", PARENT, CHILD, how], env=env,
                              stdout=subprocess.PIPE, text=True)
    child = None
    try:
        line = parent.stdout.readline() if parent.stdout else ""
        child = int(line)
        assert not _gone(child)
        parent.kill()
        parent.wait()
        end = time.monotonic() + 15
        while not _gone(child) and time.monotonic() < end:
            time.sleep(0.05)
        assert _gone(child), "the child outlived its parent"
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        if child is not None and not _gone(child):
            os.kill(child, signal.SIGKILL)
