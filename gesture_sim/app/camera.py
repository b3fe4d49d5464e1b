"""Camera plans for offline rendering: a named model camera, or a smooth pelvis-tracking view.

A :class:`CameraPlan` is computed once for the whole pose sequence, before the frames are split
between render workers, so that every worker sees exactly the same camera path (no seams at
chunk boundaries).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from gesture_sim.errors import GestureSimError

#: The reserved camera name that selects the pelvis-tracking free camera.
TRACK = "track"

#: Tracking-camera defaults: distance (m), azimuth and elevation (degrees, MuJoCo's free-camera
#: convention: azimuth 180 looks along -x, i.e. from +x at a humanoid facing +x), the height of
#: the look-at point above the root (m, roughly chest height for a pelvis root) and the time
#: constant of the look-at smoothing (s).
TRACK_DISTANCE_M = 3.2
TRACK_AZIMUTH_DEG = 195.0
TRACK_ELEVATION_DEG = -6.0
TRACK_HEIGHT_OFFSET_M = 0.3
TRACK_TIME_CONSTANT_S = 0.5


@dataclass(frozen=True)
class CameraPlan:
    """How to place the camera for every frame.

    Attributes:
        camera_id: index of a fixed model camera, or -1 for the tracking free camera.
        lookat: shape (n_frames, 3), the tracking camera's look-at point per frame (m, world
            frame); ``None`` for a fixed camera.
        distance, azimuth, elevation: the tracking camera's orbit (m, degrees, degrees).
    """

    camera_id: int
    lookat: np.ndarray | None = None
    distance: float = TRACK_DISTANCE_M
    azimuth: float = TRACK_AZIMUTH_DEG
    elevation: float = TRACK_ELEVATION_DEG

    def slice(self, start: int, stop: int) -> CameraPlan:
        """The plan for frames ``start:stop`` (what one render worker needs)."""
        if self.lookat is None:
            return self
        return CameraPlan(self.camera_id, self.lookat[start:stop].copy(), self.distance,
                          self.azimuth, self.elevation)

    def configure(self, cam: mujoco.MjvCamera, frame: int) -> None:
        """Set ``cam`` for frame index ``frame`` (relative to this plan's first frame)."""
        if self.lookat is None:
            cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
            cam.fixedcamid = self.camera_id
            return
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = self.lookat[frame]
        cam.distance = self.distance
        cam.azimuth = self.azimuth
        cam.elevation = self.elevation


def root_positions(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """World positions of the first free joint's body, shape (n_frames, 3) in metres.

    Read straight from ``qpos`` (a free joint's first three coordinates are its body's world
    position). A model without a free joint gives its static centre for every frame.
    """
    free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    if free.size == 0:
        return np.tile(np.asarray(model.stat.center, dtype=float), (len(qpos), 1))
    adr = int(model.jnt_qposadr[free[0]])
    return np.asarray(qpos[:, adr : adr + 3], dtype=float)


def smooth(points: np.ndarray, fps: float, time_constant_s: float) -> np.ndarray:
    """First-order low-pass of a (n, 3) path sampled at ``fps``; starts at the first point.

    The filter runs forward then backward (zero phase), so the camera neither lags behind the
    body nor jumps; a time constant of 0 returns the path unchanged.
    """
    if time_constant_s <= 0 or len(points) < 2:
        return points.copy()
    alpha = 1.0 - np.exp(-1.0 / (fps * time_constant_s))

    def one_pass(x: np.ndarray) -> np.ndarray:
        y = np.empty_like(x)
        y[0] = x[0]
        for i in range(1, len(x)):  # n is a few thousand frames: a plain loop is fine
            y[i] = y[i - 1] + alpha * (x[i] - y[i - 1])
        return y

    return one_pass(one_pass(points)[::-1])[::-1]


def plan_camera(model: mujoco.MjModel, camera: str, qpos: np.ndarray, fps: float) -> CameraPlan:
    """A camera plan for ``qpos`` (shape (n_frames, model.nq), sampled at ``fps`` Hz).

    ``camera`` is the name of a camera in the model (e.g. ``"front"``) or :data:`TRACK` for a
    free camera whose look-at point follows the root body, smoothed with
    :data:`TRACK_TIME_CONSTANT_S`.
    """
    if camera == TRACK:
        lookat = smooth(root_positions(model, qpos), fps, TRACK_TIME_CONSTANT_S)
        lookat[:, 2] += TRACK_HEIGHT_OFFSET_M
        return CameraPlan(-1, lookat)
    cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    if cam_id < 0:
        names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(model.ncam)]
        choices = ", ".join([n for n in names if n] + [TRACK])
        raise GestureSimError(f"no camera named {camera!r} in the model (choose from: {choices})")
    return CameraPlan(int(cam_id))
