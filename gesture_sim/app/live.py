"""The live loop: the passive MuJoCo viewer driven by the microphone (or a file) in real time.

One loop on the main thread, one frame at a time at the display rate (default 60 Hz)::

    drain the audio blocks that have arrived (never waits)  -> pipeline.push_audio
    advance physics to the live clock (wall time, pauses excluded) -> pipeline.advance
    hand the overlay texts to the overlay thread; viewer.sync() (never per physics step)
    act on the keys pressed since the last frame; sleep to the next frame deadline

Threads: PortAudio's callback thread (the microphone; it only fills a ring buffer, see
:class:`~gesture_sim.audio.sources.MicrophoneSource`), a pump thread that turns the ring into
:class:`~gesture_sim.contracts.AudioBlock` s on a queue, the viewer's render thread (MuJoCo), and
an overlay thread that calls ``Handle.set_texts``, which blocks until the render thread has
drawn a frame (hundreds of ms under software GL) and releases the GIL while it waits.

Clocks. The *live clock* (the stream time physics is advanced to) starts with the first audio
block pushed and then follows the wall clock, less the time spent paused and less *slip*: when
physics falls more than ``max_lag_s`` behind (a slow machine, a stall), the live clock gives up
the excess instead of making the next frame catch up all at once. Audio blocks are re-stamped
onto one contiguous pipeline clock: audio that arrived while the window opened or while paused
is dropped, and after a slip the same duration of audio is dropped, so audio and physics stay
on one clock. A reset restarts the stream (and the live clock) at 0. Everything dropped is
counted in the stats.

Memory: the loop itself keeps bounded buffers only (preallocated timing rings, a bounded audio
queue, a thinned RSS history), so its resident size stays flat over a long run, provided the
pipeline keeps no unbounded history (``GesturePipeline(record=False)`` where available); the
stats sample the RSS once a second and report its slope over the second half of the run.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import json
import math
import os
import queue
import resource
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import mujoco
import numpy as np

from gesture_sim.app.overlay import (
    KeyAction,
    OverlayState,
    decode_key,
    key_map_lines,
    viewer_texts,
)
from gesture_sim.audio.sources import DEFAULT_BLOCK_SIZE, MicrophoneSource, load_audio
from gesture_sim.contracts import SAMPLE_RATE, AudioBlock
from gesture_sim.control.style import clip_style
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_path, atomic_write_text

#: Viewer camera: distance (m), azimuth and elevation (degrees), look-at height above the root.
CAMERA_DISTANCE_M = 3.0
CAMERA_AZIMUTH_DEG = 195.0
CAMERA_ELEVATION_DEG = -8.0
CAMERA_LOOKAT_DZ_M = 0.2
#: Frames kept for the timing percentiles (10 min at 60 Hz): bounded, so memory stays flat.
TIMING_WINDOW = 36_000
#: Seconds between RSS samples; samples kept (a bounded, thinned history).
RSS_PERIOD_S = 1.0
RSS_SAMPLES = 600


class Pipeline(Protocol):
    """What the live loop needs of :class:`gesture_sim.pipeline.GesturePipeline` (the MuJoCo
    model and data are found by :func:`mujoco_of`: ``model_mj``/``data`` or ``model``/``data``).
    """

    data: mujoco.MjData
    labels: tuple[str, ...]

    def push_audio(self, block: AudioBlock) -> None: ...
    def advance(self, t: float) -> None: ...
    def status(self) -> Any: ...
    def set_style(self, dial: float) -> None: ...
    def trigger_label(self, label: str) -> None: ...
    def reset(self) -> None: ...


# ============================================================================================
# Audio feeds: non-blocking sources of AudioBlocks for the loop
# ============================================================================================


class AudioFeed(Protocol):
    """A live audio source polled once per frame with the feed clock ``t_feed`` (s: wall time
    since the loop started, pauses excluded); a microphone ignores it, a file is paced by it."""

    description: str

    def start(self) -> None: ...
    def poll(self, t_feed: float) -> list[AudioBlock]: ...
    def set_paused(self, paused: bool) -> None: ...
    def stats(self) -> dict[str, float]: ...
    def close(self) -> None: ...


class MicrophoneFeed:
    """A :class:`MicrophoneSource` drained by a pump thread into a bounded queue.

    Args:
        source: the microphone (or a fake device through its ``stream_factory``).
        max_queue_s: audio (s) the queue holds before the oldest blocks are dropped (counted).

    :meth:`poll` returns every block that has arrived, in order, without waiting. The blocks'
    ``t_start`` is the microphone's stream time (delivered samples / 16 kHz).
    """

    def __init__(self, source: MicrophoneSource, max_queue_s: float = 2.0) -> None:
        self.source = source
        name = source.device_info["name"] if source.device_info else "input device"
        self.description = f"microphone: {name}"
        self._q: queue.Queue[AudioBlock] = queue.Queue(
            maxsize=max(4, int(max_queue_s * SAMPLE_RATE / source.block_size)))
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.queue_dropped_s = 0.0
        self.ended = False

    def start(self) -> None:
        """Open the input stream (errors surface here, as :class:`GestureSimError`)."""
        self.source.start()
        self._thread = threading.Thread(target=self._pump, name="gesture-sim-audio",
                                        daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        try:
            for block in self.source:
                while True:
                    try:
                        self._q.put_nowait(block)
                        break
                    except queue.Full:
                        with contextlib.suppress(queue.Empty):
                            old = self._q.get_nowait()
                            self.queue_dropped_s += len(old.samples) / SAMPLE_RATE
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread by poll()
            self._error = exc
        finally:
            self.ended = True

    def poll(self, t_feed: float) -> list[AudioBlock]:
        """Every block that has arrived since the last call (``t_feed`` is not used)."""
        if self._error is not None:
            err, self._error = self._error, None
            if isinstance(err, GestureSimError):
                raise err
            raise GestureSimError(f"the audio input failed: {err}") from err
        out: list[AudioBlock] = []
        while True:
            try:
                out.append(self._q.get_nowait())
            except queue.Empty:
                return out

    def set_paused(self, paused: bool) -> None:
        """The microphone keeps running; the loop drops what arrives while paused."""

    def stats(self) -> dict[str, float]:
        """PortAudio overflow events, ring-buffer drops and queue drops."""
        s = dict(self.source.stats())
        s["queue_dropped_s"] = round(self.queue_dropped_s, 4)
        return s

    def close(self) -> None:
        """Stop and close the input stream and the pump thread."""
        self.source.stop()
        if self._thread is not None:
            self._thread.join(timeout=2.0)


class FileFeed:
    """An audio file played through the live path, paced by the feed clock.

    ``poll(t_feed)`` returns the 10 ms blocks whose end lies at or before ``t_feed`` (so
    pausing the clock pauses the file). After the end the file repeats (``loop``) or silence
    follows. With ``speakers`` the samples also go to the default output device through a
    sounddevice ``OutputStream`` (silence while paused); without an output device the feed
    plays silently.

    Args:
        path: any file :func:`~gesture_sim.audio.sources.load_audio` reads.
        loop: repeat the file.
        speakers: try to play it to the default output device.
        block_size: samples per block (16 kHz).
    """

    def __init__(self, path: str | Path, loop: bool = False, speakers: bool = True,
                 block_size: int = DEFAULT_BLOCK_SIZE) -> None:
        self.samples, self.info = load_audio(path)
        self.path = Path(path)
        self.loop = loop
        self.block_size = int(block_size)
        self.want_speakers = speakers
        self.description = f"file: {self.path.name}"
        self._next = 0  # next sample index on the live clock (may exceed len when looping)
        self._out: Any = None
        self._play = 0
        self._paused = False
        self.output_device: str | None = None
        self.output_underflows = 0

    @property
    def duration(self) -> float:
        """Duration of the file (s)."""
        return len(self.samples) / SAMPLE_RATE

    def finished(self, t_feed: float) -> bool:
        """Whether the file has been played through (never when looping)."""
        return not self.loop and t_feed >= self.duration

    def start(self) -> None:
        """Open the speaker stream when there is an output device (silently skip otherwise)."""
        if not self.want_speakers:
            return
        try:
            import sounddevice as sd

            dev = sd.query_devices(kind="output")
            stream = sd.OutputStream(samplerate=SAMPLE_RATE, channels=1, dtype="float32",
                                     callback=self._out_callback)
            stream.start()
        except Exception:  # noqa: BLE001 - no PortAudio, no output device, busy: play silently
            return
        self._out = stream
        self.output_device = str(dev.get("name", "default")) if isinstance(dev, dict) else "default"
        self.description += " (speakers)"

    def _out_callback(self, outdata: np.ndarray, frames: int, time_info: Any,
                      status: Any) -> None:
        if status is not None and getattr(status, "output_underflow", False):
            self.output_underflows += 1
        outdata[:, 0] = self._slice(self._play, frames) if not self._paused else 0.0
        if not self._paused:
            self._play += frames

    def _slice(self, i0: int, n: int) -> np.ndarray:
        """Samples [i0, i0 + n) of the (looped or silence-padded) stream, float32 (n,)."""
        total = len(self.samples)
        if self.loop:
            idx = np.arange(i0, i0 + n) % total
            return self.samples[idx]
        out = np.zeros(n, dtype=np.float32)
        if i0 < total:
            k = min(n, total - i0)
            out[:k] = self.samples[i0 : i0 + k]
        return out

    def poll(self, t_feed: float) -> list[AudioBlock]:
        """The blocks whose end is at or before ``t_feed`` (s on the feed clock: wall time
        since the loop started, pauses excluded)."""
        end = int(math.floor(t_feed * SAMPLE_RATE + 1e-6))
        out = []
        b = self.block_size
        while self._next + b <= end:
            out.append(AudioBlock(self._slice(self._next, b), self._next / SAMPLE_RATE))
            self._next += b
        return out

    def set_paused(self, paused: bool) -> None:
        """Pause the speaker output (the live clock pauses the blocks)."""
        self._paused = paused

    def stats(self) -> dict[str, float]:
        """Output underflows (0 when there are no speakers)."""
        return {"overflow_events": 0, "dropped_samples": 0, "dropped_s": 0.0,
                "output_underflows": self.output_underflows,
                "speakers": self._out is not None}

    def close(self) -> None:
        """Stop the speaker stream."""
        if self._out is not None:
            with contextlib.suppress(Exception):
                self._out.stop()
                self._out.close()
            self._out = None


# ============================================================================================
# Options, statistics
# ============================================================================================


@dataclass
class LiveOptions:
    """Settings of :func:`run_live`.

    Attributes:
        duration: stop after this many seconds of wall time (``None``: until the window is
            closed, Ctrl-C, or the end of a non-looping file plus ``tail_s``).
        fps: display rate (Hz) at which the loop syncs the viewer.
        max_lag_s: physics may lag the live clock by this much (s) before the clock slips.
        style: initial style dial, 0 (calm) … 1 (energetic).
        screenshots: (wall time s since start, PNG path) pairs to capture during the run.
        final_screenshot: a PNG captured when the loop ends.
        screenshot_mode: ``"render"`` (offscreen :class:`mujoco.Renderer` from the viewer's
            camera; no overlays) or ``"screen"`` (grab the X screen where the window is; needs
            an X display without a window manager moving the window, e.g. Xvfb).
        stats_path: write the loop statistics (JSON) here at the end.
        shadow_size: shadow-map size for the viewer (pixels); software GL renders 1024 several
            times faster than the scene's 4096.
        tail_s: how long to keep going after a non-looping file ends (s).
        show_keys: show the key map in the viewer; print_keys: print it at start.
        out: where the key map and the end summary go (``None``: stdout).
    """

    duration: float | None = None
    fps: float = 60.0
    max_lag_s: float = 0.2
    style: float = 0.5
    screenshots: Sequence[tuple[float, str | Path]] = ()
    final_screenshot: str | Path | None = None
    screenshot_mode: str = "render"
    stats_path: str | Path | None = None
    shadow_size: int | None = 1024
    tail_s: float = 1.0
    show_keys: bool = True
    print_keys: bool = True
    out: Any = None


class _Window:
    """Running mean/std/max over everything, percentiles over the last ``n`` values.

    The recent values live in a preallocated ring (touched at creation), so a long run does
    not grow the process.
    """

    def __init__(self, n: int = TIMING_WINDOW) -> None:
        self._ring = np.full(n, np.nan)
        self.count = 0
        self.mean = 0.0
        self._m2 = 0.0
        self.max = -math.inf

    def add(self, x: float) -> None:
        self._ring[self.count % len(self._ring)] = x
        self.count += 1
        d = x - self.mean
        self.mean += d / self.count
        self._m2 += d * (x - self.mean)
        self.max = max(self.max, x)

    @property
    def std(self) -> float:
        return math.sqrt(self._m2 / self.count) if self.count > 1 else 0.0

    def pct(self, q: float) -> float:
        return float(np.nanpercentile(self._ring, q)) if self.count else 0.0


def _rss_mb() -> float:
    """Current resident set size (MiB), from /proc (0 where unavailable)."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return 0.0


def _maxrss_mb() -> float:
    """Peak resident set size of this process so far (MiB; Linux reports KiB)."""
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / 2**20 if sys.platform == "darwin" else r / 1024


@dataclass
class LiveStats:
    """What one live run measured (written by ``--stats``; see :meth:`to_dict`)."""

    frames: int = 0
    wall_s: float = 0.0
    paused_s: float = 0.0
    sim_s: float = 0.0
    slipped_s: float = 0.0
    audio_pushed_s: float = 0.0
    audio_dropped_paused_s: float = 0.0
    audio_dropped_slip_s: float = 0.0
    audio_dropped_at_start_s: float = 0.0
    frame_dt: _Window = field(default_factory=_Window)
    steps: _Window = field(default_factory=_Window)
    work_ms: _Window = field(default_factory=_Window)
    lag: _Window = field(default_factory=_Window)
    maxrss_start_mb: float = 0.0
    maxrss_end_mb: float = 0.0
    rss: list[tuple[float, float]] = field(default_factory=list)
    source: dict[str, Any] = field(default_factory=dict)
    keys: list[str] = field(default_factory=list)
    exit_reason: str = ""
    screenshots: list[str] = field(default_factory=list)

    def sample_rss(self, t: float) -> None:
        """Record (t, RSS MiB); halves the history when full so it stays bounded."""
        self.rss.append((round(t, 2), round(_rss_mb(), 2)))
        if len(self.rss) > RSS_SAMPLES:
            self.rss = self.rss[::2]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures: frame time (ms), physics steps per frame, real-time share, audio
        drops (s), memory (MiB) with the RSS slope over the second half of the run (MiB per
        minute, least squares; ~0 when memory stays flat)."""
        rt_wall = max(self.wall_s - self.paused_s, 1e-9)
        rss = np.array(self.rss) if self.rss else np.zeros((0, 2))
        half = rss[len(rss) // 2 :]  # after the warm-up (windows, caches, first allocations)
        slope = 0.0
        if len(half) >= 3 and np.ptp(half[:, 0]) > 0:
            slope = float(np.polyfit(half[:, 0], half[:, 1], 1)[0] * 60.0)
        return {
            "frames": self.frames,
            "wall_s": round(self.wall_s, 3),
            "paused_s": round(self.paused_s, 3),
            "sim_s": round(self.sim_s, 3),
            "percent_real_time": round(100.0 * self.sim_s / rt_wall, 1),
            "fps": round(self.frames / max(self.wall_s, 1e-9), 2),
            "physics_steps_per_frame": {"mean": round(self.steps.mean, 2),
                                        "p95": self.steps.pct(95), "max": self.steps.max
                                        if self.steps.count else 0},
            "frame_time_ms": {"mean": round(1e3 * self.frame_dt.mean, 3),
                              "p50": round(1e3 * self.frame_dt.pct(50), 3),
                              "p95": round(1e3 * self.frame_dt.pct(95), 3),
                              "max": round(1e3 * self.frame_dt.max, 3)
                              if self.frame_dt.count else 0.0,
                              "jitter_std": round(1e3 * self.frame_dt.std, 3)},
            "loop_work_ms": {"mean": round(self.work_ms.mean, 3),
                             "p95": round(self.work_ms.pct(95), 3)},
            "physics_lag_ms": {"mean": round(1e3 * self.lag.mean, 2),
                               "p95": round(1e3 * self.lag.pct(95), 2)},
            "slipped_s": round(self.slipped_s, 4),
            "audio": {"pushed_s": round(self.audio_pushed_s, 3),
                      "dropped_while_paused_s": round(self.audio_dropped_paused_s, 3),
                      "dropped_on_slip_s": round(self.audio_dropped_slip_s, 3),
                      "dropped_at_start_s": round(self.audio_dropped_at_start_s, 3),
                      **self.source},
            "memory": {"maxrss_start_mb": round(self.maxrss_start_mb, 1),
                       "maxrss_end_mb": round(self.maxrss_end_mb, 1),
                       "rss_first_mb": rss[0, 1].item() if len(rss) else None,
                       "rss_last_mb": rss[-1, 1].item() if len(rss) else None,
                       "rss_max_mb": rss[:, 1].max().item() if len(rss) else None,
                       "rss_slope_second_half_mb_per_min": round(slope, 3),
                       "rss_series": [list(r) for r in self.rss[:: max(len(self.rss) // 60, 1)]]},
            "keys": self.keys[-50:],
            "exit_reason": self.exit_reason,
            "screenshots": self.screenshots,
        }


# ============================================================================================
# Viewer helpers
# ============================================================================================


def check_display() -> None:
    """Raise a one-line :class:`GestureSimError` when no window can be opened.

    On Linux an X display must be reachable (``DISPLAY``, opened with Xlib) or a Wayland
    socket named (``WAYLAND_DISPLAY``); macOS and Windows always have one.
    """
    if not sys.platform.startswith("linux"):
        return
    disp = os.environ.get("DISPLAY")
    if not disp:
        if os.environ.get("WAYLAND_DISPLAY"):
            return
        raise GestureSimError(
            "no display: the live viewer needs a window (DISPLAY is not set); "
            "use `gesture-sim render AUDIO -o OUT.mp4` for a headless video")
    lib = ctypes.util.find_library("X11")
    if lib is None:
        return  # cannot check; GLFW will tell
    x11 = ctypes.CDLL(lib)
    x11.XOpenDisplay.restype = ctypes.c_void_p
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    dpy = x11.XOpenDisplay(disp.encode())
    if not dpy:
        raise GestureSimError(
            f"no display: cannot open X display {disp!r}; "
            "use `gesture-sim render AUDIO -o OUT.mp4` for a headless video")
    x11.XCloseDisplay(dpy)


class _OverlayPump:
    """Calls ``viewer.set_texts`` on its own thread with the newest texts.

    ``set_texts`` waits until the render thread has drawn a frame (and releases the GIL while
    it waits), so calling it from the loop would tie the loop to the render rate.
    """

    def __init__(self, viewer: Any) -> None:
        self.viewer = viewer
        self._texts: list[Any] | None = None
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self.updates = 0
        self._thread = threading.Thread(target=self._run, name="gesture-sim-overlay",
                                        daemon=True)
        self._thread.start()

    def submit(self, texts: list[Any]) -> None:
        with self._lock:
            self._texts = texts
        self._wake.set()

    def _run(self) -> None:
        while not self._stop.is_set():
            if not self._wake.wait(0.05):
                continue
            self._wake.clear()
            with self._lock:
                texts, self._texts = self._texts, None
            if texts is None or self._stop.is_set() or not self.viewer.is_running():
                continue
            try:
                self.viewer.set_texts(texts)
            except Exception:  # noqa: BLE001 - a closing viewer; the loop notices by itself
                return
            self.updates += 1

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout=2.0)


def setup_camera(viewer: Any, model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Point the viewer's free camera at the humanoid's chest from the front-right."""
    with viewer.lock():
        cam = viewer.cam
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        root = np.array(data.qpos[:3]) if model.nq >= 7 else np.array(model.stat.center)
        cam.lookat[:] = (root[0], root[1], root[2] + CAMERA_LOOKAT_DZ_M)
        cam.distance = CAMERA_DISTANCE_M
        cam.azimuth = CAMERA_AZIMUTH_DEG
        cam.elevation = CAMERA_ELEVATION_DEG


class ScreenshotTaker:
    """Saves PNGs of what the viewer shows.

    ``"render"`` draws ``data`` offscreen with a :class:`mujoco.Renderer` from a copy of the
    viewer's camera at the viewer's size (clipped to the model's offscreen buffer);
    ``"screen"`` grabs the X screen (Pillow's XCB grab) and crops the window's area at the
    screen's top-left corner, where a window without a window manager opens (Xvfb).
    """

    def __init__(self, model: mujoco.MjModel, mode: str = "render") -> None:
        if mode not in ("render", "screen"):
            raise GestureSimError(f"screenshot mode must be 'render' or 'screen', got {mode!r}")
        self.model = model
        self.mode = mode
        self._renderer: mujoco.Renderer | None = None

    def capture(self, viewer: Any, data: mujoco.MjData) -> np.ndarray:
        """The current picture, uint8 (height, width, 3)."""
        vp = viewer.viewport if viewer is not None else None
        w, h = (vp.width, vp.height) if vp is not None and vp.width > 0 else (853, 480)
        if self.mode == "screen":
            from PIL import ImageGrab

            img = ImageGrab.grab(xdisplay=os.environ.get("DISPLAY"))
            return np.asarray(img.convert("RGB"))[:h, :w].copy()
        w = min(w, int(self.model.vis.global_.offwidth))
        h = min(h, int(self.model.vis.global_.offheight))
        if self._renderer is None or (self._renderer.width, self._renderer.height) != (w, h):
            self.close()
            self._renderer = mujoco.Renderer(self.model, h, w)
        cam = mujoco.MjvCamera()
        if viewer is not None:
            src = viewer.cam
            cam.type, cam.fixedcamid, cam.trackbodyid = src.type, src.fixedcamid, src.trackbodyid
            cam.lookat[:], cam.distance = src.lookat, src.distance
            cam.azimuth, cam.elevation = src.azimuth, src.elevation
        self._renderer.update_scene(data, camera=cam)
        return self._renderer.render().copy()

    def save(self, viewer: Any, data: mujoco.MjData, path: str | Path) -> None:
        """Capture and write a PNG atomically."""
        from PIL import Image

        img = self.capture(viewer, data)
        with atomic_path(path, suffix=".png") as tmp:
            Image.fromarray(img).save(tmp, format="PNG")

    def close(self) -> None:
        if self._renderer is not None:
            with contextlib.suppress(Exception):
                self._renderer.close()
            self._renderer = None


# ============================================================================================
# The loop
# ============================================================================================


def _status_fields(st: Any) -> dict[str, Any]:
    """Read a PipelineStatus defensively (fields may be missing or None)."""
    belief = getattr(st, "belief", None)
    segment = getattr(st, "segment_name", None) or getattr(st, "segment", None)
    if isinstance(segment, (int, np.integer)) and segment < 0:
        segment = None
    return {
        "t": float(getattr(st, "t", 0.0) or 0.0),
        "level_db": getattr(st, "level_db", None),
        "state": getattr(st, "state", None),
        "belief": None if belief is None else np.asarray(belief, dtype=float),
        "segment": segment,
        "style": getattr(st, "style", None),
        "label": getattr(st, "label", None),
    }


def mujoco_of(pipeline: Any) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The simulated humanoid's (MjModel, MjData) of a pipeline: ``model_mj``/``data`` of
    :class:`~gesture_sim.pipeline.GesturePipeline`, else ``model``/``data``."""
    model = getattr(pipeline, "model_mj", None)
    if not isinstance(model, mujoco.MjModel):
        model = getattr(pipeline, "model", None)
    data = getattr(pipeline, "data", None)
    if not isinstance(model, mujoco.MjModel) or not isinstance(data, mujoco.MjData):
        raise GestureSimError("the live viewer needs a pipeline that simulates the humanoid "
                              "(this one runs without physics)")
    return model, data


class LiveLoop:
    """The live loop of one session (see the module docstring); run it with :meth:`run`.

    Clocks (all in seconds): *wall* runs from the loop's start; the *feed clock* (paces a
    file) is wall time minus pauses; the *live clock* ``t_live`` is the stream time physics is
    advanced to. It stays at 0 until the first audio block is pushed (so a late or silent
    start costs nothing), then runs with the wall clock, less pauses and slips; a reset
    restarts it at 0 together with the pipeline's stream.

    Args:
        pipeline: a :class:`~gesture_sim.pipeline.GesturePipeline` (or anything with its
            methods); its MuJoCo model and data (:func:`mujoco_of`) are what the viewer shows.
        feed: where the audio comes from (:class:`MicrophoneFeed` or :class:`FileFeed`).
        options: :class:`LiveOptions`.
        viewer_factory: ``mujoco.viewer.launch_passive`` or a stand-in with its signature.
    """

    def __init__(self, pipeline: Pipeline, feed: AudioFeed, options: LiveOptions | None = None,
                 viewer_factory: Callable[..., Any] | None = None) -> None:
        self.pipeline = pipeline
        self.model, self.data = mujoco_of(pipeline)
        self.feed = feed
        self.opt = options or LiveOptions()
        if self.opt.fps <= 0:
            raise GestureSimError(f"fps must be positive, got {self.opt.fps}")
        if self.opt.screenshot_mode not in ("render", "screen"):
            raise GestureSimError(f"screenshot mode must be 'render' or 'screen', got "
                                  f"{self.opt.screenshot_mode!r}")
        self._factory = viewer_factory
        self.clock = time.perf_counter
        self.labels = tuple(getattr(pipeline, "labels", ()) or ())
        self.style = clip_style(self.opt.style)
        self.paused = False
        self.show_keys = self.opt.show_keys
        self.stats = LiveStats()
        self._keys: queue.SimpleQueue[int] = queue.SimpleQueue()
        self._stop_reason: str | None = None
        self._started = False  # has the live clock started (first audio pushed)?
        self._base = 0.0  # t_live = wall - base once started
        self._audio_cursor = 0.0  # pipeline time of the next audio sample (s)
        self._audio_debt = 0.0  # audio (s) still to drop after a slip
        self._pause_started: float | None = None
        self._feed_paused = 0.0  # total pause time (s), for the feed clock
        self._pending_after_sync: list[KeyAction] = []

    # ---------------------------------------------------------------- keys and signals
    def key_callback(self, key: int) -> None:
        """Called by the viewer's render thread: queue the key, act on it in the loop."""
        self._keys.put(int(key))

    def request_stop(self, reason: str = "stopped") -> None:
        """Ask the loop to end after the current frame (thread-safe)."""
        if self._stop_reason is None:
            self._stop_reason = reason

    def _apply(self, action: KeyAction, wall: float) -> None:
        p = self.pipeline
        if action.kind == "style":
            self.style = round(clip_style(self.style + action.value), 3)
            p.set_style(self.style)
            self.stats.keys.append(f"style={self.style:.2f}")
        elif action.kind == "pause":
            self._set_paused(not self.paused, wall)
            self.stats.keys.append("pause" if self.paused else "resume")
        elif action.kind == "reset":
            p.reset()
            p.set_style(self.style)
            self._started = False  # the stream restarts at 0 with the next audio
            self._audio_cursor = 0.0
            self._audio_debt = 0.0
            self.stats.keys.append("reset")
        elif action.kind == "label" and action.label is not None:
            p.trigger_label(action.label)
            self.stats.keys.append(f"label={action.label}")
        elif action.kind == "help":
            self.show_keys = not self.show_keys

    def _set_paused(self, paused: bool, wall: float) -> None:
        if paused == self.paused:
            return
        self.paused = paused
        self.feed.set_paused(paused)
        if paused:
            self._pause_started = wall
        elif self._pause_started is not None:
            dt = wall - self._pause_started
            self._base += dt
            self._feed_paused += dt
            self.stats.paused_s += dt
            self._pause_started = None

    def _handle_keys(self, wall: float) -> None:
        for action in self._pending_after_sync:
            self._apply(action, wall)
        self._pending_after_sync = []
        while True:
            try:
                key = self._keys.get_nowait()
            except queue.Empty:
                return
            action = decode_key(key, self.labels)
            if action is None:
                continue
            if action.deferred:
                self._pending_after_sync.append(action)
            else:
                self._apply(action, wall)

    # ---------------------------------------------------------------- audio
    def _push_audio(self, blocks: list[AudioBlock], wall: float) -> None:
        """Re-stamp blocks onto the contiguous pipeline clock and push them."""
        for block in blocks:
            x = block.samples
            if self.paused:
                self.stats.audio_dropped_paused_s += len(x) / SAMPLE_RATE
                continue
            if self._audio_debt > 0:
                n_drop = min(len(x), int(round(self._audio_debt * SAMPLE_RATE)))
                x = x[n_drop:]
                self._audio_debt = 0.0 if n_drop == 0 else max(
                    self._audio_debt - n_drop / SAMPLE_RATE, 0.0)
                self.stats.audio_dropped_slip_s += n_drop / SAMPLE_RATE
                if len(x) == 0:
                    continue
            if not self._started:
                self._started = True
                self._base = wall - self._audio_cursor
            self.pipeline.push_audio(AudioBlock(x, self._audio_cursor))
            self._audio_cursor += len(x) / SAMPLE_RATE
            self.stats.audio_pushed_s += len(x) / SAMPLE_RATE

    # ---------------------------------------------------------------- main
    def run(self) -> LiveStats:
        """Open the viewer, run until the window closes, Ctrl-C, ``duration`` or the end of
        the file; return the statistics (also written to ``options.stats_path``)."""
        opt, p = self.opt, self.pipeline
        model, data = self.model, self.data
        st = self.stats
        st.maxrss_start_mb = _maxrss_mb()
        out = opt.out if opt.out is not None else sys.stdout
        if opt.print_keys:
            print("gesture-sim live - keys (in the viewer window):", file=out)
            for line in key_map_lines(self.labels):
                print(f"  {line}", file=out)
            print(f"audio: {self.feed.description}", file=out, flush=True)
        if opt.shadow_size:
            model.vis.quality.shadowsize = int(min(model.vis.quality.shadowsize,
                                                   opt.shadow_size))
        p.set_style(self.style)
        factory = self._factory
        if factory is None:
            import mujoco.viewer

            factory = mujoco.viewer.launch_passive
        shots = sorted((float(t), Path(pth)) for t, pth in opt.screenshots)
        taker = ScreenshotTaker(model, opt.screenshot_mode)
        old_sigint = None
        if threading.current_thread() is threading.main_thread():
            old_sigint = signal.signal(signal.SIGINT, self._on_sigint)
        before = set(threading.enumerate())
        viewer = None
        viewer_threads: set[threading.Thread] = set()
        pump = None
        try:
            self.feed.start()
            viewer = factory(model, data, key_callback=self.key_callback,
                             show_left_ui=False, show_right_ui=False)
            viewer_threads = set(threading.enumerate()) - before
            setup_camera(viewer, model, data)
            pump = _OverlayPump(viewer)
            # audio that arrived while the window opened is stale: drop it
            stale = self.feed.poll(0.0)
            st.audio_dropped_at_start_s = sum(len(b.samples) for b in stale) / SAMPLE_RATE
            self._loop(viewer, pump, taker, shots)
            if opt.final_screenshot is not None:
                taker.save(viewer, data, opt.final_screenshot)
                st.screenshots.append(str(opt.final_screenshot))
        finally:
            if pump is not None:
                pump.stop()
            self.feed.close()
            taker.close()
            if viewer is not None:
                with contextlib.suppress(Exception):
                    viewer.close()
            for th in viewer_threads:
                th.join(timeout=10.0)  # let GLFW shut down before the interpreter does
            if old_sigint is not None:
                signal.signal(signal.SIGINT, old_sigint)
            st.maxrss_end_mb = _maxrss_mb()
            st.source = self.feed.stats()
        if opt.stats_path is not None:
            atomic_write_text(opt.stats_path, json.dumps(st.to_dict(), indent=1) + "\n")
        return st

    def _on_sigint(self, signum: int, frame: Any) -> None:
        if self._stop_reason is not None:  # second Ctrl-C: stop now
            raise KeyboardInterrupt
        self.request_stop("interrupted (Ctrl-C)")

    def _should_stop(self, viewer: Any, wall: float, feed_t: float) -> bool:
        opt = self.opt
        if self._stop_reason is not None:
            return True
        if not viewer.is_running():
            self.request_stop("window closed")
        elif opt.duration is not None and wall >= opt.duration:
            self.request_stop("duration reached")
        elif isinstance(self.feed, FileFeed) and opt.duration is None and not self.paused \
                and self.feed.finished(feed_t - opt.tail_s):
            self.request_stop("end of audio")
        return self._stop_reason is not None

    def _loop(self, viewer: Any, pump: _OverlayPump, taker: ScreenshotTaker,
              shots: list[tuple[float, Path]]) -> None:
        opt, p, st, data = self.opt, self.pipeline, self.stats, self.data
        frame_dt = 1.0 / opt.fps
        timestep = float(self.model.opt.timestep)
        t0 = self.clock()
        deadline = t0
        last_sync: float | None = None
        next_rss = 0.0
        recent_rt: deque[tuple[float, float]] = deque(maxlen=int(opt.fps) + 1)
        t_live = 0.0
        while True:
            wall = self.clock() - t0
            feed_t = wall - self._feed_paused - (
                wall - self._pause_started if self._pause_started is not None else 0.0)
            if self._should_stop(viewer, wall, feed_t):
                break
            work_start = self.clock()
            self._push_audio(self.feed.poll(feed_t), wall)
            steps = 0
            if not self.paused:
                t_live = wall - self._base if self._started else 0.0
                t_before = float(data.time)
                lag = t_live - t_before
                if self._started and lag > opt.max_lag_s:
                    slip = lag - opt.max_lag_s  # give the excess up instead of catching up
                    self._base += slip
                    self._audio_debt += slip
                    st.slipped_s += slip
                    t_live -= slip
                p.advance(t_live)
                advanced = max(float(data.time) - t_before, 0.0)
                st.sim_s += advanced
                steps = int(round(advanced / timestep))
                st.steps.add(steps)
                if self._started:
                    st.lag.add(max(t_live - float(data.time), 0.0))
            fields = _status_fields(p.status())
            recent_rt.append((wall, st.sim_s))
            realtime = 0.0
            if len(recent_rt) > 1 and recent_rt[-1][0] > recent_rt[0][0]:
                realtime = (recent_rt[-1][1] - recent_rt[0][1]) / (recent_rt[-1][0]
                                                                   - recent_rt[0][0])
            pump.submit(viewer_texts(OverlayState(
                t=float(data.time), level_db=fields["level_db"], state=fields["state"],
                belief=fields["belief"], segment=fields["segment"],
                style=self.style if fields["style"] is None else float(fields["style"]),
                label=fields["label"], paused=self.paused, steps_per_frame=steps,
                realtime=realtime, source=self.feed.description,
            ), self.labels, show_keys=self.show_keys))
            st.work_ms.add(1e3 * (self.clock() - work_start))
            viewer.sync()
            synced = self.clock()
            if last_sync is not None:
                st.frame_dt.add(synced - last_sync)
            last_sync = synced
            st.frames += 1
            self._handle_keys(synced - t0)
            while shots and wall >= shots[0][0]:
                _, path = shots.pop(0)
                taker.save(viewer, data, path)
                st.screenshots.append(str(path))
                last_sync = None  # a screenshot's pause is not a frame time
            if wall >= next_rss:
                st.sample_rss(wall)
                next_rss = wall + RSS_PERIOD_S
            deadline += frame_dt
            now = self.clock()
            if deadline < now - frame_dt:  # more than a frame late: restart the schedule
                deadline = now
            time.sleep(max(deadline - now, 0.0))
        end = self.clock()
        if self._pause_started is not None:
            st.paused_s += end - t0 - self._pause_started
        st.wall_s = end - t0
        st.exit_reason = self._stop_reason or ""


def run_live(pipeline: Pipeline, feed: AudioFeed, options: LiveOptions | None = None,
             viewer_factory: Callable[..., Any] | None = None) -> LiveStats:
    """Run one live session (see :class:`LiveLoop`); returns its :class:`LiveStats`."""
    return LiveLoop(pipeline, feed, options, viewer_factory).run()
