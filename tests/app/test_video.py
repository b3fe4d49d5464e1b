"""Headless video export: frame count, durations, stream start times, pixels, failures.

The clips are rendered from a tiny articulated figure (tests/data/app/figure.xml) at a small size;
each mp4 is decoded with the ffmpeg binary that imageio-ffmpeg ships (``showinfo`` and
``ashowinfo`` report every decoded video frame and audio block with its time stamp).
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import imageio_ffmpeg  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.io import wavfile  # noqa: E402

from gesture_sim.app.camera import TRACK, plan_camera, smooth  # noqa: E402
from gesture_sim.app.video import fit_frames, frames_for_duration, render_video  # noqa: E402
from gesture_sim.errors import GestureSimError  # noqa: E402

FIGURE = Path(__file__).resolve().parents[1] / "data" / "app" / "figure.xml"
FPS = 30.0
W, H = 160, 120
SR = 16_000


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    m = mujoco.MjModel.from_xml_path(str(FIGURE))
    try:
        mujoco.Renderer(m, 32, 32).close()
    except Exception as exc:  # no GL back-end on this machine
        pytest.skip(f"offscreen rendering unavailable: {exc}")
    return m


def swinging_poses(model: mujoco.MjModel, n: int) -> np.ndarray:
    """(n, nq) poses: upright root (identity quaternion) at 1 m, the arm swinging 0 -> 2.5 rad."""
    q = np.zeros((n, model.nq))
    q[:, 2] = 1.0
    q[:, 3] = 1.0
    q[:, 7] = np.linspace(0.0, 2.5, n)
    return q


@dataclass
class Probe:
    video_pts: list[float]
    audio_pts: list[float]
    audio_samples: int
    audio_rate: int | None


def probe(path: Path) -> Probe:
    """Decode ``path`` and collect every frame's time stamp and the audio length.

    Video and audio are decoded in separate passes so that the two filters' log lines cannot
    interleave.
    """
    exe = imageio_ffmpeg.get_ffmpeg_exe()

    def log(*args: str) -> str:
        cmd = [exe, "-hide_banner", "-nostats", "-i", str(path), *args, "-f", "null", "-"]
        return subprocess.run(cmd, capture_output=True, text=True, check=True).stderr

    video = [float(t) for t in re.findall(r"Parsed_showinfo.*?pts_time:\s*(-?[\d.]+)",
                                          log("-an", "-vf", "showinfo"))]
    audio = []
    if has_audio(path):
        audio = re.findall(
            r"Parsed_ashowinfo.*?pts_time:\s*(-?[\d.]+).*?rate:(\d+) nb_samples:(\d+)",
            log("-vn", "-af", "ashowinfo"))
    return Probe(
        video_pts=video,
        audio_pts=[float(a[0]) for a in audio],
        audio_samples=sum(int(a[2]) for a in audio),
        audio_rate=int(audio[0][1]) if audio else None,
    )


def has_audio(path: Path) -> bool:
    info = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)],
                          capture_output=True, text=True).stderr
    return "Audio:" in info


def decode_frames(path: Path) -> np.ndarray:
    """All video frames of ``path`` as (n, H, W, 3) uint8."""
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    return np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader])


@pytest.fixture(scope="module")
def padded_clip(model: mujoco.MjModel, tmp_path_factory: pytest.TempPathFactory):
    """50 poses + a 1.9 s WAV, two workers: the video must grow to ceil(1.9 * 30) = 57 frames."""
    folder = tmp_path_factory.mktemp("padded")
    t = np.arange(int(1.9 * SR)) / SR
    wav = folder / "tone.wav"
    wavfile.write(wav, SR, (0.3 * np.sin(2 * np.pi * 440 * t)).astype(np.float32))
    out = folder / "clip.mp4"
    result = render_video(model, swinging_poses(model, 50), out, fps=FPS, audio=wav, width=W,
                          height=H, workers=2, show_progress=False)
    return result, out


def test_padded_clip_frames_and_durations(padded_clip) -> None:
    result, out = padded_clip
    p = probe(out)
    assert result.n_frames == 57 and result.workers == 2
    assert len(p.video_pts) == 57
    assert p.video_pts[-1] == pytest.approx(56 / FPS, abs=1e-3)
    # The audio keeps the input's 1.9 s (30400 samples at 16 kHz), within one video frame.
    assert p.audio_rate == SR
    assert abs(p.audio_samples - 30_400) <= SR / FPS


def test_streams_start_at_zero(padded_clip) -> None:
    _, out = padded_clip
    p = probe(out)
    assert p.video_pts[0] == pytest.approx(0.0, abs=1e-6)
    assert p.audio_pts[0] == pytest.approx(0.0, abs=1e-6)
    # Frames are evenly spaced at 1/fps across the seam between the two workers' chunks.
    assert np.allclose(np.diff(p.video_pts), 1 / FPS, atol=1e-3)


def test_frames_show_the_figure_and_move(padded_clip) -> None:
    _, out = padded_clip
    frames = decode_frames(out).astype(float)
    assert frames.shape == (57, H, W, 3)
    assert frames[0].std() > 10  # not blank: floor, sky and figure differ
    # The swinging arm changes the picture (mean absolute change over 5 frames, 0-255 scale)...
    motion = np.abs(frames[5:50] - frames[:45]).mean(axis=(1, 2, 3))
    assert motion.min() > 0.2
    # ...and the seven padding frames hold the last pose (up to the encoder's noise).
    held = np.abs(frames[50:] - frames[49]).mean(axis=(1, 2, 3))
    assert held.max() < 0.1


def test_trimmed_to_audio_from_samples_single_worker(model, tmp_path: Path) -> None:
    out = tmp_path / "trim.mp4"
    samples = np.zeros(SR, dtype=np.float32)  # 1.0 s of silence -> 30 frames
    result = render_video(model, swinging_poses(model, 40), out, fps=FPS, audio=samples,
                          width=W, height=H, workers=1, show_progress=False)
    p = probe(out)
    assert result.n_frames == 30 and len(p.video_pts) == 30
    assert abs(p.audio_samples - SR) <= SR / FPS


def test_without_audio_every_pose_is_a_frame(model, tmp_path: Path) -> None:
    out = tmp_path / "silent.mp4"
    render_video(model, swinging_poses(model, 20), out, fps=FPS, width=W, height=H, workers=1,
                 camera=TRACK, show_progress=False)
    assert not has_audio(out)
    assert len(probe(out).video_pts) == 20


def test_failed_encode_leaves_no_file(model, tmp_path: Path) -> None:
    out = tmp_path / "broken.mp4"
    with pytest.raises(GestureSimError, match="render worker 0 failed: .*invalid preset"):
        render_video(model, swinging_poses(model, 40), out, width=W, height=H, workers=2,
                     preset="no-such-preset", show_progress=False)
    assert list(tmp_path.iterdir()) == []


def test_failed_render_keeps_existing_output(model, tmp_path: Path) -> None:
    out = tmp_path / "keep.mp4"
    out.write_bytes(b"old")
    with pytest.raises(GestureSimError):
        render_video(model, swinging_poses(model, 10), out, width=W, height=H, workers=1,
                     preset="no-such-preset", show_progress=False)
    assert out.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.mp4"]


def test_unwritable_path_is_a_clear_error(model, tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(GestureSimError, match="cannot create output folder"):
        render_video(model, swinging_poses(model, 5), blocker / "out.mp4", width=W, height=H,
                     show_progress=False)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"camera": "nowhere"}, "no camera named 'nowhere'.*front, side, track"),
        ({"width": 161}, "even"),
        ({"quality": "ultra"}, "quality"),
        ({"audio": "missing.wav"}, "audio file not found"),
    ],
)
def test_bad_arguments(model, tmp_path: Path, kwargs: dict, match: str) -> None:
    args = {"width": W, "height": H, "show_progress": False} | kwargs
    with pytest.raises(GestureSimError, match=match):
        render_video(model, swinging_poses(model, 5), tmp_path / "x.mp4", **args)
    assert list(tmp_path.iterdir()) == []


def test_wrong_qpos_shape(model, tmp_path: Path) -> None:
    with pytest.raises(GestureSimError, match=r"qpos must have shape \(n_frames >= 1, 8\)"):
        render_video(model, np.zeros((5, 3)), tmp_path / "x.mp4", show_progress=False)


def test_frames_for_duration() -> None:
    assert frames_for_duration(1.9, 30) == 57
    assert frames_for_duration(1.0, 30) == 30
    assert frames_for_duration(1.01, 30) == 31
    assert frames_for_duration(0.0, 30) == 1


def test_fit_frames_trims_and_holds_last_pose() -> None:
    q = np.arange(6, dtype=float).reshape(3, 2)
    assert np.array_equal(fit_frames(q, 2), q[:2])
    assert np.array_equal(fit_frames(q, 5), [[0, 1], [2, 3], [4, 5], [4, 5], [4, 5]])


def test_tracking_camera_follows_root_without_lag(model) -> None:
    n = 301
    q = swinging_poses(model, n)
    q[:, 1] = np.linspace(0.0, 1.0, n)  # walk 1 m along +y over 10 s
    plan = plan_camera(model, TRACK, q, FPS)
    assert plan.lookat is not None and plan.lookat.shape == (n, 3)
    # Zero-phase smoothing of a ramp: no lag away from the ends; height = root + 0.3 m.
    mid = slice(100, 201)
    assert np.allclose(plan.lookat[mid, 1], q[mid, 1], atol=1e-3)
    assert np.allclose(plan.lookat[:, 2], 1.3)


def test_smooth_removes_jitter_keeps_constant() -> None:
    rng = np.random.default_rng(0)
    const = np.tile([1.0, 2.0, 3.0], (60, 1))
    assert np.allclose(smooth(const, 30.0, 0.5), const)
    noisy = const + rng.normal(0, 0.05, const.shape)
    assert smooth(noisy, 30.0, 0.5).std(axis=0).max() < 0.5 * noisy.std(axis=0).min()


def test_resample_qpos_interpolates_and_renormalises(model) -> None:
    from gesture_sim.app.video import resample_qpos

    # Two samples 0.1 s apart: the root turns 90 degrees about z, the arm goes 0 -> 1 rad.
    q = np.zeros((2, model.nq))
    q[:, 2] = 1.0
    q[0, 3] = 1.0
    q[1, 3], q[1, 6] = np.cos(np.pi / 4), np.sin(np.pi / 4)
    q[1, 7] = 1.0
    out = resample_qpos(model, np.array([5.0, 5.1]), q, fps=20.0, n_frames=4)
    # Frames at 0, 0.05, 0.1 s, and 0.15 s (past the end: the last pose is held).
    assert np.allclose(out[:, 7], [0.0, 0.5, 1.0, 1.0])
    assert np.allclose(np.linalg.norm(out[:, 3:7], axis=1), 1.0)
    # Normalised lerp halfway between 0 and 90 degrees is exactly 45 degrees about z.
    assert np.allclose(out[1, 3:7], [np.cos(np.pi / 8), 0, 0, np.sin(np.pi / 8)])


def test_resample_qpos_takes_the_short_way_between_quaternion_signs(model) -> None:
    from gesture_sim.app.video import resample_qpos

    q = np.zeros((2, model.nq))
    q[0, 3] = 1.0
    q[1, 3] = -1.0  # the same orientation, opposite sign
    out = resample_qpos(model, np.array([0.0, 1.0]), q, fps=2.0, n_frames=2)
    assert np.allclose(np.abs(out[1, 3]), 1.0)  # no collapse through a zero quaternion


def test_demo_command_renders_the_example_speech(tmp_path: Path) -> None:
    import json
    import sys

    out = tmp_path / "demo.mp4"
    proc = subprocess.run(
        [sys.executable, "-m", "gesture_sim.cli", "demo", "-o", str(out), "--width", "128",
         "--height", "72", "--quality", "fast", "--json"],
        capture_output=True, text=True, env=os.environ | {"MUJOCO_GL": "egl"},
    )
    if proc.returncode != 0 and "OpenGL" in proc.stderr:
        pytest.skip("offscreen rendering unavailable")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["frames"] == 330 and summary["duration_s"] == pytest.approx(11.0)
    p = probe(out)
    assert len(p.video_pts) == 330
    assert abs(p.audio_samples - 11 * SR) <= SR / FPS  # the whole 11 s speech
    frames = decode_frames(out).astype(float)
    # The simulated humanoid gestures: the picture changes between distant frames.
    assert np.abs(frames[300] - frames[30]).mean() > 0.5


def test_demo_unwritable_output_is_one_line_error(tmp_path: Path) -> None:
    import sys

    blocker = tmp_path / "file"
    blocker.write_text("")
    proc = subprocess.run(
        [sys.executable, "-m", "gesture_sim.cli", "demo", "-o", str(blocker / "x.mp4")],
        capture_output=True, text=True,
    )
    assert proc.returncode == 2
    assert proc.stderr.startswith("gesture-sim: error: cannot create output folder")
    assert "Traceback" not in proc.stderr


def test_render_benchmark_reports_every_configuration() -> None:
    import json
    import sys

    proc = subprocess.run(
        [sys.executable, "-m", "gesture_sim.cli", "bench", "render", "--seconds", "0.5",
         "--sizes", "64x48", "--workers", "1", "--quality", "fast", "--json"],
        capture_output=True, text=True, env=os.environ | {"MUJOCO_GL": "egl"},
    )
    assert proc.returncode == 0, proc.stderr
    results = json.loads(proc.stdout)["results"]
    assert [(r["look"], r["width"], r["height"], r["workers"], r["quality"])
            for r in results] == [("human", 64, 48, 1, "fast"), ("mannequin", 64, 48, 1, "fast")]
    assert all(r["frames"] == 15 and r["video_s"] == pytest.approx(0.5) for r in results)
    assert all(r["realtime_factor"] > 0 for r in results)


_ORPHAN_PARENT = """
import os, pickle, signal, subprocess, sys
import mujoco, numpy as np
from gesture_sim.app import video
from gesture_sim.app.camera import plan_camera
model = mujoco.MjModel.from_xml_path(sys.argv[1])
q = np.zeros((3000, model.nq)); q[:, 2] = 1.0; q[:, 3] = 1.0
q[:, 7] = np.linspace(0.0, 2.5, len(q))
chunk = video._Chunk(0, q, plan_camera(model, "track", q, 30.0), video.Path(sys.argv[2]))
enc = video._Encoder(video.ffmpeg_exe(), 160, 120, 30.0, 30, "ultrafast")
with open(sys.argv[3], "wb") as f:
    pickle.dump((model, chunk, enc), f)
code = "from gesture_sim.app.video import _worker_entry; _worker_entry()"
w = subprocess.Popen([sys.executable, "-c", code, sys.argv[3]], stdout=subprocess.PIPE,
                     stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
                     start_new_session=True)
w.stdout.readline()  # the first frame is done: the worker and its ffmpeg are running
print(w.pid, flush=True)
os.kill(os.getpid(), signal.SIGKILL)  # like an OOM kill: no clean-up runs
"""


def _session_alive(sid: int) -> list[int]:
    """Pids (not zombies) whose session id is ``sid``."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[3]) == sid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
def test_render_worker_and_ffmpeg_exit_when_the_parent_is_killed(model, tmp_path: Path) -> None:
    """Sweep defect 6: after SIGKILL of the main process its render workers noticed nothing
    (the broken pipe to the parent was taken for ffmpeg's) and waited on ffmpeg forever."""
    import time

    proc = subprocess.run(
        [sys.executable, "-c", _ORPHAN_PARENT, str(FIGURE), str(tmp_path / "c.mp4"),
         str(tmp_path / "job.pkl")], capture_output=True, text=True, timeout=120,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})
    worker = int(proc.stdout.split()[0])
    deadline = time.monotonic() + 30.0
    while _session_alive(worker) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = _session_alive(worker)
    for pid in left:  # do not leave them running whatever the outcome
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, 9)
    assert not left, f"worker session {worker} still has processes {left} 30 s after"
