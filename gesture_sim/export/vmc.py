"""The body's pose, live, to another program: the VMC protocol (Virtual Motion Capture) over OSC.

VMC is what VRM avatar applications (VSeeFace, VirtualMotionCapture, Warudo, VMagicMirror …) and
their Unity/Unreal/Blender receivers (EVMC4U, VMC4B …) read: OSC 1.0 messages over UDP, by
default to port 39539. :class:`VmcSender` sends one frame of the humanoid's pose per call (the
live loop's :class:`gesture_sim.app.pose_clock.ClockedStream` calls it at a fixed rate, 60 Hz by
default, in a forked sender process, from the latest simulated state: ``gesture-sim live --stream
HOST:PORT`` or ``vmc://HOST:PORT``; ``json://HOST:PORT`` sends the same per-frame pose as plain
JSON instead, :mod:`gesture_sim.export.json_stream`; ``streams.open_stream`` chooses). A frame is
a few OSC bundles (each at most :data:`MAX_PACKET` bytes, so that none is fragmented on an
Ethernet or Wi-Fi link; a receiver handles every message on its own) holding, in this order:

* ``/VMC/Ext/Root/Pos`` ``s"root"`` ``f px py pz qx qy qz qw``: the avatar's root transform,
  which stays at the origin, unrotated (the stage is the receiver's);
* ``/VMC/Ext/Bone/Pos`` ``s NAME`` ``f px py pz qx qy qz qw`` for every bone of
  :data:`BONES` (Unity ``HumanBodyBones`` names): the bone's local position and rotation
  relative to its parent. Rotations are relative to a T-pose whose every bone is aligned with
  the avatar's axes (the rest of a normalised VRM 0.x model, which is what VMC applications
  load), so a receiver applies them as ``localRotation``. ``Hips`` carries the body's
  translation (the pelvis, scaled to the rig's leg length: feet on the floor);
* ``/VMC/Ext/Blend/Val`` ``s NAME f VALUE`` for ``A`` (mouth open: ``jaw_open`` over its joint
  range), ``Blink_L`` and ``Blink_R`` (the eyelids' travel over theirs), 0 … 1, then
  ``/VMC/Ext/Blend/Apply``;
* ``/VMC/Ext/OK`` ``i 1`` (a model is loaded) and ``/VMC/Ext/T`` ``f``: the simulation time of
  the pose (s; the stream's time, 0 again after a reset), or the seconds since the sender started
  for a bare qpos row sent without a time.

Coordinates: Unity's, left-handed, Y up, metres, the avatar facing +Z with its left towards −X.
The pose comes from :class:`gesture_sim.export.PoseTransfer` with the Mixamo rig's table
(:func:`gesture_sim.export.mixamo.mixamo_follow`, whose rest is the same kind of T-pose): every
bone points where the humanoid's points, its roll from the humanoid body that drives it. Its
target axes (X left, Y up, Z forward, right-handed) become Unity's by mirroring X:
``p_unity = U p``, ``R_unity = U R U`` with ``U = diag(-1, 1, 1)``.

What is approximate (beyond :mod:`gesture_sim.export.mixamo`'s own notes):

* **Bone positions** are the Mixamo rig's rest offsets (a 1.73 m MakeHuman body), not the
  receiver's avatar's; receivers that apply bone positions (an option in most) get that body's
  proportions, and ``Hips`` at the rig's height. Rotations do not depend on it.
* **Jaw**: the humanoid's ``jaw_open`` hinge as a rotation about the head's left-right axis
  (its hinge axis at rest); the eyes are not sent (the humanoid has none), so the receiver
  keeps its own. The fingers are sent (Unity's Proximal, Intermediate and Distal of each: the
  rig's three finger joints, following the humanoid's fingers as in the Mixamo BVH).
* **Chest/UpperChest**: the rig's ``Spine1``/``Spine2``; an avatar without ``UpperChest`` (it
  is optional in VRM) loses that bone's share of the spine's bend.

Sending never blocks (a non-blocking UDP socket) and never raises: a datagram the system refuses
(a full buffer, no route) drops the frame, counted in :meth:`VmcSender.stats`. A frame costs the
loop ~0.7 ms on an idle 2-core machine (1.6-2.5 ms with a test suite running beside it; the
viewer kept 59 fps, physics lag and slips unchanged, against the same run without a stream).

The OSC encoding is written here (OSC 1.0: strings NUL-terminated and padded to 4 bytes,
big-endian int32/float32, ``,sff…`` type tags, bundles ``#bundle`` + 64-bit time tag + sized
elements); :func:`decode_packet` reads it back (for the tests and for debugging).
"""

from __future__ import annotations

import functools
import socket
import struct
import time
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.export import MJ_TO_TARGET, PoseTransfer, TargetSkeleton
from gesture_sim.export.mixamo import PREFIX, mixamo_follow, mixamo_skeleton, root_scale

#: The VMC receivers' usual port.
DEFAULT_PORT = 39539
DEFAULT_ADDRESS = f"127.0.0.1:{DEFAULT_PORT}"
#: Largest datagram sent (bytes): an Ethernet MTU (1500) less IP and UDP headers, with margin.
MAX_PACKET = 1400
#: OSC time tag "immediately".
IMMEDIATELY = 1

#: Unity HumanBodyBones name -> the Mixamo rig joint whose pose it takes (``Jaw`` is separate).
BONES: dict[str, str] = {
    "Hips": "Hips", "Spine": "Spine", "Chest": "Spine1", "UpperChest": "Spine2",
    "Neck": "Neck", "Head": "Head",
    **{f"{s}{vmc}": f"{s}{rig}" for s in ("Left", "Right") for vmc, rig in (
        ("Shoulder", "Shoulder"), ("UpperArm", "Arm"), ("LowerArm", "ForeArm"),
        ("Hand", "Hand"), ("UpperLeg", "UpLeg"), ("LowerLeg", "Leg"), ("Foot", "Foot"),
        ("Toes", "ToeBase"))},
    # the fingers (Unity's thumb "Proximal" is its metacarpal joint, as the Mixamo rig's Thumb1)
    **{f"{s}{vmc}{part}": f"{s}Hand{rig}{k}" for s in ("Left", "Right")
       for vmc, rig in (("Thumb", "Thumb"), ("Index", "Index"), ("Middle", "Middle"),
                        ("Ring", "Ring"), ("Little", "Pinky"))
       for k, part in ((1, "Proximal"), (2, "Intermediate"), (3, "Distal"))},
}
#: Every bone sent, in the order sent (parents before children; ``Jaw`` last).
BONE_NAMES: tuple[str, ...] = (*BONES, "Jaw")
#: Blend shape (VRM 0.x preset) -> the humanoid joint whose travel over its range gives it.
BLENDS: dict[str, str] = {"A": "jaw_open", "Blink_L": "left_eyelid_close",
                          "Blink_R": "right_eyelid_close"}
#: Target axes (X left) -> Unity axes (X right): the mirror U.
TO_UNITY = np.diag([-1.0, 1.0, 1.0])


# ============================================================================================
# OSC 1.0
# ============================================================================================


def osc_string(s: str) -> bytes:
    """An OSC string: UTF-8, NUL-terminated, padded with NULs to a multiple of 4 bytes."""
    b = s.encode("utf-8")
    if b"\0" in b:
        raise GestureSimError(f"OSC strings cannot hold NUL characters: {s!r}")
    return b + b"\0" * (4 - len(b) % 4)


def osc_blob(b: bytes) -> bytes:
    """An OSC blob: int32 size, the bytes, NUL padding to a multiple of 4."""
    return struct.pack(">i", len(b)) + b + b"\0" * (-len(b) % 4)


def osc_message(address: str, *args: Any) -> bytes:
    """One OSC message: address, type tags (``,`` then ``s`` str, ``i`` int, ``f`` float,
    ``b`` bytes; ``T``/``F`` for bools), arguments (big-endian int32 / float32)."""
    if not address.startswith("/"):
        raise GestureSimError(f"an OSC address starts with '/': {address!r}")
    tags, body = [","], []
    for a in args:
        if isinstance(a, bool):
            tags.append("T" if a else "F")
        elif isinstance(a, (int, np.integer)):
            tags.append("i")
            body.append(struct.pack(">i", int(a)))
        elif isinstance(a, (float, np.floating)):
            tags.append("f")
            body.append(struct.pack(">f", float(a)))
        elif isinstance(a, str):
            tags.append("s")
            body.append(osc_string(a))
        elif isinstance(a, (bytes, bytearray)):
            tags.append("b")
            body.append(osc_blob(bytes(a)))
        else:
            raise GestureSimError(f"cannot send {type(a).__name__} in an OSC message")
    return osc_string(address) + osc_string("".join(tags)) + b"".join(body)


def _floats_message(head: bytes, values) -> bytes:
    """A message whose encoded address, type tags and leading string are ``head``, followed by
    float32 ``values`` (the fast path for the per-bone messages)."""
    return head + struct.pack(f">{len(values)}f", *values)


@functools.lru_cache(maxsize=64)
def _bone_head(address: str, name: str, n_floats: int) -> bytes:
    return osc_string(address) + osc_string(",s" + "f" * n_floats) + osc_string(name)


BUNDLE_TAG = osc_string("#bundle")


def osc_bundle(elements, timetag: int = IMMEDIATELY) -> bytes:
    """An OSC bundle: ``#bundle``, the 64-bit NTP time tag (1 = immediately), then every
    element (an encoded message or bundle) preceded by its int32 size."""
    return BUNDLE_TAG + struct.pack(">Q", timetag) + b"".join(
        struct.pack(">i", len(e)) + e for e in elements)


def pack_bundles(messages, max_bytes: int = MAX_PACKET) -> list[bytes]:
    """Encoded messages, in order, into as few bundles as fit ``max_bytes`` each (a message too
    big for one gets a bundle of its own)."""
    out, cur, size = [], [], 16
    for m in messages:
        if cur and size + 4 + len(m) > max_bytes:
            out.append(osc_bundle(cur))
            cur, size = [], 16
        cur.append(m)
        size += 4 + len(m)
    if cur:
        out.append(osc_bundle(cur))
    return out


def _read_string(buf: bytes, i: int) -> tuple[str, int]:
    end = buf.index(b"\0", i)
    return buf[i:end].decode("utf-8"), (end // 4 + 1) * 4


def decode_message(buf: bytes) -> tuple[str, list[Any]]:
    """(address, arguments) of one encoded OSC message (tags ``s i f b T F`` and ``d h``)."""
    try:
        address, i = _read_string(buf, 0)
        tags, i = _read_string(buf, i)
        if not tags.startswith(","):
            raise ValueError(f"type tags {tags!r} do not start with ','")
        args: list[Any] = []
        for t in tags[1:]:
            if t == "s":
                s, i = _read_string(buf, i)
                args.append(s)
            elif t in "if":
                args.append(struct.unpack_from(">i" if t == "i" else ">f", buf, i)[0])
                i += 4
            elif t in "dh":
                args.append(struct.unpack_from(">d" if t == "d" else ">q", buf, i)[0])
                i += 8
            elif t == "b":
                (n,) = struct.unpack_from(">i", buf, i)
                args.append(buf[i + 4 : i + 4 + n])
                i += 4 + n + (-n % 4)
            elif t in "TF":
                args.append(t == "T")
            else:
                raise ValueError(f"unknown type tag {t!r}")
        if i > len(buf):
            raise ValueError("message truncated")
    except (ValueError, struct.error, UnicodeDecodeError) as exc:
        raise GestureSimError(f"malformed OSC message: {exc}") from exc
    return address, args


def decode_packet(buf: bytes) -> list[tuple[str, list[Any]]]:
    """Every message of an OSC packet (a message, or a bundle, nested bundles flattened)."""
    if not buf.startswith(b"#bundle\0"):
        return [decode_message(buf)]
    out, i = [], 16
    if len(buf) < 16:
        raise GestureSimError("malformed OSC bundle: no time tag")
    while i < len(buf):
        if i + 4 > len(buf):
            raise GestureSimError("malformed OSC bundle: truncated element size")
        (n,) = struct.unpack_from(">i", buf, i)
        if n < 0 or i + 4 + n > len(buf):
            raise GestureSimError("malformed OSC bundle: element runs past the packet")
        out += decode_packet(buf[i + 4 : i + 4 + n])
        i += 4 + n
    return out


# ============================================================================================
# The pose
# ============================================================================================


def parse_address(address: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[IPv6]:PORT`` for an IPv6 literal) -> (host, port)."""
    hint = f"expected HOST:PORT (e.g. {DEFAULT_ADDRESS}), got {address!r}"
    host, sep, port = str(address).strip().rpartition(":")
    if not sep or not host or not port.isdigit():
        raise GestureSimError(f"stream address: {hint}")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    elif ":" in host:
        raise GestureSimError(f"stream address: {hint} (write an IPv6 address in brackets)")
    if not 1 <= int(port) <= 65535:
        raise GestureSimError(f"stream address: port {port} is not in 1-65535")
    return host, int(port)


def _quat_xyzw(mats: np.ndarray) -> np.ndarray:
    """Unit quaternions (N, 4) x y z w of rotation matrices (N, 3, 3), w >= 0."""
    q = Rotation.from_matrix(mats).as_quat()
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


class VmcPose:
    """The VMC bones of one humanoid pose: :meth:`PoseTransfer.pose` with the Mixamo rig's
    table (vectorised over joints: ~0.3-0.5 ms a frame, within a live frame's budget), the
    rig joints of :data:`BONES` picked out, the jaw and the blend shapes added.

    Args:
        model: the humanoid model (the body alone or the scene with it).
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        skeleton, _ = mixamo_skeleton()
        self.model = model
        self.skeleton: TargetSkeleton = skeleton
        self.transfer = PoseTransfer(model, skeleton, mixamo_follow())
        self.scale = root_scale(model, skeleton)
        sk = skeleton
        self._bones = [sk.index(PREFIX + BONES[n]) for n in BONES]
        # joint offsets in Unity axes (the rig's rest: local positions of the bones)
        self._offsets = sk.offsets[self._bones] @ TO_UNITY
        head, jaw = model.body("head"), model.body("jaw")
        self._jaw_offset = TO_UNITY @ MJ_TO_TARGET @ (jaw.pos if jaw.parentid == head.id
                                                       else np.zeros(3))
        self._qadr = {n: int(model.jnt_qposadr[model.joint(j).id]) for n, j in BLENDS.items()}
        self._range = {n: float(model.jnt_range[model.joint(j).id][1]) for n, j in
                       BLENDS.items()}

    def local(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The VMC bones' rig joints for one qpos row (nq,), in :data:`BONES` order: local
        rotations (B, 3, 3) (relative to the parent; the root's: global) and global ones
        (B, 3, 3) in target axes, and the root point (3,) in target axes (m, unscaled)."""
        local, glob, root = self.transfer.pose(np.asarray(qpos, dtype=float)[None])
        return local[0, self._bones], glob[0, self._bones], root[0]

    def bone_pose(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
        """The per-frame pose every stream sends (VMC here, JSON in
        :mod:`gesture_sim.export.json_stream`), computed once: for one qpos row, the local
        rotations (len(BONE_NAMES), 3, 3) of :data:`BONE_NAMES` in target axes (X left, Y up,
        Z forward; relative to the parent bone, ``Hips``: global; ``Jaw``: the ``jaw_open``
        hinge about the head's left axis), the ``Hips`` point (3,) in target axes (m, the
        humanoid's, unscaled), and blend shape name -> value 0 … 1 (:data:`BLENDS`)."""
        qpos = np.asarray(qpos, dtype=float)
        local, _, root = self.local(qpos)
        mats = np.empty((len(BONE_NAMES), 3, 3))
        mats[: len(self._bones)] = local
        jaw = float(qpos[self._qadr["A"]])
        # about the left axis: U Rx U = Rx, so the same matrix in target and Unity axes
        c, s = np.cos(jaw), np.sin(jaw)
        mats[-1] = ((1.0, 0.0, 0.0), (0.0, c, -s), (0.0, s, c))
        blends = {n: float(np.clip(qpos[a] / self._range[n], 0.0, 1.0)) if self._range[n] > 0
                  else 0.0 for n, a in self._qadr.items()}
        return mats, root, blends

    def frame(self, qpos: np.ndarray) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]],
                                               dict[str, float]]:
        """The VMC frame of one qpos row: bone name -> (local position (3,), local rotation
        quaternion x y z w (4,)) in Unity axes, and blend shape name -> value 0 … 1."""
        local, root, blends = self.bone_pose(qpos)
        U = TO_UNITY
        quats = _quat_xyzw(U @ local @ U)
        pos = np.empty((len(BONE_NAMES), 3))
        pos[: len(self._bones)] = self._offsets
        pos[0] = U @ root * self.scale                                  # Hips: the translation
        pos[-1] = self._jaw_offset
        bones = {n: (pos[i], quats[i]) for i, n in enumerate(BONE_NAMES)}
        return bones, blends


def frame_messages(bones: dict[str, tuple[np.ndarray, np.ndarray]], blends: dict[str, float],
                   t: float) -> list[bytes]:
    """The encoded messages of one VMC frame (see the module docstring for the order)."""
    msgs = [osc_message("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)]
    for name, (p, q) in bones.items():
        msgs.append(_floats_message(_bone_head("/VMC/Ext/Bone/Pos", name, 7),
                                    (*p.tolist(), *q.tolist())))
    for name, v in blends.items():
        msgs.append(_floats_message(_bone_head("/VMC/Ext/Blend/Val", name, 1), (v,)))
    msgs += [osc_message("/VMC/Ext/Blend/Apply"), osc_message("/VMC/Ext/OK", 1),
             osc_message("/VMC/Ext/T", float(t))]
    return msgs


# ============================================================================================
# The sender
# ============================================================================================


class UdpPoseSender:
    """Sends the humanoid's pose, one frame per :meth:`send`, as UDP datagrams to ``address``
    (``HOST:PORT``): the socket, the counting and the statistics that :class:`VmcSender` and
    :class:`gesture_sim.export.json_stream.JsonSender` share; a subclass says what a frame's
    datagrams are (:meth:`datagrams`).

    The address is resolved once, here (a bad one: :class:`GestureSimError`); sending never
    blocks and never raises (see :meth:`send`). Use as a context manager or call :meth:`close`.

    Args:
        address: where the receiver listens.
    """

    #: the ``protocol`` of :meth:`stats`
    protocol = "udp"

    def __init__(self, address: str) -> None:
        host, port = parse_address(address)
        try:
            infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except (socket.gaierror, UnicodeError) as exc:
            raise GestureSimError(f"stream address {address!r}: cannot resolve {host!r} "
                                  f"({exc})") from exc
        family, _, _, _, sockaddr = infos[0]
        try:
            self._sock = socket.socket(family, socket.SOCK_DGRAM)
        except OSError as exc:
            raise GestureSimError(f"stream address {address!r}: cannot open a UDP socket "
                                  f"({exc})") from exc
        self._sock.setblocking(False)
        self.address = address
        self.sockaddr = sockaddr
        self._pose: VmcPose | None = None
        self._t0 = time.perf_counter()
        self.frames_sent = 0
        self.frames_dropped = 0
        self.packets_sent = 0
        self.bytes_sent = 0
        self.packet_bytes_max = 0
        self.last_error = ""
        self.send_ms_max = 0.0
        self._send_s = 0.0

    def pose_of(self, model: mujoco.MjModel) -> VmcPose:
        """The (cached) per-frame pose computation for ``model``."""
        if self._pose is None or self._pose.model is not model:
            self._pose = VmcPose(model)
        return self._pose

    def prepare(self, model: mujoco.MjModel) -> None:
        """Build the per-frame pose computation for ``model`` now (the rig and its rest
        calibration: ~0.1-1 s), so that the first :meth:`send` costs what the others do (the
        live loop calls this before its first frame)."""
        self.pose_of(model)

    def datagrams(self, model: mujoco.MjModel, qpos: np.ndarray, t: float) -> list[bytes]:
        """The datagrams of one frame: a qpos row (nq,) of ``model`` at stream time ``t``
        (s)."""
        raise NotImplementedError

    def send(self, model: mujoco.MjModel, data: mujoco.MjData | np.ndarray,
             t: float | None = None) -> bool:
        """Send a pose as one frame: ``data.qpos`` at ``data.time``, or a qpos row (nq,) at
        simulation time ``t`` (s; ``None``: the time since the sender started); True when
        every datagram went out. A frame the system refuses (full buffer, no route …) or a
        non-finite pose is dropped and counted; nothing is raised for either."""
        start = time.perf_counter()
        if isinstance(data, mujoco.MjData):
            qpos = np.asarray(data.qpos, dtype=float)
            t = float(data.time) if t is None else float(t)
        else:
            qpos = np.asarray(data, dtype=float)
            t = start - self._t0 if t is None else float(t)
        ok = False
        if not np.all(np.isfinite(qpos)):
            self.last_error = "non-finite pose"
        else:
            try:
                for pkt in self.datagrams(model, qpos, t):
                    self._sock.sendto(pkt, self.sockaddr)
                    self.packets_sent += 1
                    self.bytes_sent += len(pkt)
                    self.packet_bytes_max = max(self.packet_bytes_max, len(pkt))
                ok = True
            except OSError as exc:          # BlockingIOError, ECONNREFUSED, ENETUNREACH …
                self.last_error = f"{type(exc).__name__}: {exc}"
        if ok:
            self.frames_sent += 1
        else:
            self.frames_dropped += 1
        dt = time.perf_counter() - start
        self._send_s += dt
        self.send_ms_max = max(self.send_ms_max, 1e3 * dt)
        return ok

    def stats(self) -> dict[str, Any]:
        """JSON-ready figures: protocol, address, frames sent/dropped, datagrams, bytes (total
        and the largest datagram), time per frame (ms)."""
        n = self.frames_sent + self.frames_dropped
        return {"protocol": self.protocol, "address": self.address,
                "frames_sent": self.frames_sent, "frames_dropped": self.frames_dropped,
                "packets_sent": self.packets_sent, "bytes_sent": self.bytes_sent,
                "packet_bytes_max": self.packet_bytes_max,
                "send_ms_mean": round(1e3 * self._send_s / n, 3) if n else 0.0,
                "send_ms_max": round(self.send_ms_max, 3),
                "last_error": self.last_error}

    def close(self) -> None:
        """Close the socket (idempotent)."""
        self._sock.close()

    def __enter__(self) -> UdpPoseSender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class VmcSender(UdpPoseSender):
    """Sends the humanoid's pose as VMC frames to ``address`` (``HOST:PORT``) over UDP (see
    :class:`UdpPoseSender` for the sending; ``/VMC/Ext/T`` is the pose's simulation time).

    Args:
        address: where the receiver listens (default ``127.0.0.1:39539``).
        max_packet: largest datagram (bytes); a frame takes as many bundles as it needs.
    """

    protocol = "vmc"

    def __init__(self, address: str = DEFAULT_ADDRESS, max_packet: int = MAX_PACKET) -> None:
        super().__init__(address)
        self.max_packet = int(max_packet)

    def packets(self, model: mujoco.MjModel, qpos: np.ndarray,
                t: float | None = None) -> list[bytes]:
        """The datagrams of one frame for a qpos row of ``model`` at simulation time ``t``
        (s, sent as ``/VMC/Ext/T``; ``None``: the time since the sender started)."""
        bones, blends = self.pose_of(model).frame(qpos)
        if t is None:
            t = time.perf_counter() - self._t0
        return pack_bundles(frame_messages(bones, blends, t), self.max_packet)

    def datagrams(self, model: mujoco.MjModel, qpos: np.ndarray, t: float) -> list[bytes]:
        return self.packets(model, qpos, t)

    def __enter__(self) -> VmcSender:
        return self
