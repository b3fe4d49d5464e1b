"""The body's pose, live, to another program: the VMC protocol (Virtual Motion Capture) over OSC.

VMC is what VRM avatar applications (VSeeFace, VirtualMotionCapture, Warudo, VMagicMirror …) and
their Unity/Unreal/Blender receivers (EVMC4U, VMC4B …) read: OSC 1.0 messages over UDP, by
default to port 39539. :class:`VmcSender` sends one frame of the humanoid's pose per call (the
live loop calls it once per viewer frame, after physics: ``gesture-sim live --stream
HOST:PORT``). A frame is a few OSC bundles (each at most :data:`MAX_PACKET` bytes, so that none
is fragmented on an Ethernet or Wi-Fi link; a receiver handles every message on its own) holding,
in this order:

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
* ``/VMC/Ext/OK`` ``i 1`` (a model is loaded) and ``/VMC/Ext/T`` ``f`` (seconds since the sender
  started).

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
  (its hinge axis at rest); eyes and fingers are not sent (the humanoid has none: mitten hands),
  so the receiver keeps its own.
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
from gesture_sim.export import MJ_TO_TARGET, PoseTransfer, TargetSkeleton, _swing
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
    """The VMC bones of one humanoid pose: :class:`PoseTransfer`'s mapping (the Mixamo table)
    evaluated for a single frame without its per-call allocations (a live frame's budget is a
    few ms; :meth:`PoseTransfer.pose` takes ~4 ms for one row). The result equals
    ``PoseTransfer.pose`` (tested).

    Args:
        model: the humanoid model (the body alone or the scene with it).
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        skeleton, _ = mixamo_skeleton()
        self.model = model
        self.skeleton: TargetSkeleton = skeleton
        self.transfer = PoseTransfer(model, skeleton, mixamo_follow())
        self.scale = root_scale(model, skeleton)
        self._data = mujoco.MjData(model)
        sk, tr = skeleton, self.transfer
        wanted = {sk.index(PREFIX + rig) for rig in BONES.values()}
        self._bones = [sk.index(PREFIX + BONES[n]) for n in BONES]
        order = set()
        for j in wanted:                        # the wanted joints and their ancestors
            while j >= 0 and j not in order:
                order.add(j)
                j = int(sk.parents[j])
        self._order = np.array(sorted(order))   # parents before children
        if any(tr.follow[j].body is None for j in self._order):
            raise GestureSimError("every VMC bone needs a driving humanoid body")
        self._parent = sk.parents[self._order]
        pos_in = {int(j): i for i, j in enumerate(self._order)}
        self._parent_row = np.array([pos_in.get(int(p), -1) for p in self._parent])
        self._rows = [pos_in[j] for j in self._bones]
        self._body_id = np.array([tr._body(tr.follow[j].body) for j in self._order])
        self._calib = tr.calib[self._order]
        self._aim_rest = tr.aim_rest[self._order]
        aimed = tr.aim_child[self._order]
        self._aimed = np.flatnonzero(aimed >= 0)
        # the humanoid points of the aimed joints and of their aimed children
        anchors = [int(j) for j in self._order[self._aimed]] + [int(c) for c in
                                                                aimed[self._aimed]]
        if any(j not in tr.anchor for j in anchors):
            raise GestureSimError("an aimed VMC bone lacks a humanoid point")
        self._anchor_body = np.array([tr.anchor[j][0] for j in anchors])
        self._anchor_off = np.array([tr.anchor[j][1] for j in anchors])
        self._root_anchor = tr.anchor[0]
        # joint offsets in Unity axes (the rig's rest: local positions of the bones)
        self._offsets = sk.offsets[self._bones] @ TO_UNITY
        head, jaw = model.body("head"), model.body("jaw")
        self._jaw_offset = TO_UNITY @ MJ_TO_TARGET @ (jaw.pos if jaw.parentid == head.id
                                                       else np.zeros(3))
        self._qadr = {n: int(model.jnt_qposadr[model.joint(j).id]) for n, j in BLENDS.items()}
        self._range = {n: float(model.jnt_range[model.joint(j).id][1]) for n, j in
                       BLENDS.items()}

    def local(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The VMC bones' rig joints for one qpos row, in :data:`BONES` order: local rotations
        (B, 3, 3) (relative to the parent; the root's: global) and global ones (B, 3, 3) in
        target axes, and the root point (3,) in target axes (m, unscaled). Vectorised: a bone's
        global rotation depends on its body and the aimed points only, never on its parent."""
        m, d, C = self.model, self._data, MJ_TO_TARGET
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        xmat = d.xmat.reshape(-1, 3, 3)
        glob = C @ xmat[self._body_id] @ self._calib
        ab = self._anchor_body
        pts = (d.xpos[ab] + np.einsum("nab,nb->na", xmat[ab], self._anchor_off)) @ C.T
        n_a = len(self._aimed)
        want = pts[n_a:] - pts[:n_a]
        want /= np.maximum(np.linalg.norm(want, axis=1, keepdims=True), 1e-12)
        have = np.einsum("nab,nb->na", glob[self._aimed], self._aim_rest[self._aimed])
        glob[self._aimed] = _swing(have, want) @ glob[self._aimed]
        local = glob.copy()
        child = self._parent_row >= 0
        local[child] = np.swapaxes(glob[self._parent_row[child]], -1, -2) @ glob[child]
        b, off = self._root_anchor
        root = C @ (d.xpos[b] + xmat[b] @ off)
        return local[self._rows], glob[self._rows], root

    def frame(self, qpos: np.ndarray) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]],
                                               dict[str, float]]:
        """The VMC frame of one qpos row: bone name -> (local position (3,), local rotation
        quaternion x y z w (4,)) in Unity axes, and blend shape name -> value 0 … 1."""
        qpos = np.asarray(qpos, dtype=float)
        local, _, root = self.local(qpos)
        U = TO_UNITY
        mats = np.empty((len(BONE_NAMES), 3, 3))
        mats[: len(self._bones)] = U @ local @ U
        jaw = float(qpos[self._qadr["A"]])
        mats[-1] = Rotation.from_rotvec([jaw, 0.0, 0.0]).as_matrix()   # about the left axis
        quats = _quat_xyzw(mats)
        pos = np.empty((len(BONE_NAMES), 3))
        pos[: len(self._bones)] = self._offsets
        pos[0] = U @ root * self.scale                                  # Hips: the translation
        pos[-1] = self._jaw_offset
        bones = {n: (pos[i], quats[i]) for i, n in enumerate(BONE_NAMES)}
        blends = {n: float(np.clip(qpos[a] / self._range[n], 0.0, 1.0)) if self._range[n] > 0
                  else 0.0 for n, a in self._qadr.items()}
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


class VmcSender:
    """Sends the humanoid's pose as VMC frames to ``address`` (``HOST:PORT``) over UDP.

    The address is resolved once, here (a bad one: :class:`GestureSimError`); sending never
    blocks and never raises (see :meth:`send`). Use as a context manager or call :meth:`close`.

    Args:
        address: where the receiver listens (default ``127.0.0.1:39539``).
        max_packet: largest datagram (bytes); a frame takes as many bundles as it needs.
    """

    def __init__(self, address: str = DEFAULT_ADDRESS, max_packet: int = MAX_PACKET) -> None:
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
        self.max_packet = int(max_packet)
        self._pose: VmcPose | None = None
        self._t0 = time.perf_counter()
        self.frames_sent = 0
        self.frames_dropped = 0
        self.packets_sent = 0
        self.bytes_sent = 0
        self.last_error = ""
        self.send_ms_max = 0.0
        self._send_s = 0.0

    def packets(self, model: mujoco.MjModel, qpos: np.ndarray) -> list[bytes]:
        """The datagrams of one frame for a qpos row of ``model``."""
        if self._pose is None or self._pose.model is not model:
            self._pose = VmcPose(model)
        bones, blends = self._pose.frame(qpos)
        return pack_bundles(frame_messages(bones, blends, time.perf_counter() - self._t0),
                            self.max_packet)

    def send(self, model: mujoco.MjModel, data: mujoco.MjData | np.ndarray) -> bool:
        """Send the current pose (``data.qpos``, or a qpos row) as one frame; True when every
        datagram went out. A frame the system refuses (full buffer, no route …) or a non-finite
        pose is dropped and counted; nothing is raised for either."""
        start = time.perf_counter()
        qpos = np.asarray(data.qpos if isinstance(data, mujoco.MjData) else data, dtype=float)
        ok = False
        if not np.all(np.isfinite(qpos)):
            self.last_error = "non-finite pose"
        else:
            try:
                for pkt in self.packets(model, qpos):
                    self._sock.sendto(pkt, self.sockaddr)
                    self.packets_sent += 1
                    self.bytes_sent += len(pkt)
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
        """JSON-ready figures: address, frames sent/dropped, datagrams, bytes, time per frame."""
        n = self.frames_sent + self.frames_dropped
        return {"protocol": "vmc", "address": self.address, "frames_sent": self.frames_sent,
                "frames_dropped": self.frames_dropped, "packets_sent": self.packets_sent,
                "bytes_sent": self.bytes_sent,
                "send_ms_mean": round(1e3 * self._send_s / n, 3) if n else 0.0,
                "send_ms_max": round(self.send_ms_max, 3),
                "last_error": self.last_error}

    def close(self) -> None:
        """Close the socket (idempotent)."""
        self._sock.close()

    def __enter__(self) -> VmcSender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

