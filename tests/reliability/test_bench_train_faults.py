"""``bench train``'s process and file faults (issue 49): its per-length worker ends with the
main process however that ends (SIGKILL included), a worker's failure and a Ctrl-C are one
line, ``--pair`` is checked as ``train`` checks it, and ``--figure`` is checked before any
work and written atomically."""

from __future__ import annotations

import argparse
import errno
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from gesture_sim.commands.bench import train as bt
from gesture_sim.errors import GestureSimError
from gesture_sim.testing.processes import tagged_processes

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
MOTION = DATA / "motion" / "2_scott_0_1_1_first10s.npz"
AUDIO = DATA / "eval" / "2_scott_0_1_1_first10s.wav"
SHORT = DATA / "audio" / "arctic_a0007.wav"          # about 3 s of speech
TAG = "GESTURE_SIM_FAULTS_TAG"


def _env(tag: str) -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT), MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl",
                **{TAG: tag})


def _cli(*args: str, tmp: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gesture_sim.cli", "bench", "train", *args],
                          capture_output=True, text=True, cwd=tmp, env=_env("x"), timeout=120)


def _one_line_error(proc: subprocess.CompletedProcess) -> str:
    err = proc.stderr.strip()
    assert proc.returncode == 2, err
    assert "Traceback" not in err, err
    assert len(err.splitlines()) == 1 and err.startswith("gesture-sim: error: "), err
    return err


def _start(tmp: Path, tag: str, new_session: bool = False) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "gesture_sim.cli", "bench", "train", "--pair", str(MOTION),
           str(AUDIO), "--minutes", "5"]
    return subprocess.Popen(cmd, env=_env(tag), cwd=tmp, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=new_session)


def _worker_running(tag: str, proc: subprocess.Popen, timeout: float = 120.0) -> int:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        workers = [p for p, c in tagged_processes(TAG, tag).items() if "--worker" in c]
        if workers:
            return workers[0]
        assert proc.poll() is None, proc.communicate()[1][-2000:]
        time.sleep(0.05)
    raise AssertionError("the worker never started")


def _gone_soon(tag: str, timeout: float = 15.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if not tagged_processes(TAG, tag):
            return True
        time.sleep(0.1)
    return False


def test_sigkill_of_the_main_process_ends_the_worker(tmp_path: Path) -> None:
    tag = uuid.uuid4().hex
    proc = _start(tmp_path, tag)
    try:
        _worker_running(tag, proc)
        proc.kill()
        proc.communicate(timeout=30)
        assert _gone_soon(tag), f"the worker outlived its parent: {tagged_processes(TAG, tag)}"
    finally:
        for pid in tagged_processes(TAG, tag):
            os.kill(pid, signal.SIGKILL)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_or_term_is_one_line_and_ends_the_worker(tmp_path: Path, signum: int) -> None:
    """Ctrl-C reaches the whole process group of the terminal; TERM the main process."""
    tag = uuid.uuid4().hex
    proc = _start(tmp_path, tag, new_session=True)
    try:
        _worker_running(tag, proc)
        time.sleep(0.5)
        if signum == signal.SIGINT:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)
        _out, err = proc.communicate(timeout=60)
        assert proc.returncode == 128 + signum, err
        assert "Traceback" not in err, err
        assert err.strip().splitlines()[-1].startswith("gesture-sim: interrupted"), err
        assert _gone_soon(tag), "the worker outlived the interrupted run"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        for pid in tagged_processes(TAG, tag):
            os.kill(pid, signal.SIGKILL)


def test_bad_pairs_are_refused_before_any_work(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(os.urandom(3000))
    text = tmp_path / "speech.wav"
    text.write_text("not audio at all\n")
    for pair in ((garbage, AUDIO), (MOTION, text)):
        err = _one_line_error(_cli("--pair", str(pair[0]), str(pair[1]), "--minutes", "0.25",
                                   tmp=tmp_path))
        assert ("garbage.npz" in err) if pair[0] == garbage else ("speech.wav" in err), err
    # 10 s of motion with 3 s of speech: refused as `train` refuses it
    err = _one_line_error(_cli("--pair", str(MOTION), str(SHORT), "--minutes", "0.25",
                               tmp=tmp_path))
    assert "a pair must be the motion and speech of the same take" in err, err


def test_a_worker_failure_is_one_line(capfd) -> None:
    """A failure inside the worker (the parent's checks bypassed) comes back as one line."""
    spec = {"pairs": [[str(MOTION), str(DATA / "audio" / "SOURCE.md")]], "minutes": 0.25,
            "states": 3, "decisions": 10, "seed": 0, "threads": 1}
    with pytest.raises(GestureSimError, match="the run at 0.25 min failed: ") as err:
        bt._in_subprocess(spec)
    assert "\n" not in str(err.value)
    assert "Traceback" not in capfd.readouterr().err


@pytest.mark.parametrize("figure", ["folder", "missing/sub/x.jpg", "x.svg", "/dev/full",
                                    "input"])
def test_a_bad_figure_is_refused_before_any_work(tmp_path: Path, figure: str) -> None:
    (tmp_path / "folder").mkdir()
    path = str(AUDIO) if figure == "input" else figure
    err = _one_line_error(_cli("--pair", str(MOTION), str(AUDIO), "--minutes", "0.25",
                               "--figure", path, tmp=tmp_path))
    assert "--figure" in err, err
    assert not (tmp_path / "missing").exists()


def test_a_full_disk_leaves_the_previous_figure(tmp_path: Path, monkeypatch) -> None:
    old = tmp_path / "fig.png"
    old.write_bytes(b"my previous figure")
    row = {"corpus_s": 15.0, "total_s": 1.0,
           "stages": {s: {"seconds": 1.0, "cpu_seconds": 1.0, "peak_mb": 1.0}
                      for s in bt.STAGES}}
    monkeypatch.setattr(bt, "check_inputs", lambda pairs: None)
    monkeypatch.setattr(bt, "_measure_with_bar", lambda spec: dict(row, minutes=0.25))

    def full_disk(result: dict, path: str) -> None:
        Path(path).write_bytes(b"\x89PNG trunc")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(bt, "draw_figure", full_disk)
    args = argparse.Namespace(pair=[[str(MOTION), str(AUDIO)]], minutes=[0.25], states=3,
                              decisions=10, seed=0, threads=1, in_process=True,
                              figure=str(old), json=True)
    with pytest.raises(GestureSimError, match="No space left"):
        bt.run(args)
    assert old.read_bytes() == b"my previous figure"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png"]
