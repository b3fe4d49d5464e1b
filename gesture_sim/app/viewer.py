"""Viewer helpers of the live loop: the display check, the overlay pump (viewer texts on
their own thread), the headless stand-in for a window (``live --headless``), the camera,
screenshots, and the MuJoCo model and data of a pipeline."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import sys
import threading
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import atomic_path

#: Viewer camera: distance (m), azimuth and elevation (degrees), look-at height above the root.
CAMERA_DISTANCE_M = 3.0
CAMERA_AZIMUTH_DEG = 195.0
CAMERA_ELEVATION_DEG = -8.0
CAMERA_LOOKAT_DZ_M = 0.2


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


class OverlayPump:
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


class HeadlessViewer:
    """The live loop's viewer when there is no window (``live --headless``): always running,
    nothing drawn (``sync`` does nothing), no keys; a camera (for ``--screenshot``, drawn
    offscreen by :class:`ScreenshotTaker`) and the viewer's lock. Made with the signature of
    ``mujoco.viewer.launch_passive`` (:meth:`launch`)."""

    def __init__(self) -> None:
        self.cam = mujoco.MjvCamera()
        self.viewport = None
        self._lock = threading.Lock()
        self._running = True

    @classmethod
    def launch(cls, model: mujoco.MjModel, data: mujoco.MjData, **kwargs: Any) -> HeadlessViewer:
        """A new headless viewer (``model``, ``data`` and the keyword arguments are unused)."""
        return cls()

    def lock(self) -> threading.Lock:
        return self._lock

    def is_running(self) -> bool:
        return self._running

    def sync(self) -> None:
        """Nothing to draw."""

    def set_texts(self, texts: Any) -> None:
        """No overlay to show."""

    def close(self) -> None:
        self._running = False


class NullPump:
    """:class:`OverlayPump`'s interface for a loop without a window: nothing is submitted."""

    updates = 0

    def submit(self, texts: list[Any]) -> None:
        """Drop the texts."""

    def stop(self) -> None:
        """Nothing to stop."""


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
