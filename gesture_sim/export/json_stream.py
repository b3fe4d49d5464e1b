"""The body's pose, live, as plain JSON over UDP: ``gesture-sim live --stream json://HOST:PORT``.

For any program that is not a VMC receiver (a web page behind a small relay, a game engine
script, a robot, a logger): one UDP datagram per frame of the stream's clock (60 Hz by default,
``live --stream-rate``), holding one compact JSON object
(UTF-8, no whitespace, floats rounded to :data:`DIGITS` decimals)::

    {"format": "gesture_sim.pose_stream", "version": 1,
     "t": 1.2345,            # simulation (stream) time of the pose, s; 0 again after a reset
     "wall": 3.21,           # seconds since the sender started (wall clock)
     "frame": 42,            # this sender's frame counter, from 0, one per frame;
                             # a gap: frames dropped (see the live stats)
     "root": {"pos": [x, y, z], "quat": [w, x, y, z]},
                             # the humanoid's free root joint (the pelvis body) in MuJoCo's
                             # world: x forward, y left, z up, metres; orientation w x y z
     "joints": {"lower_spine_flex": 0.01, ...},
                             # every actuated joint (gesture_sim.sim.humanoid.ACTUATED_JOINTS,
                             # in that order): its qpos value, rad (hinges) or m (slides)
     "bones": {"Hips": [w, x, y, z], "Spine": [...], ..., "Jaw": [...]},
                             # the VMC bones (gesture_sim.export.vmc.BONE_NAMES, Unity
                             # HumanBodyBones names, 23): local rotation relative to the parent
                             # bone (Hips: global), against a T-pose rest whose bones are aligned
                             # with the avatar's axes, unit quaternion w x y z with w >= 0
     "hips": [x, y, z],      # the Hips bone's position (the humanoid's pelvis), m
     "blends": {"A": 0.3, "Blink_L": 0.0, "Blink_R": 0.0}}
                             # mouth open and eyelids closed, 0 ... 1

Axes of ``bones`` and ``hips``: right-handed, Y up, the avatar facing +Z with its left towards
+X: glTF's (and three.js's, Blender's glTF importer's) character convention; the VMC stream
sends the same rotations mirrored into Unity's left-handed axes. ``root`` and ``joints`` are
the MuJoCo state itself: with the project's model (``gesture_sim.sim.humanoid.load_model``) they
reproduce the pose exactly.

``bones``, ``hips`` and ``blends`` come from the same per-frame computation as the VMC stream
(:meth:`gesture_sim.export.vmc.VmcPose.bone_pose`), so the two streams agree.

A datagram is about 4 KB (measured 3.8-4.4 KB over random poses with the 105 actuated joints
of the humanoid with fingers, 2.8-3.2 KB with the 65 of the mitten-handed one; the joints take
~30 bytes each; under :data:`MAX_DATAGRAM`, 8 KB, checked in the tests): one message, never
split, small enough for any receiver's buffer. Over a network a datagram above
the path MTU (~1.5 KB) is fragmented by IP, which loopback and LANs handle; a lossy link loses
whole frames, never half ones.

Sending never blocks (non-blocking UDP) and never raises: a refused datagram or a non-finite
pose drops the frame, counted in :meth:`JsonSender.stats` (``frames_sent``,
``frames_dropped``, ``last_error``), which the live loop reports under ``stream``.

A receiver in Python::

    import json, socket
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind(("127.0.0.1", 39540))
    while True:
        msg = json.loads(s.recv(65536))
        print(msg["t"], msg["bones"]["RightLowerArm"])
"""

from __future__ import annotations

import json
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.export.vmc import BONE_NAMES, UdpPoseSender
from gesture_sim.sim.humanoid import ACTUATED_JOINTS

#: ``format`` and ``version`` of every message.
FORMAT = "gesture_sim.pose_stream"
VERSION = 1
#: Decimals of every float sent (1e-5 rad, 10 µm).
DIGITS = 5
#: The size a datagram must stay under (bytes); a message is ~4 KB.
MAX_DATAGRAM = 8192
#: The usual port of this stream in the examples (the VMC port + 1).
DEFAULT_PORT = 39540


def _rounded(values: np.ndarray) -> list[float]:
    """A flat list of Python floats rounded to :data:`DIGITS` decimals (-0.0 as 0.0)."""
    return (np.round(np.ravel(values), DIGITS) + 0.0).tolist()


class JsonSender(UdpPoseSender):
    """Sends the humanoid's pose as one JSON datagram per frame to ``address`` (``HOST:PORT``;
    see the module docstring for the message; :class:`~gesture_sim.export.vmc.UdpPoseSender`
    for the sending, which never blocks nor raises).

    Args:
        address: where the receiver listens.
    """

    protocol = "json"

    def __init__(self, address: str) -> None:
        super().__init__(address)
        self._joint_model: mujoco.MjModel | None = None
        self._joint_qadr = np.zeros(0, dtype=int)
        self._root_qadr = 0

    def _addresses(self, model: mujoco.MjModel) -> None:
        if self._joint_model is model:
            return
        self._joint_qadr = np.array([int(model.jnt_qposadr[model.joint(n).id])
                                     for n in ACTUATED_JOINTS], dtype=int)
        self._root_qadr = self.pose_of(model).transfer.root_qadr
        self._joint_model = model

    def prepare(self, model: mujoco.MjModel) -> None:
        """Build the per-frame pose computation and the joint addresses for ``model`` now
        (see :meth:`UdpPoseSender.prepare`)."""
        self._addresses(model)

    def message(self, model: mujoco.MjModel, qpos: np.ndarray, t: float) -> dict[str, Any]:
        """The JSON object (a dict) of one qpos row (nq,) of ``model`` at stream time ``t``
        (s), numbers rounded to :data:`DIGITS` decimals."""
        import time

        self._addresses(model)
        qpos = np.asarray(qpos, dtype=float)
        local, hips, blends = self.pose_of(model).bone_pose(qpos)
        quats = Rotation.from_matrix(local).as_quat(scalar_first=True)
        quats *= np.where(quats[:, :1] < 0, -1.0, 1.0)
        r, n_b, n_j = self._root_qadr, len(BONE_NAMES), len(ACTUATED_JOINTS)
        # every float rounded at once: bones (4 each), joints, root (7), hips (3), blends
        x = _rounded(np.concatenate([quats.ravel(), qpos[self._joint_qadr], qpos[r : r + 7],
                                     hips, list(blends.values())]))
        j0, r0 = 4 * n_b, 4 * n_b + n_j
        return {
            "format": FORMAT, "version": VERSION,
            "t": round(float(t), DIGITS), "wall": round(time.perf_counter() - self._t0, DIGITS),
            "frame": self.frames_sent + self.frames_dropped,   # this send's index
            "root": {"pos": x[r0 : r0 + 3], "quat": x[r0 + 3 : r0 + 7]},
            "joints": dict(zip(ACTUATED_JOINTS, x[j0:r0], strict=True)),
            "bones": {n: x[4 * i : 4 * i + 4] for i, n in enumerate(BONE_NAMES)},
            "hips": x[r0 + 7 : r0 + 10],
            "blends": dict(zip(blends, x[r0 + 10 :], strict=True)),
        }

    def encode(self, message: dict[str, Any]) -> bytes:
        """A message as the datagram's bytes (compact UTF-8 JSON)."""
        return json.dumps(message, separators=(",", ":"), allow_nan=False).encode("utf-8")

    def datagrams(self, model: mujoco.MjModel, qpos: np.ndarray, t: float) -> list[bytes]:
        """One datagram: the frame's message."""
        return [self.encode(self.message(model, qpos, t))]

    def __enter__(self) -> JsonSender:
        return self
