"""SIGINT and SIGTERM, sent to the main process only, at any stage of a render: the workers and
ffmpeg end with it, no temporary is left (beside the outputs or in ``$TMPDIR``), the previous
outputs are untouched, and the user sees one line, never a traceback.

Each case starts a real ``gesture-sim render`` of a 4 s recording (320x240, two render workers)
over three existing outputs and signals it at a stage recognised from outside: "simulating" is
before any render worker exists, "rendering" once both workers and their ffmpeg processes run.
The children are found by an environment tag they inherit.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from gesture_sim.testing.processes import tagged_processes

ROOT = Path(__file__).resolve().parents[2]
SPEECH = ROOT / "tests" / "data" / "audio" / "arctic_a0007.wav"
TAG = "GESTURE_SIM_RELIABILITY_TAG"

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("reliability-render")]


def _tagged(tag: str) -> dict[int, str]:
    return tagged_processes(TAG, tag)


def _wait_for(pred, timeout: float, proc: subprocess.Popen) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.05)
    return False


@pytest.fixture
def olds(tmp_path: Path) -> dict[str, bytes]:
    out = tmp_path / "out"
    out.mkdir()
    contents = {"old.mp4": b"my previous video", "old.json": b'{"previous": 1}',
                "old.png": b"my previous figure"}
    for name, data in contents.items():
        (out / name).write_bytes(data)
    return contents


@pytest.mark.parametrize(("stage", "signals"), [
    ("simulating", [signal.SIGTERM]),
    ("simulating", [signal.SIGINT]),
    ("rendering", [signal.SIGTERM]),
    ("rendering", [signal.SIGINT]),
    ("rendering", [signal.SIGINT, signal.SIGINT]),   # two Ctrl-C in quick succession
    ("rendering", [signal.SIGTERM, signal.SIGINT]),
], ids=["sim-term", "sim-int", "render-term", "render-int", "render-int-int",
        "render-term-int"])
def test_signal_leaves_nothing(stage: str, signals: list[int], tmp_path: Path,
                               olds: dict[str, bytes]) -> None:
    out, tmpdir = tmp_path / "out", tmp_path / "tmp"
    tmpdir.mkdir()
    tag = uuid.uuid4().hex
    env = dict(os.environ, TMPDIR=str(tmpdir), MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl",
               PYTHONPATH=str(ROOT), **{TAG: tag})
    cmd = [sys.executable, "-m", "gesture_sim.cli", "render", str(SPEECH),
           "-o", str(out / "old.mp4"), "--metrics", str(out / "old.json"),
           "--timeline", str(out / "old.png"), "--width", "320", "--height", "240",
           "--workers", "2"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tmp_path)
    try:
        if stage == "simulating":
            # the pipeline loads and simulates for several seconds before the first worker
            time.sleep(1.5)
            assert not any("_worker_entry" in c for c in _tagged(tag).values())
        else:
            def rendering() -> bool:
                cmds = list(_tagged(tag).values())
                return (sum("_worker_entry" in c for c in cmds) == 2
                        and sum("ffmpeg" in c and "rawvideo" in c for c in cmds) == 2)
            assert _wait_for(rendering, 240, proc), "the render workers never started"
        assert proc.poll() is None, "the render finished before it could be interrupted"
        for s in signals:
            proc.send_signal(s)   # the main process only, as kill/timeout/systemd do
            time.sleep(0.05)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    where = f"\nstdout: {stdout[-1000:]}\nstderr: {stderr[-3000:]}"
    assert proc.returncode == 128 + int(signals[0]), where
    assert "Traceback" not in stderr, where
    assert stderr.strip().splitlines()[-1].startswith("gesture-sim: interrupted"), where
    # the workers and their ffmpeg processes end with the main process (SIGKILL is immediate,
    # the kernel's teardown is not: allow it a moment)
    end = time.monotonic() + 10
    while _tagged(tag) and time.monotonic() < end:
        time.sleep(0.1)
    assert _tagged(tag) == {}, "orphaned render processes"
    assert sorted(p.name for p in out.iterdir()) == sorted(olds), "temporaries left"
    for name, data in olds.items():
        assert (out / name).read_bytes() == data, f"{name} was replaced"
    assert list(tmpdir.iterdir()) == [], "temporaries left in $TMPDIR"
