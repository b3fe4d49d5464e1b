"""Many files at once: ``render A.wav B.wav ... -o DIR`` and ``eval ... --jobs N`` / ``--dask``.

Known answers: a batch of 8 short espeak-ng utterances (1-2 s each, 160x90 at 10 fps, ``fast``
quality, physics on) rendered serially is the reference; the same batch with ``--jobs 2`` and on
a local Dask cluster (``--dask local:2``) must give the same bytes — the mp4 files (x264 is
deterministic for the same frames and settings) and the metrics JSON files (byte-identical for
the same input and seed by design; only the output folder in the paths differs). A damaged file
in the batch costs exactly one error line that names it and exit status 2, and every other file
is still written. Output paths are checked for the whole batch before any work (a name clash
leaves no output folder at all). ``eval --jobs 2`` gives the same rows as the serial run. SIGTERM
in the middle of a ``--jobs 2`` batch leaves no worker, no ffmpeg and no temporary.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from gesture_sim.cli import main
from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.testing.processes import tagged_processes

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("batch")]  # one serial reference

ROOT = Path(__file__).resolve().parents[2]
#: Eight short utterances (one file each) and two longer ones for ``eval`` (>= 2.3 s each).
TEXTS = ("Hello there.", "I went to the market.", "That sounds lovely.", "See you later.",
         "The bakery is new.", "Thank you so much.", "It is near the station.", "Good morning.")
EVAL_TEXTS = (("I went to the market this morning.", "The vegetables were very good."),
              ("That sounds really lovely.", "Did you see the new bakery?"))
#: Small, fast frames (the outputs' identity does not depend on the size).
RENDER = ["--width", "160", "--height", "90", "--fps", "10", "--quality", "fast"]
TAG = "GESTURE_SIM_BATCH_TEST_TAG"


def _write(path: Path, parts: list[np.ndarray], gap_s: float = 0.25) -> Path:
    gap = np.zeros(int(gap_s * SAMPLE_RATE), dtype=np.float32)
    x = np.concatenate([gap] + [p for part in parts for p in (0.5 * part, gap)])
    wavfile.write(path, SAMPLE_RATE, np.round(x * 32767).astype(np.int16))
    return path


@pytest.fixture(scope="module")
def speech(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """The batch: eight 1-2 s recordings ``s0.wav`` .. ``s7.wav``."""
    from gesture_sim.testing.dialogue import say

    folder = tmp_path_factory.mktemp("speech")
    try:
        return [_write(folder / f"s{k}.wav", [say(t)]) for k, t in enumerate(TEXTS)]
    except Exception as exc:  # noqa: BLE001 - no espeak-ng/sox here
        pytest.skip(f"cannot speak the test files: {exc}")


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    rc = main(argv)
    out, err = capsys.readouterr()
    return rc, out, err


def _outputs(folder: Path, names: list[str]) -> dict[str, tuple[bytes, str]]:
    """name -> (mp4 bytes, metrics JSON text with the folder written as ``OUT``)."""
    return {n: ((folder / f"{n}.mp4").read_bytes(),
                (folder / f"{n}.json").read_text(encoding="utf-8").replace(str(folder), "OUT"))
            for n in names}


@pytest.fixture(scope="module")
def serial(speech: list[Path], tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The reference: the batch rendered one file after the other, in this process."""
    out = tmp_path_factory.mktemp("serial")
    rc = main(["render", *map(str, speech), "-o", str(out), "--metrics", str(out), *RENDER])
    assert rc == 0
    return _outputs(out, [p.stem for p in speech])


def test_serial_batch_writes_one_video_and_metrics_file_per_input(serial: dict,
                                                                  speech: list[Path]) -> None:
    assert sorted(serial) == sorted(p.stem for p in speech)
    digests = {hashlib.sha1(video).hexdigest() for video, _ in serial.values()}
    assert len(digests) == len(speech), "every input has its own video"
    for p in speech:
        video, text = serial[p.stem]
        doc = json.loads(text)
        rate, samples = wavfile.read(p)
        assert doc["output"] == f"OUT/{p.stem}.mp4" and doc["metrics"] == f"OUT/{p.stem}.json"
        assert doc["duration_s"] == pytest.approx(len(samples) / rate, abs=0.02)
        assert doc["seed"] == 0 and doc["physics"]["fell"] is False
        assert doc["frames"] == int(np.ceil(doc["duration_s"] * 10 - 1e-9))
        assert video[4:8] == b"ftyp"


def test_jobs_2_same_outputs_and_a_bad_file_costs_one_line(
        serial: dict, speech: list[Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "broken.wav"
    bad.write_bytes(b"RIFF\x24\x00\x00\x00WAVEfmt this is not a recording")
    inputs = [*map(str, speech[:4]), str(bad), *map(str, speech[4:])]
    out = tmp_path / "jobs"
    rc, stdout, stderr = _run(["render", *inputs, "-o", str(out), "--metrics", str(out),
                               "--jobs", "2", *RENDER], capsys)
    where = f"\nstdout: {stdout}\nstderr: {stderr}"
    assert rc == 2, where
    errors = [line for line in stderr.splitlines() if line.startswith("gesture-sim: error:")]
    assert len(errors) == 1 and "broken.wav" in errors[0], where
    assert "Traceback" not in stderr, where
    assert "rendered 8 of 9 files" in stdout and "failed: " + str(bad) in stdout, where
    assert sorted(p.name for p in out.iterdir()) == sorted(
        f"{p.stem}{ext}" for p in speech for ext in (".json", ".mp4")), "outputs or temporaries"
    assert _outputs(out, [p.stem for p in speech]) == serial


def test_dask_local_cluster_same_outputs(serial: dict, speech: list[Path], tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("distributed")
    out = tmp_path / "dask"
    rc, stdout, stderr = _run(["render", *map(str, speech), "-o", str(out), "--metrics",
                               str(out), "--dask", "local:2", *RENDER], capsys)
    assert rc == 0, f"\nstdout: {stdout}\nstderr: {stderr}"
    assert "a local Dask cluster of 2 workers" in stdout
    assert _outputs(out, [p.stem for p in speech]) == serial


def test_every_output_checked_before_any_work(speech: list[Path], tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    other = tmp_path / "other"
    other.mkdir()
    twin = other / speech[0].name            # same stem: both would write OUT/s0.mp4
    twin.write_bytes(speech[0].read_bytes())
    out = tmp_path / "out"
    rc, _, stderr = _run(["render", str(speech[0]), str(speech[1]), str(twin), "-o", str(out),
                          "--jobs", "2", *RENDER], capsys)
    assert rc == 2
    assert "is also the path of" in stderr and str(twin) in stderr, stderr
    assert len(stderr.strip().splitlines()) == 1, stderr
    assert not out.exists(), "work started before the outputs were checked"
    # several inputs: -o is a folder, not a video file
    rc, _, stderr = _run(["render", str(speech[0]), str(speech[1]), "-o",
                          str(tmp_path / "both.mp4")], capsys)
    assert rc == 2 and "this is a folder" in stderr, stderr
    assert not (tmp_path / "both.mp4").exists()


def test_dask_missing_is_one_line(speech: list[Path], tmp_path: Path,
                                  monkeypatch: pytest.MonkeyPatch,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)   # as if not installed
    for argv in (["render", str(speech[0]), str(speech[1]), "-o", str(tmp_path / "o")],
                 ["eval", str(speech[0]), "--seeds", "1"]):
        rc, stdout, stderr = _run([*argv, "--dask", "local:2"], capsys)
        assert rc == 2 and stdout == ""
        assert stderr.count("\n") == 1 and "install gesture_sim[dask]" in stderr, stderr
    rc, _, stderr = _run(["render", str(speech[0]), "-o", str(tmp_path / "o.mp4"),
                          "--jobs", "0"], capsys)
    assert rc == 2 and "--jobs must be an integer from 1 to 64" in stderr, stderr


def test_eval_jobs_2_equals_serial(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from gesture_sim.testing.dialogue import say

    audio = [str(_write(tmp_path / f"e{k}.wav", [say(a), say(b)], gap_s=0.3))
             for k, (a, b) in enumerate(EVAL_TEXTS)]
    args = ["eval", *audio, "--methods", "controller", "mismatched", "--seeds", "1", "--json"]
    reports = []
    for extra in ([], ["--jobs", "2"]):
        rc, stdout, stderr = _run([*args, *extra], capsys)
        assert rc == 0, stderr
        reports.append(json.loads(stdout))

    def rows(report: dict) -> list:
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in report["rows"]]

    serial_rows, parallel_rows = rows(reports[0]), rows(reports[1])
    assert [(r["audio"], r["method"]) for r in serial_rows] == [
        ("e0", "controller"), ("e1", "controller"), ("e0", "mismatched"), ("e1", "mismatched")]
    assert np.isfinite(serial_rows[0]["metrics"]["fgd"])
    assert serial_rows[0]["metrics"] != serial_rows[1]["metrics"]   # the files differ
    assert parallel_rows == serial_rows
    assert reports[1]["summary"] == reports[0]["summary"]


# ------------------------------------------------------------------------------------------
# Interrupts
# ------------------------------------------------------------------------------------------


def _tagged(tag: str) -> dict[int, str]:
    return tagged_processes(TAG, tag)


def _interrupt_render(speech: list[Path], tmp_path: Path, batch: list[str],
                      sig: signal.Signals, group: bool
                      ) -> tuple[int, str, str, Path, Path, str]:
    """Render four files with ``batch`` options (``--jobs 2``, ``--dask local:2``), send ``sig``
    once a worker encodes a video — to the main process, or to its whole process group — and
    wait for the end. Returns (exit status, stderr, a note of both streams for assertion
    messages, output folder, $TMPDIR, the process tag)."""
    out, tmpdir = tmp_path / "out", tmp_path / "tmp"
    tmpdir.mkdir()
    tag = uuid.uuid4().hex
    env = dict(os.environ, TMPDIR=str(tmpdir), MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl",
               PYTHONPATH=str(ROOT), **{TAG: tag})
    cmd = [sys.executable, "-m", "gesture_sim.cli", "render", *map(str, speech[:4]), "-o",
           str(out), "--metrics", str(out), *batch, *RENDER]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tmp_path, start_new_session=group)
    try:
        end = time.monotonic() + 120
        while time.monotonic() < end and proc.poll() is None:   # a worker encodes a video
            if any("ffmpeg" in c and "rawvideo" in c for c in _tagged(tag).values()):
                break
            time.sleep(0.02)
        assert proc.poll() is None, "the batch ended before it could be interrupted"
        if group:   # the whole group, as a terminal's Ctrl-C or `kill -- -PGID` does
            os.killpg(proc.pid, sig)
        else:       # the main process only, as kill/timeout/systemd do
            proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            if group:
                os.killpg(proc.pid, signal.SIGKILL)
            else:
                proc.kill()
            proc.communicate()
    end = time.monotonic() + 15
    while _tagged(tag) and time.monotonic() < end:
        time.sleep(0.1)
    where = f"\nstdout: {stdout[-1000:]}\nstderr: {stderr[-3000:]}"
    return proc.returncode, stderr, where, out, tmpdir, tag


def test_sigterm_mid_batch_leaves_no_worker_and_no_temporary(speech: list[Path],
                                                             tmp_path: Path) -> None:
    rc, err, where, out, tmpdir, tag = _interrupt_render(speech, tmp_path, ["--jobs", "2"],
                                                         signal.SIGTERM, group=False)
    assert rc == 128 + signal.SIGTERM, where
    assert "Traceback" not in err, where
    assert err.strip().splitlines()[-1] == "gesture-sim: interrupted (SIGTERM)", where
    assert _tagged(tag) == {}, "orphaned workers"
    names = sorted(p.name for p in out.iterdir()) if out.exists() else []
    assert not [n for n in names if n.startswith(".tmp")], names
    assert len(names) < 8 and len(names) % 2 == 0, names   # whole files only, not all of them
    assert list(tmpdir.iterdir()) == [], "temporaries left in $TMPDIR"


@pytest.mark.skipif(importlib.util.find_spec("distributed") is None, reason="needs dask")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_to_the_group_with_dask_leaves_nothing_and_one_line(
        speech: list[Path], tmp_path: Path, sig: signal.Signals) -> None:
    """Sweep defects 5 and 7: TERM (or a terminal's Ctrl-C) to the whole process group of a
    ``--dask local:2`` render reached the cluster's workers too; they died mid-job (``.tmp-*``
    in the output folder, ``gesture-sim-video-*`` in $TMPDIR) or printed 60 lines of
    tracebacks. The workers now have their own session; the batch aborts their jobs."""
    rc, err, where, out, tmpdir, tag = _interrupt_render(
        speech, tmp_path, ["--dask", "local:2"], sig, group=True)
    assert rc == 128 + sig, where
    assert len(err.strip().splitlines()) == 1, where
    assert err.startswith("gesture-sim: interrupted"), where
    assert _tagged(tag) == {}, "orphaned workers"
    names = sorted(p.name for p in out.iterdir()) if out.exists() else []
    assert not [n for n in names if n.startswith(".tmp")], names
    assert list(tmpdir.iterdir()) == [], "temporaries left in $TMPDIR"
