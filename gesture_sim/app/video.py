"""Headless video export: a pose sequence of a MuJoCo model to an H.264 mp4, speech muxed in.

How it works:

1. The frames are split into contiguous chunks, one per render worker. Each worker (a spawned
   process, or the calling process when there is one worker) owns its own offscreen
   :class:`mujoco.Renderer` (EGL when headless) and pipes raw RGB frames straight into an ffmpeg
   process (the binary shipped by ``imageio-ffmpeg``) that encodes its chunk to H.264 yuv420p.
   No image files are written.
2. One final ffmpeg call concatenates the chunks (concat demuxer, stream copy, no re-encode) and
   encodes the audio as AAC into the same mp4.

Duration rule (with audio): the video gets ``ceil(audio_duration * fps)`` frames, so it covers the
whole audio and is at most one frame longer; a longer pose sequence is trimmed, a shorter one
holds its last pose. The audio is never cut or stretched: its stream has the input's duration.
Both streams start at t = 0. Without audio every pose becomes one frame.

Renderer and encoder are independent of where the poses come from (a simulation trace, a
procedural stream, a mocap clip): all this module needs is ``qpos`` sampled at the video rate.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import math
import os
import pickle
import resource
import select
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import mujoco
import numpy as np

from gesture_sim import interrupt
from gesture_sim.app.camera import CameraPlan, plan_camera
from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.cpus import software_gl_threads, usable_cpus
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_path, temp_dir_prefix
from gesture_sim.progress import progress

#: Default video frame rate (frames per second).
DEFAULT_FPS = 30.0
#: Default frame size (pixels).
DEFAULT_WIDTH, DEFAULT_HEIGHT = 1280, 720
#: Sample rate assumed for audio given as an array (Hz), the pipeline's one audio format.
AUDIO_SAMPLE_RATE = SAMPLE_RATE
#: A worker gets at least this many frames; fewer frames mean fewer workers.
MIN_FRAMES_PER_WORKER = 15
#: x264 settings: constant-quality factor and speed preset.
DEFAULT_CRF = 20
DEFAULT_PRESET = "veryfast"
#: AAC bit rate of the muxed speech.
AUDIO_BITRATE = "96k"


@dataclass(frozen=True)
class Quality:
    """A render quality preset.

    Attributes:
        msaa_samples: offscreen multisampling (``model.vis.quality.offsamples``); ``None`` keeps
            the model's value.
        shadow_size: cap on the shadow map size (pixels); ``None`` keeps the model's value.
        shadows, reflections: whether those render passes run.
    """

    msaa_samples: int | None
    shadow_size: int | None
    shadows: bool
    reflections: bool


#: Render quality presets. With software EGL (Mesa llvmpipe, the headless default) the cost of a
#: 1280x720 humanoid frame is dominated by 4x multisampling (about 2-3x), the shadow pass and the
#: floor-reflection pass, not by geometry. ``"high"`` keeps the model's own settings,
#: ``"standard"`` drops multisampling and reflections but keeps the key light's shadow (a
#: 1024-pixel map; 512 shows shadow acne), ``"fast"`` also drops the shadow (about half the cost
#: of ``"standard"``: the shadow pass costs as much as the main pass).
QUALITIES: dict[str, Quality] = {
    "fast": Quality(msaa_samples=0, shadow_size=1024, shadows=False, reflections=False),
    "standard": Quality(msaa_samples=0, shadow_size=1024, shadows=True, reflections=False),
    "high": Quality(msaa_samples=None, shadow_size=None, shadows=True, reflections=True),
}
DEFAULT_QUALITY = "standard"


@dataclass(frozen=True)
class VideoResult:
    """What :func:`render_video` wrote.

    Attributes:
        path: the output file.
        n_frames: video frames written.
        fps: frame rate (Hz).
        width, height: frame size (pixels).
        duration_s: video duration, ``n_frames / fps`` (s).
        audio_duration_s: duration of the muxed audio (s), or ``None`` without audio.
        workers: render workers used.
        wall_s: wall-clock time of rendering, encoding and muxing (s).
        cpu_s: CPU time of the same work, this process and its render/encode processes
            together (s); on a busy machine a steadier figure than ``wall_s``.
    """

    path: Path
    n_frames: int
    fps: float
    width: int
    height: int
    duration_s: float
    audio_duration_s: float | None
    workers: int
    wall_s: float
    cpu_s: float

    @property
    def realtime_factor(self) -> float:
        """Seconds of video produced per second of wall-clock time (> 1: faster than real time)."""
        return self.duration_s / self.wall_s if self.wall_s > 0 else math.inf

    @property
    def frames_per_second(self) -> float:
        """Frames rendered and encoded per wall-clock second."""
        return self.n_frames / self.wall_s if self.wall_s > 0 else math.inf


@dataclass(frozen=True)
class _Encoder:
    """ffmpeg settings shared by every chunk."""

    exe: str
    width: int
    height: int
    fps: float
    crf: int
    preset: str
    quality: Quality = QUALITIES[DEFAULT_QUALITY]

    def chunk_command(self, out: Path) -> list[str]:
        """ffmpeg reading raw RGB frames on stdin, writing H.264 yuv420p to ``out``."""
        return [
            self.exe, "-hide_banner", "-loglevel", "error", "-y",
            "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{self.width}x{self.height}",
            "-framerate", _rate(self.fps), "-i", "pipe:0",
            "-an", "-c:v", "libx264", "-preset", self.preset, "-crf", str(self.crf),
            "-pix_fmt", "yuv420p", str(out),
        ]


@dataclass(frozen=True)
class _Chunk:
    """One worker's share: frames ``start:start + len(qpos)`` of the video."""

    index: int
    qpos: np.ndarray
    camera: CameraPlan
    path: Path


def ffmpeg_exe() -> str:
    """Path of the ffmpeg binary shipped by ``imageio-ffmpeg``."""
    try:
        import imageio_ffmpeg
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise GestureSimError("video export needs imageio-ffmpeg (pip install imageio-ffmpeg)") \
            from exc
    try:
        return imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as exc:
        raise GestureSimError(f"no ffmpeg binary found: {exc}") from exc


def frames_for_duration(duration_s: float, fps: float) -> int:
    """Frames needed for a video of ``fps`` Hz to cover ``duration_s`` seconds (at least 1)."""
    return max(1, math.ceil(duration_s * fps - 1e-6))


def fit_frames(qpos: np.ndarray, n_frames: int) -> np.ndarray:
    """``qpos`` (n, nq) trimmed to ``n_frames`` rows, or padded by repeating its last row."""
    if len(qpos) >= n_frames:
        return qpos[:n_frames]
    pad = np.repeat(qpos[-1:], n_frames - len(qpos), axis=0)
    return np.concatenate([qpos, pad], axis=0)


def resample_qpos(
    model: mujoco.MjModel, times: np.ndarray, qpos: np.ndarray, fps: float,
    n_frames: int | None = None,
) -> np.ndarray:
    """Resample a recorded qpos trace to video frames at ``k / fps`` seconds.

    Args:
        model: the model the trace belongs to (to find quaternion coordinates).
        times: shape (T,), increasing sample times (s); the video's t = 0 is ``times[0]``.
        qpos: shape (T, model.nq), the recorded poses.
        fps: video frame rate (Hz).
        n_frames: frames wanted (default: those that fit in the trace, ``floor(span * fps) + 1``);
            frames past the trace's end hold its last pose.

    Returns:
        Shape (n_frames, model.nq): coordinates interpolated linearly in time, with the
        quaternions of free and ball joints renormalised (normalised linear interpolation).
    """
    times = np.asarray(times, dtype=float)
    qpos = np.asarray(qpos, dtype=float)
    if times.ndim != 1 or qpos.shape != (len(times), model.nq) or len(times) == 0:
        raise GestureSimError(
            f"expected times (T,) and qpos (T, {model.nq}); got {times.shape} and {qpos.shape}")
    rel = times - times[0]
    if n_frames is None:
        n_frames = int(math.floor(rel[-1] * fps + 1e-9)) + 1
    if len(rel) == 1:
        return np.repeat(qpos[:1], n_frames, axis=0)
    t_new = np.minimum(np.arange(n_frames) / fps, rel[-1])
    hi = np.clip(np.searchsorted(rel, t_new, side="right"), 1, len(rel) - 1)
    lo = hi - 1
    span = rel[hi] - rel[lo]
    w = np.where(span > 0, (t_new - rel[lo]) / np.where(span > 0, span, 1.0), 0.0)[:, None]
    out = (1.0 - w) * qpos[lo] + w * qpos[hi]
    for j in range(model.njnt):
        jtype = model.jnt_type[j]
        if jtype == mujoco.mjtJoint.mjJNT_FREE:
            a = int(model.jnt_qposadr[j]) + 3
        elif jtype == mujoco.mjtJoint.mjJNT_BALL:
            a = int(model.jnt_qposadr[j])
        else:
            continue
        quat = out[:, a : a + 4]
        # q and -q are the same rotation: interpolate within one hemisphere.
        flip = np.sum(qpos[lo, a : a + 4] * qpos[hi, a : a + 4], axis=1) < 0
        quat[flip] = ((1.0 - w) * qpos[lo, a : a + 4] - w * qpos[hi, a : a + 4])[flip]
        quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    return out


def scene_camera_names() -> tuple[str, ...]:
    """Camera names of the shipped scene (``assets/mjcf/scene.xml``), without compiling it."""
    import xml.etree.ElementTree as ET

    from gesture_sim.sim.humanoid import SCENE_XML

    try:
        root = ET.parse(SCENE_XML).getroot()
    except (OSError, ET.ParseError):
        return ()
    return tuple(c.get("name") for c in root.iter("camera") if c.get("name"))


def check_camera(camera: str) -> None:
    """GestureSimError unless ``camera`` is a camera of the shipped scene or ``"track"``."""
    from gesture_sim.app.camera import TRACK

    names = scene_camera_names()
    if names and camera not in (*names, TRACK):
        raise GestureSimError(f"--camera must be one of {', '.join((*names, TRACK))}; "
                              f"got {camera!r}")


def render_video(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    output: str | os.PathLike[str],
    *,
    fps: float = DEFAULT_FPS,
    audio: str | os.PathLike[str] | np.ndarray | None = None,
    audio_rate: int = AUDIO_SAMPLE_RATE,
    width: int = DEFAULT_WIDTH,
    height: int = DEFAULT_HEIGHT,
    camera: str = "front",
    workers: int | None = None,
    crf: int = DEFAULT_CRF,
    preset: str = DEFAULT_PRESET,
    quality: str = DEFAULT_QUALITY,
    show_progress: bool = True,
) -> VideoResult:
    """Render ``qpos`` to an H.264 mp4 at ``output``, with ``audio`` muxed in as AAC.

    Args:
        model: the MuJoCo model (not modified; a copy gets the offscreen buffer size and the
            quality settings).
        qpos: shape (n_frames, model.nq), one pose per video frame, sampled at ``fps``.
        output: the mp4 to write, atomically (nothing appears there when rendering fails).
        fps: video frame rate (Hz).
        audio: a WAV file, or mono float32 samples at ``audio_rate`` Hz, or ``None``. With audio
            the video is trimmed or padded (last pose held) to ``ceil(duration * fps)`` frames.
        width, height: frame size in pixels (even numbers, as yuv420p needs).
        camera: a camera name in the model, or ``"track"`` for a free camera that follows the
            root body smoothly (:mod:`gesture_sim.app.camera`).
        workers: render processes; default: the CPUs available to this process.
        crf, preset: x264 quality (lower is better, 18-28 sensible) and speed preset.
        quality: render quality, a key of :data:`QUALITIES` (``"fast"``, ``"standard"``,
            ``"high"``).
        show_progress: show a progress bar on stderr (when it is a terminal).

    Returns:
        A :class:`VideoResult` with frame count, durations and the wall-clock time.

    Raises:
        GestureSimError: bad input, unwritable output, unreadable audio, a failed render or
            encode.
    """
    qpos = np.asarray(qpos, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(qpos) == 0:
        raise GestureSimError(
            f"qpos must have shape (n_frames >= 1, {model.nq}); got {qpos.shape}")
    if not np.all(np.isfinite(qpos)):
        raise GestureSimError("qpos contains NaN or infinite values")
    if not fps > 0:
        raise GestureSimError(f"fps must be positive; got {fps}")
    if width < 16 or height < 16 or width % 2 or height % 2:
        raise GestureSimError(f"frame size must be even and at least 16x16; got {width}x{height}")
    if quality not in QUALITIES:
        raise GestureSimError(f"quality must be one of {', '.join(QUALITIES)}; got {quality!r}")
    from gesture_sim import validation as v

    v.fps("fps", fps)
    v.frame_size(width, height)
    v.workers("workers", workers)
    audio_inputs = [audio] if isinstance(audio, str | os.PathLike) else []
    (out_path,) = v.check_outputs([v.Output("output", output, v.VIDEO_EXTENSIONS)],
                                  inputs=audio_inputs)

    t0, cpu0 = time.perf_counter(), _cpu_seconds()
    exe = ffmpeg_exe()
    with contextlib.ExitStack() as stack:
        tmp_out = stack.enter_context(atomic_path(out_path, suffix=out_path.suffix or ".mp4"))
        tmpdir = Path(stack.enter_context(
            tempfile.TemporaryDirectory(prefix=temp_dir_prefix("video"))))
        audio_file, audio_duration = _prepare_audio(audio, audio_rate, tmpdir)
        if audio_duration is not None:
            qpos = fit_frames(qpos, frames_for_duration(audio_duration, fps))
        n_frames = len(qpos)

        model = copy.copy(model)
        model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
        model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
        preset_q = QUALITIES[quality]
        if camera.startswith("face"):
            # a close-up has no floor shadow to show, and the key light's shadow map, made for
            # the whole body, is too coarse for a face: it speckles the skin (shadow acne)
            preset_q = dataclasses.replace(preset_q, shadows=False)
        if preset_q.msaa_samples is not None:
            model.vis.quality.offsamples = preset_q.msaa_samples
        if preset_q.shadow_size is not None:
            model.vis.quality.shadowsize = min(int(model.vis.quality.shadowsize),
                                               preset_q.shadow_size)
        plan = plan_camera(model, camera, qpos, fps)

        n_workers = _worker_count(workers, n_frames)
        bounds = np.linspace(0, n_frames, n_workers + 1).round().astype(int)
        chunks = [
            _Chunk(i, qpos[a:b], plan.slice(a, b), tmpdir / f"chunk_{i:03d}.mp4")
            for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True))
        ]
        encoder = _Encoder(exe, width, height, float(fps), int(crf), preset, preset_q)
        with progress(total=n_frames, desc="render", unit="frame", enabled=show_progress) as bar:
            if n_workers == 1:
                _render_chunk(model, chunks[0], encoder, bar.update)
            else:
                _render_in_workers(model, chunks, encoder, tmpdir, bar.update)
        _concat_and_mux(exe, [c.path for c in chunks], audio_file, tmpdir, tmp_out)
    return VideoResult(
        path=Path(output), n_frames=n_frames, fps=float(fps), width=width, height=height,
        duration_s=n_frames / fps, audio_duration_s=audio_duration, workers=n_workers,
        wall_s=time.perf_counter() - t0, cpu_s=_cpu_seconds() - cpu0,
    )


def _cpu_seconds() -> float:
    """User + system CPU time of this process and of its finished child processes (s)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _rate(fps: float) -> str:
    """ffmpeg's spelling of a frame rate: an integer where possible, else a decimal."""
    return str(int(fps)) if float(fps).is_integer() else repr(float(fps))


def _worker_count(workers: int | None, n_frames: int) -> int:
    if workers is None:
        workers = usable_cpus()
    if workers < 1:
        raise GestureSimError(f"workers must be at least 1; got {workers}")
    return max(1, min(workers, n_frames // MIN_FRAMES_PER_WORKER))


def _prepare_audio(
    audio: str | os.PathLike[str] | np.ndarray | None, rate: int, tmpdir: Path,
) -> tuple[Path | None, float | None]:
    """A file ffmpeg can read and its duration (s); (None, None) without audio."""
    from scipy.io import wavfile

    if audio is None:
        return None, None
    if isinstance(audio, str | os.PathLike):
        path = Path(audio)
        if not path.is_file():
            raise GestureSimError(f"audio file not found: {path}")
        from gesture_sim.audio.sources import read_wav_checked

        # the readers' checks and formats (G.711 telephony WAVs included; ffmpeg muxes them)
        samples, file_rate, _ = read_wav_checked(path)
        if len(samples) == 0:
            raise GestureSimError(f"audio file {path} is empty")
        return path, len(samples) / float(file_rate)
    samples = np.asarray(audio, dtype=np.float32)
    if samples.ndim != 1 or len(samples) == 0:
        raise GestureSimError(f"audio samples must be a non-empty mono array; got {samples.shape}")
    if not rate > 0:
        raise GestureSimError(f"audio_rate must be positive; got {rate}")
    path = tmpdir / "audio.wav"
    wavfile.write(path, int(rate), samples)
    return path, len(samples) / float(rate)


def _make_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    try:
        return mujoco.Renderer(model, height, width)
    except Exception as exc:  # GL back-ends raise assorted types
        raise GestureSimError(
            f"cannot create an offscreen OpenGL context ({exc}); on a machine without a "
            "display set MUJOCO_GL=egl and install the EGL/Mesa libraries") from exc


def _render_chunk(
    model: mujoco.MjModel, chunk: _Chunk, encoder: _Encoder, report: Callable[[int], object],
) -> None:
    """Render one chunk's frames and encode them to ``chunk.path``; report each frame done."""
    data = mujoco.MjData(model)
    renderer = _make_renderer(model, encoder.height, encoder.width)
    cam = mujoco.MjvCamera()
    mujoco.mjv_defaultFreeCamera(model, cam)
    log_path = chunk.path.with_suffix(".log")
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(encoder.chunk_command(chunk.path), stdin=subprocess.PIPE,
                                stdout=subprocess.DEVNULL, stderr=log)
        assert proc.stdin is not None
        try:
            for i, q in enumerate(chunk.qpos):
                data.qpos[:] = q
                mujoco.mj_forward(model, data)
                chunk.camera.configure(cam, i)
                renderer.update_scene(data, camera=cam)
                if not encoder.quality.shadows:
                    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
                if not encoder.quality.reflections:
                    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
                if not _to_encoder(proc.stdin, np.ascontiguousarray(renderer.render()).data):
                    break  # ffmpeg died; its log says why
                # A broken pipe here is the parent gone (killed): not ffmpeg, and not to be
                # swallowed, or the wait below would wait on an ffmpeg whose stdin is open.
                report(1)
            _to_encoder(proc.stdin, None)
        except BaseException:
            proc.kill()
            raise
        finally:
            try:
                rc = proc.wait()
            finally:  # a signal during the wait must not leave the encoder running
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
                renderer.close()
    if rc != 0:
        raise GestureSimError(f"video encoding failed (ffmpeg exit {rc}): {_first_line(log_path)}")


def _to_encoder(stdin: IO[bytes], frame: memoryview | None) -> bool:
    """Write one raw frame to ffmpeg's stdin (``None``: close it); ``False`` when ffmpeg has
    gone (a broken pipe)."""
    try:
        if frame is None:
            stdin.close()
        else:
            stdin.write(frame)
        return True
    except BrokenPipeError:
        return False


def _worker_entry() -> None:
    """Entry point of a render process: ``python -c ... JOB.pkl``.

    Renders the pickled job's chunk, writes one line ``+`` per finished frame to stdout and exits
    0, or writes ``error: MESSAGE`` and exits 1. It ends with the main process (``argv[2]``, its
    pid) however that ends (:func:`gesture_sim.interrupt.end_with_parent`).
    """
    if len(sys.argv) > 2:
        import signal

        if os.getpgrp() == os.getpid():   # its own group (its session): it and its ffmpeg
            signal.signal(signal.SIGTERM,
                          lambda _s, _f: os.killpg(os.getpgrp(), signal.SIGKILL))
        interrupt.end_with_parent(int(sys.argv[2]))
    with open(sys.argv[1], "rb") as f:
        model, chunk, encoder = pickle.load(f)
    out = sys.stdout

    def report(n: int) -> None:
        out.write("+\n" * n)
        out.flush()

    try:
        _render_chunk(model, chunk, encoder, report)
    except BrokenPipeError:  # the parent is gone (killed): nobody to tell; ffmpeg is closed
        os._exit(1)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises
        message = (str(exc) or type(exc).__name__).replace("\n", " ")
        out.write(f"error: {message}\n")
        out.flush()
        sys.exit(1)


def _render_in_workers(
    model: mujoco.MjModel, chunks: list[_Chunk], encoder: _Encoder, tmpdir: Path,
    report: Callable[[int], object],
) -> None:
    """Render the chunks in parallel worker processes, each with its own GL context.

    Workers are fresh interpreters started with :mod:`subprocess` (not :mod:`multiprocessing`),
    so they never inherit a GL context and never re-import the caller's main script.
    """
    env = dict(os.environ)
    if "MUJOCO_GL" not in env and sys.platform.startswith("linux") and not env.get("DISPLAY"):
        env["MUJOCO_GL"] = "egl"
        env.setdefault("PYOPENGL_PLATFORM", "egl")
    # Software EGL (llvmpipe) starts one rasteriser thread per CPU in every worker; share the
    # CPUs between the workers instead (0 = rasterise in the worker's own thread).
    env.setdefault("LP_NUM_THREADS", software_gl_threads(usable_cpus() // len(chunks)))
    code = "from gesture_sim.app.video import _worker_entry; _worker_entry()"
    procs: list[subprocess.Popen[bytes]] = []
    errors: dict[int, str] = {}
    try:
        for c in chunks:
            job = tmpdir / f"job_{c.index:03d}.pkl"
            with open(job, "wb") as f:
                pickle.dump((model, c, encoder), f, protocol=pickle.HIGHEST_PROTOCOL)
            log = open(tmpdir / f"worker_{c.index:03d}.log", "wb")  # noqa: SIM115
            with log:
                # own session: a terminal's Ctrl-C reaches only the main process, which ends
                # each worker together with its ffmpeg (same process group) on the way out
                procs.append(subprocess.Popen(
                    [sys.executable, "-c", code, str(job), str(os.getpid())],
                    stdout=subprocess.PIPE,
                    stderr=log, env=env, start_new_session=True))
        streams = {p.stdout: i for i, p in enumerate(procs) if p.stdout is not None}
        while streams:
            interrupt.check()   # a signal whose raise was dropped still ends the render
            ready, _, _ = select.select(list(streams), [], [], 1.0)
            for stream in ready:
                line = stream.readline()
                if not line:
                    del streams[stream]
                elif line.startswith(b"+"):
                    report(1)
                elif line.startswith(b"error:"):
                    errors[streams[stream]] = line[6:].decode(errors="replace").strip()
        for i, p in enumerate(procs):
            rc = p.wait()
            if rc != 0 and i not in errors:
                errors[i] = (f"exit code {rc}: "
                             f"{_first_line(tmpdir / f'worker_{i:03d}.log')}")
    finally:
        for p in procs:
            _kill_group(p)
            if p.stdout is not None:
                p.stdout.close()
    if errors:
        index = min(errors)
        raise GestureSimError(f"render worker {index} failed: {errors[index]}")


def _kill_group(proc: subprocess.Popen[bytes]) -> None:
    """End a render worker and everything in its process group (its ffmpeg), and reap it."""
    import signal

    if proc.returncode is None:  # not reaped yet: its pid is still its group's id
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()
    proc.wait()


def _concat_and_mux(
    exe: str, chunk_paths: list[Path], audio: Path | None, tmpdir: Path, out: Path,
) -> None:
    """Concatenate the encoded chunks (stream copy) and mux ``audio`` as AAC into ``out``."""
    listing = tmpdir / "chunks.txt"
    listing.write_text("".join(f"file '{p.resolve()}'\n" for p in chunk_paths), encoding="utf-8")
    cmd = [exe, "-hide_banner", "-loglevel", "error", "-y",
           "-f", "concat", "-safe", "0", "-i", str(listing)]
    if audio is not None:
        cmd += ["-i", str(audio), "-map", "0:v:0", "-map", "1:a:0",
                "-c:a", "aac", "-b:a", AUDIO_BITRATE]
    cmd += ["-c:v", "copy", "-movflags", "+faststart", str(out)]
    proc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, check=False)
    if proc.returncode != 0:
        message = proc.stderr.decode(errors="replace").strip().splitlines()
        raise GestureSimError(
            f"muxing the video failed (ffmpeg exit {proc.returncode}): "
            f"{message[0] if message else 'no message'}")


def _first_line(path: Path) -> str:
    """The first line of an ffmpeg log (ffmpeg reports the cause first, then the fallout)."""
    try:
        lines = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return "no message"
    return lines[0] if lines else "no message"
