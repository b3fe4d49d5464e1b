"""Finger motion of a library's clips, beside the library: ``<library>/fingers.npz``.

The library's clips carry the body's joints; a clip whose source has finger motion (an SMPL-X
take with its hand pose, as BEAT2's; a BVH whose skeleton has finger joints, as Mixamo's,
BEAT's, ZEGGS' or CMU's) can also carry the humanoid's 40 finger joint targets
(rad; 0 = MakeHuman's rest hand, :data:`gesture_sim.sim.humanoid.FINGER_JOINTS` order), one
row per clip frame. They are stored apart from ``library.npz`` so that adding them changes
neither the library's content nor its fingerprint (the inference model and the policy still
fit); ``library build`` and ``train --corpus`` write them for their SMPL-X and BVH inputs
(:func:`smplx_finger_track`, :func:`bvh_finger_track`, through
:func:`gesture_sim.motion.build.analyse_clip`),
``tools/build_finger_tracks.py`` for an existing library's clips, and the hand layer
(:class:`gesture_sim.signals.hands.HandLayer`) plays them while their clip plays.

File: ``format`` ``"gesture_sim.finger_tracks"``, ``library_fingerprint``, ``joints`` (40,),
``names`` (K,) clip names and ``track_<name>`` (T, 40) float32 for each.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.motion.skeleton import SkeletonMotion
from gesture_sim.sim.humanoid import FINGER_JOINTS, FINGERS

if TYPE_CHECKING:
    import mujoco

#: The angle from straight (deg) of each finger joint at qpos = 0: the MakeHuman rest hand as
#: tools/build_skin.py fits it (each phalanx against the proximal one about the joint's axis;
#: the thumb's carpometacarpal joint and the spreads are measured from that rest, 0).
MESH_REST_DEG: dict[str, float] = {
    "thumb_cmc_oppose": 0.0, "thumb_cmc_flex": 0.0, "thumb_mcp_flex": -3.2, "thumb_ip_flex": 15.6,
    "index_spread": 0.0, "index_mcp_flex": 13.8, "index_pip_flex": 12.1, "index_dip_flex": 7.5,
    "middle_spread": 0.0, "middle_mcp_flex": 21.5, "middle_pip_flex": 5.8, "middle_dip_flex": 7.6,
    "ring_spread": 0.0, "ring_mcp_flex": 21.9, "ring_pip_flex": 7.0, "ring_dip_flex": 7.0,
    "little_spread": 0.0, "little_mcp_flex": 20.6, "little_pip_flex": 9.6, "little_dip_flex": -0.1,
}

#: The SMPL-X joint whose rotation each finger joint takes (SMPL-X names its little finger
#: ``pinky``; ``1`` is the MCP (the thumb's CMC), ``2`` PIP (thumb MCP), ``3`` DIP (thumb IP)).
SMPLX_OF: dict[str, str] = {
    "thumb_cmc_oppose": "thumb1", "thumb_cmc_flex": "thumb1", "thumb_mcp_flex": "thumb2",
    "thumb_ip_flex": "thumb3",
    **{f"{f}_{j}": f"{'pinky' if f == 'little' else f}{k}" for f in FINGERS[1:]
       for j, k in (("spread", 1), ("mcp_flex", 1), ("pip_flex", 2), ("dip_flex", 3))},
}

#: The humanoid's hand frame at qpos = 0 -> SMPL-X's (T-pose, Y up, facing +Z, the body's
#: left at +X), per side, as a rotation (columns: the images of the humanoid's x, y, z). The
#: humanoid's hand hangs with the fingers down (-z), the palm towards the thigh (left: -y,
#: right: +y), the thumb forward (+x); SMPL-X's left hand points along +X, the right along -X,
#: both palms down (-Y), the thumbs forward (+Z).
HAND_TO_SMPLX: dict[str, np.ndarray] = {
    "left": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "right": np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]),
}



#: One hand's finger joints without the side (the order of :data:`FINGER_JOINTS` per side).
HAND_JOINTS: tuple[str, ...] = tuple(j.split("_", 1)[1] for j in FINGER_JOINTS[:20])



def _shape(thumb: tuple[float, float, float, float],
           fingers: dict[str, tuple[float, float, float, float]]) -> dict[str, float]:
    out = dict(zip(HAND_JOINTS[:4], thumb, strict=True))
    for f, vals in fingers.items():
        out.update(zip((f"{f}_spread", f"{f}_mcp_flex", f"{f}_pip_flex", f"{f}_dip_flex"),
                       vals, strict=True))
    return out


#: The relaxed hand (deg from straight): the resting "cascade" of the fingers, each flexed a
#: little more than its radial neighbour from the index to the little finger, the thumb resting
#: beside the index, lightly flexed (Kapandji, The Physiology of the Joints vol. 1, the hand at
#: rest; Lister's The Hand: Diagnosis and Indications, the posture of the resting hand; the
#: semi-flexed hand of the weightless "neutral body posture", NASA-STD-3000 Man-Systems
#: Integration Standards, 1995, fig. 3.3.4.3-1). The values are ours, chosen to show that
#: cascade within those descriptions, not measurements.
RELAXED_DEG: dict[str, float] = _shape(
    (12.0, 5.0, 10.0, 15.0),
    {"index": (3.0, 18.0, 22.0, 8.0), "middle": (0.0, 23.0, 26.0, 10.0),
     "ring": (2.0, 28.0, 30.0, 11.0), "little": (6.0, 33.0, 34.0, 12.0)})


def smplx_finger_angles(poses: np.ndarray, model: mujoco.MjModel) -> np.ndarray:
    """Finger angles from straight (rad), shape (T, 40) in :data:`FINGER_JOINTS` order, from
    SMPL-X poses (T, 165) axis-angle (rad), the 55 joints of
    :data:`gesture_sim.motion.smplx.SMPLX_JOINTS`.

    Each finger joint's angle is the component of its SMPL-X joint's axis-angle vector along
    the finger joint's axis (the humanoid's, from ``model``, taken into SMPL-X's hand frame by
    :data:`HAND_TO_SMPLX`): flexion about the finger's flexion axis, spread about the palm
    normal. A flat SMPL-X hand is 0, a straight finger; the SMPL-X template's finger
    directions and the MakeHuman rest hand's differ by a few degrees, which this ignores.
    """
    from gesture_sim.motion.smplx import SMPLX_JOINTS

    p = np.asarray(poses, dtype=float).reshape(len(poses), -1, 3)
    out = np.zeros((len(p), len(FINGER_JOINTS)))
    for c, name in enumerate(FINGER_JOINTS):
        side, joint = name.split("_", 1)
        axis = HAND_TO_SMPLX[side] @ model.jnt_axis[model.joint(name).id]
        src = SMPLX_JOINTS.index(f"{side}_{SMPLX_OF[joint]}")
        out[:, c] = p[:, src] @ axis
    return out


def smplx_finger_targets(poses: np.ndarray, model: mujoco.MjModel,
                         margin: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Finger joint targets q (rad), shape (T, 40), from SMPL-X poses (T, 165); the angles
    less the mesh's rest (:data:`MESH_REST_DEG`), clamped into the joints' ranges less
    ``margin`` of each span. Also returns the unclamped values (T, 40)."""
    rest = np.radians([MESH_REST_DEG[j.split("_", 1)[1]] for j in FINGER_JOINTS])
    q = smplx_finger_angles(poses, model) - rest
    rng = np.array([model.jnt_range[model.joint(j).id] for j in FINGER_JOINTS])
    span = rng[:, 1] - rng[:, 0]
    return np.clip(q, rng[:, 0] + margin * span, rng[:, 1] - margin * span), q


#: The file beside a library's ``library.npz``.
FINGER_TRACKS = "fingers.npz"
FORMAT = "gesture_sim.finger_tracks"


def smplx_finger_track(path: str | os.PathLike[str], model, fps: float,
                       n_frames: int) -> np.ndarray | None:
    """The humanoid's 40 finger joint targets (rad), shape (n_frames, 40), of an SMPL-X take's
    hand pose, resampled to ``fps`` (Hz; frame j at j / fps s, linear between the source's
    frames, held at its ends) so that row j goes with frame j of the clip the file became;
    ``None`` when the file carries no hand pose (fewer than 165 pose columns, or hands that
    never leave the zero pose). ``model``: the humanoid (its finger joint ranges).
    """
    with np.load(path, allow_pickle=False) as z:
        poses = np.asarray(z["poses"], dtype=float)
        rate_key = next((k for k in ("mocap_frame_rate", "mocap_framerate") if k in z), None)
        src_fps = float(z[rate_key]) if rate_key else fps
    if poses.ndim != 2 or poses.shape[1] < 165 or not np.any(np.abs(poses[:, 75:165]) > 1e-6):
        return None
    q, _ = smplx_finger_targets(poses[:, :165], model)
    t_src = np.arange(len(q)) / src_fps
    t = np.arange(n_frames) / float(fps)
    return np.stack([np.interp(t, t_src, q[:, k]) for k in range(q.shape[1])],
                    axis=1).astype(np.float32)


def save_finger_tracks(library_dir: str | os.PathLike[str], library,
                       tracks: dict[str, np.ndarray]) -> Path:
    """Write ``tracks`` (clip name -> (T, 40) rad, T = the clip's frames) beside the library
    (atomically); returns the path.

    Raises:
        GestureSimError: a name that is no clip of the library, or a track of the wrong shape.
    """
    from gesture_sim.fileio import atomic_path
    names = [c.name for c in library.clips]
    arrays = {}
    for name, track in tracks.items():
        if name not in names:
            raise GestureSimError(f"finger tracks: {name!r} is not a clip of the library")
        clip = library.clips[names.index(name)]
        a = np.asarray(track, dtype=np.float32)
        if a.shape != (clip.n_frames, len(FINGER_JOINTS)):
            raise GestureSimError(f"finger tracks: {name!r} has shape {a.shape}; the clip has "
                                  f"{clip.n_frames} frames of {len(FINGER_JOINTS)} joints")
        arrays[f"track_{name}"] = a
    path = Path(library_dir) / FINGER_TRACKS
    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, format=np.array(FORMAT),
                            library_fingerprint=np.array(library.fingerprint),
                            joints=np.array(FINGER_JOINTS), names=np.array(list(tracks)),
                            **arrays)
    return path


def load_finger_tracks(library_dir: str | os.PathLike[str], library) -> dict[int, np.ndarray]:
    """The finger tracks beside a library: clip index -> (T, 40) float rad. Empty when there is
    no file, or when it belongs to another library (fingerprint) or other finger joints (a
    stale file is ignored, not an error: the hands then rest as they do without one)."""
    path = Path(library_dir) / FINGER_TRACKS
    if not path.is_file():
        return {}
    try:
        with np.load(path, allow_pickle=False) as z:
            if (str(z["format"]) != FORMAT
                    or str(z["library_fingerprint"]) != library.fingerprint
                    or tuple(str(j) for j in z["joints"]) != tuple(FINGER_JOINTS)):
                return {}
            names = [c.name for c in library.clips]
            out = {}
            for name in (str(n) for n in z["names"]):
                if name in names:
                    track = np.asarray(z[f"track_{name}"], dtype=float)
                    if len(track) == library.clips[names.index(name)].n_frames:
                        out[names.index(name)] = track
            return out
    except (OSError, KeyError, ValueError) as exc:
        raise GestureSimError(f"cannot read finger tracks {path}: {exc}") from exc


# ---------------------------------------------------------------------------------------------
# BVH finger joints
# ---------------------------------------------------------------------------------------------

#: Finger words of BVH joint names (lower case) -> the humanoid's digit.
_DIGIT_WORDS = {"thumb": "thumb", "index": "index", "middle": "middle", "ring": "ring",
                "pinky": "little", "pinkie": "little", "little": "little"}
_DIGIT_RE = re.compile(r"^(?:hand|finger)?(in)?(?:hand)?(thumb|index|middle|ring|pinkie|pinky|"
                       r"little)(?:finger)?(metacarpal|\d+)?$")
#: Radial position of each digit's base (the thumb's metacarpal end) across the palm: the
#: palm's radial direction is fitted to these (thumb side positive).
_LETTER_RE = re.compile(r"^hand([timrp])(\d*)$")    # BEAT's short names: LHandI1, RHandT2
_LETTERS = {"t": "thumb", "i": "index", "m": "middle", "r": "ring", "p": "little"}
_RADIAL_WEIGHT = {"thumb": 2.0, "index": 1.0, "middle": 0.0, "ring": -1.0, "little": -2.0}


def _normalise_name(name: str) -> str:
    """A joint name without namespace prefix (``mixamorig:``, ``rig|``), lower case, without
    separators (``_ . - space``)."""
    base = re.split(r"[:|]", name)[-1]
    return re.sub(r"[\s_.\-]", "", base.lower())


def parse_finger_name(name: str) -> tuple[str, str, int] | None:
    """``(side, digit, number)`` of a BVH finger joint name, else ``None``.

    ``side`` is ``left`` / ``right``, ``digit`` a humanoid digit (``pinky`` -> ``little``),
    ``number`` 1, 2, 3 ... along the digit from the hand (1 = the MCP joint, the thumb's
    carpometacarpal), 0 for a metacarpal joint (ZEGGS ``LeftInHandIndex``, Unreal
    ``index_metacarpal_l``, ``Index0``), -1 without a number: the metacarpal where the digit
    also has numbered joints (BEAT's ``RightHandRing`` before ``RightHandRing1``), else the
    digit's only joint (CMU's ``LThumb``). Recognised: Mixamo (``mixamorig:LeftHandIndex1``),
    BEAT / ZEGGS / MotionBuilder (``LeftHandThumb2``, ``LeftHandPinky``, ``LeftInHandRing``,
    BEAT's short ``LHandI1``), CMU (``LThumb``, ``LeftHandIndex1``), Unreal (``thumb_01_l``)
    and their case / separator variants.
    """
    n = _normalise_name(name)
    candidates = []
    for pre in ("left", "right", "l", "r"):
        if n.startswith(pre):
            candidates.append((pre, n[len(pre):]))
        if n.endswith(pre):
            candidates.append((pre, n[:-len(pre)]))
    for side, rest in candidates:
        side = "left" if side.startswith("l") else "right"
        short = _LETTER_RE.match(rest)
        if short is not None:
            return side, _LETTERS[short.group(1)], int(short.group(2)) if short.group(2) else -1
        m = _DIGIT_RE.match(rest)
        if m is None:
            continue
        inner, word, num = m.groups()
        if inner or num in ("metacarpal", "0"):
            number = 0
        elif num is None:
            number = -1
        else:
            number = int(num)
        return side, _DIGIT_WORDS[word], number
    return None


def _is_finger_base(name: str) -> bool:
    """CMU's ``LeftFingerBase`` (the ASF ``lhand`` segment between the wrist and the fingers)."""
    n = _normalise_name(name)
    return n in ("leftfingerbase", "rightfingerbase", "lfingerbase", "rfingerbase")


@dataclass
class _Digit:
    """One digit of one hand: its rest polyline (joint positions from the base, then the end
    when known) and, for a BVH, the joints whose rotations move each segment."""

    points: list[np.ndarray]
    joints: list[int] = field(default_factory=list)  # the chain's joints, from the hand
    paths: list[list[int]] = field(default_factory=list)  # joints from the previous one down


@dataclass
class _Hand:
    """One hand's rest geometry: the wrist point and the digits present."""

    side: str
    wrist: np.ndarray
    digits: dict[str, _Digit]
    fallback_dir: np.ndarray | None = None  # the hand's direction when it has no long finger
    wrist_joint: int = -1
    palm_joint: int = -1     # the joint the palm moves with (CMU's FingerBase, else the wrist)


def _unit(v: np.ndarray) -> np.ndarray | None:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else None


def _palm_frame(hand: _Hand) -> np.ndarray | None:
    """The hand's rest frame as a rotation (columns: finger direction f, radial direction r
    towards the thumb, palmar normal n), or ``None`` when the geometry does not say."""
    long = [d for k, d in hand.digits.items() if k != "thumb"]
    f = _unit(sum((_unit(d.points[0] - hand.wrist) for d in long
                   if _unit(d.points[0] - hand.wrist) is not None), np.zeros(3)))
    if f is None:
        f = _unit(sum((_unit(d.points[1] - d.points[0]) for d in long if len(d.points) > 1
                       and _unit(d.points[1] - d.points[0]) is not None), np.zeros(3)))
    if f is None and hand.fallback_dir is not None:
        f = _unit(hand.fallback_dir)
    if f is None:
        return None
    # across the knuckles when two long fingers say it (the thumb stands out of the palm's
    # plane), else with the thumb's metacarpal end, else with the hand's axis
    pts = [d.points[0] for k, d in hand.digits.items() if k != "thumb"]
    wts = [_RADIAL_WEIGHT[k] for k in hand.digits if k != "thumb"]
    thumb = hand.digits.get("thumb")
    if len(pts) < 2 and thumb is not None and len(thumb.points) > 1:
        pts.append(thumb.points[1])
        wts.append(_RADIAL_WEIGHT["thumb"])
    if len(pts) < 2:
        pts.append(hand.wrist + 0.05 * f)
        wts.append(0.0)
    p, w = np.array(pts), np.array(wts)
    r = ((w - w.mean())[:, None] * (p - p.mean(axis=0))).sum(axis=0)
    r = _unit(r - (r @ f) * f)
    if r is None:
        return None
    n = np.cross(f, r) if hand.side == "left" else np.cross(r, f)
    return np.stack([f, r, n], axis=1)


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` to unit vector ``b``."""
    v, c = np.cross(a, b), float(a @ b)
    s = float(np.linalg.norm(v))
    if s < 1e-9:
        if c > 0:
            return np.eye(3)
        perp = _unit(np.cross(a, [1.0, 0.0, 0.0]))
        if perp is None:
            perp = _unit(np.cross(a, [0.0, 1.0, 0.0]))
        return Rotation.from_rotvec(np.pi * perp).as_matrix()
    return Rotation.from_rotvec(v / s * np.arctan2(s, c)).as_matrix()


def _humanoid_hands(model: mujoco.MjModel) -> tuple[dict[str, _Hand], dict[str, np.ndarray]]:
    """The humanoid's rest hands (qpos 0, world frame) and its finger joints' world axes."""
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    hands = {}
    for side in ("left", "right"):
        digits = {}
        for f in FINGERS:
            bodies = (("metacarpal", "proximal", "distal") if f == "thumb"
                      else ("proximal", "middle", "distal"))
            pts = [data.xpos[model.body(f"{side}_{f}_{b}").id].copy() for b in bodies]
            pts.append(data.site_xpos[model.site(f"{side}_{f}_tip").id].copy())
            digits[f] = _Digit(pts)
        hands[side] = _Hand(side, data.xpos[model.body(f"{side}_hand").id].copy(), digits)
    axes = {j: data.xaxis[model.joint(j).id].copy() for j in FINGER_JOINTS}
    return hands, axes


def _path_down(parents: np.ndarray, top: int, bottom: int) -> list[int] | None:
    """The joints from just below ``top`` down to ``bottom`` (inclusive), or None when ``top``
    is no ancestor of ``bottom``."""
    path = []
    j = bottom
    while j != top:
        if j < 0:
            return None
        path.append(j)
        j = int(parents[j])
    return path[::-1]


def _bvh_hands(motion: SkeletonMotion) -> dict[str, _Hand]:
    """The BVH's hands with finger joints found by name: rest polylines (rest = every channel
    0, so that every joint frame is the file's axes) and the joints moving each segment."""
    parents = np.asarray(motion.parents, dtype=int)
    rest = np.zeros((len(parents), 3))
    for j, p in enumerate(parents):
        rest[j] = motion.offsets[j] + (rest[p] if p >= 0 else 0.0)
    parsed = {j: parse_finger_name(n) for j, n in enumerate(motion.names)}
    finger_related = {j for j, v in parsed.items() if v is not None}
    finger_related |= {j for j, n in enumerate(motion.names) if _is_finger_base(n)}
    children: dict[int, list[int]] = {}
    for j, p in enumerate(parents):
        children.setdefault(int(p), []).append(j)
    chains: dict[tuple[str, str], dict[int, int]] = {}
    for j, v in parsed.items():
        if v is not None and v[2] > 0:
            chains.setdefault(v[:2], {}).setdefault(v[2], j)
    for j, v in parsed.items():      # no number: the digit's only joint, else its metacarpal
        if v is not None and v[2] < 0 and v[:2] not in chains:
            chains[v[:2]] = {1: j}
    hands: dict[str, _Hand] = {}
    for (side, digit), by_number in sorted(chains.items()):
        joints = [by_number[k] for k in sorted(by_number)]
        wrist = joints[0]
        while wrist >= 0 and wrist in finger_related:
            wrist = int(parents[wrist])
        if wrist < 0:
            continue
        tops = [wrist, *joints[:-1]]
        paths = [_path_down(parents, t, b) for t, b in zip(tops, joints, strict=True)]
        if any(p is None for p in paths):
            continue
        pts = [rest[j] for j in joints]
        ends = [c for c in children.get(joints[-1], [])
                if np.linalg.norm(rest[c] - rest[joints[-1]]) > 1e-9]
        if ends:
            pts.append(rest[ends[0]])
        hand = hands.setdefault(side, _Hand(side, rest[wrist], {}, wrist_joint=wrist))
        if hand.wrist_joint != wrist:
            continue  # a digit hanging off another joint than this hand's other digits
        hand.digits[digit] = _Digit(pts, joints, paths)
    for hand in hands.values():
        bases = [c for c in children.get(hand.wrist_joint, []) if _is_finger_base(motion.names[c])]
        hand.palm_joint = bases[0] if bases else hand.wrist_joint
        if all(k == "thumb" for k in hand.digits):
            w = hand.wrist_joint
            dirs = [rest[c] - rest[w] for c in children.get(w, []) if c not in finger_related]
            hand.fallback_dir = sum(dirs, np.zeros(3)) if dirs else None
    return hands


def _relative(glob: np.ndarray, ref: int, joint: int) -> np.ndarray:
    """(T, 3, 3): the rotation of ``joint`` relative to ``ref``, from their global rotations
    ``glob`` (T, J, 3, 3) (both the identity at rest, so this is in the rest's axes)."""
    return np.swapaxes(glob[:, ref], -1, -2) @ glob[:, joint]


def _hinge_angle(rot: np.ndarray, axis: np.ndarray, d: np.ndarray | None) -> np.ndarray:
    """(T,) rotation angle (rad) about ``axis`` of ``rot`` (T, 3, 3): of the segment ``d``'s
    direction about it (its swing, blind to the segment's twist) when ``d`` is known, else the
    axis-angle vector's component."""
    if d is not None:
        dp = _unit(d - (d @ axis) * axis)
        if dp is not None:
            v = rot @ dp
            return np.arctan2(v @ np.cross(axis, dp), v @ dp)
    return Rotation.from_matrix(rot).as_rotvec() @ axis


def _signed_angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> float:
    """The angle (rad) from ``a`` to ``b`` about ``axis``, both projected off it."""
    ap, bp = _unit(a - (a @ axis) * axis), _unit(b - (b @ axis) * axis)
    if ap is None or bp is None:
        return 0.0
    return float(np.arctan2(np.cross(ap, bp) @ axis, ap @ bp))


def _two_axis_angles(rot: np.ndarray, a1: np.ndarray, a2: np.ndarray,
                     t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(alpha, beta) (T,) each, rad, with R(a1, alpha) R(a2, beta) t = rot t: the two hinges
    (``a1`` the outer) that point the segment ``t`` where ``rot`` (T, 3, 3) does; the smaller
    ``|alpha|`` of the two solutions, the nearest reachable when none reaches it exactly."""
    v = rot @ t
    c12 = a1 @ a2
    v1 = v @ a1
    big_a = v @ a2 - v1 * c12
    big_b = -(np.cross(a1, v) @ a2)
    rhs = t @ a2 - v1 * c12
    rho = np.hypot(big_a, big_b)
    psi = np.arctan2(big_b, big_a)
    delta = np.arccos(np.clip(rhs / np.maximum(rho, 1e-12), -1.0, 1.0))
    sols = np.stack([psi + delta, psi - delta])
    sols = (sols + np.pi) % (2 * np.pi) - np.pi
    alpha = sols[np.argmin(np.abs(sols), axis=0), np.arange(len(v))]
    # u = R(a1, -alpha) v, by Rodrigues
    ca, sa = np.cos(alpha)[:, None], np.sin(alpha)[:, None]
    u = v * ca - np.cross(a1, v) * sa + np.outer(v1, a1) * (1 - ca)
    tp = _unit(t - (t @ a2) * a2)
    if tp is None:
        return alpha, np.zeros(len(v))
    beta = np.arctan2(u @ np.cross(a2, tp), u @ tp)
    return alpha, beta


def relaxed_finger_q() -> np.ndarray:
    """(40,) the relaxed hand's finger targets (rad;
    :data:`RELAXED_DEG` less the mesh's rest), both hands."""
    return np.radians([RELAXED_DEG[j.split("_", 1)[1]] - MESH_REST_DEG[j.split("_", 1)[1]]
                       for j in FINGER_JOINTS])


def bvh_finger_angles(motion: SkeletonMotion,
                      model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray] | None:
    """Finger angles (rad), shape (T, 40) in :data:`FINGER_JOINTS` order, of a BVH skeleton's
    finger joints, and a (40,) bool mask of the joints it measured; ``None`` when it has none.

    The finger joints are found by name (:func:`parse_finger_name`). Every measurement is in
    the BVH's own rest frame (all channels 0: every joint frame is the file's axes, so any
    rest pose and up axis works), from its geometry: the palm's frame (:func:`_palm_frame`:
    the finger direction, the radial direction towards the thumb, the palmar normal by the
    side's handedness). A long finger's flexion is its segment's swing about the axis
    perpendicular to the segment and the palm normal (positive towards the palm), plus the
    rest geometry's own curl there (so the angle is from straight, as
    :data:`MESH_REST_DEG`'s); its MCP spread is the proximal segment's swing about the palm
    normal (the rotation is split spread then flexion, the humanoid's joint order). The
    thumb's axes are the humanoid's, taken into the BVH hand by the two palm frames and turned
    with each thumb segment onto the BVH's; its carpometacarpal opposition and flexion point
    the metacarpal where the BVH's points, from the BVH's rest thumb. Each finger joint's
    rotation is taken relative to the previous finger joint (the first: relative to the palm,
    the hand joint or CMU's ``FingerBase``, the joint the retargeted hand follows), so that
    joints between them (ZEGGS' metacarpal ``InHand`` joints) count in the finger's motion.
    CMU's single ``LeftHandIndex1`` (all four fingers in one) gives the four MCP flexions.
    """
    hands = _bvh_hands(motion)
    if not any(h.digits for h in hands.values()):
        return None
    ref_hands, ref_axes = _humanoid_hands(model)
    glob = np.asarray(motion.rotations, dtype=float)
    n_t = glob.shape[0]
    out = np.zeros((n_t, len(FINGER_JOINTS)))
    have = np.zeros(len(FINGER_JOINTS), dtype=bool)
    col = {j: i for i, j in enumerate(FINGER_JOINTS)}
    for side, hand in hands.items():
        frame, ref = _palm_frame(hand), ref_hands[side]
        ref_frame = _palm_frame(ref)
        if frame is None or ref_frame is None:
            continue
        to_bvh = frame @ ref_frame.T
        normal = frame[:, 2]
        long = {k: d for k, d in hand.digits.items() if k != "thumb"}
        lumped = (len(long) == 1 and len(next(iter(long.values())).paths) == 1)
        for digit, dg in hand.digits.items():
            segs = [_unit(dg.points[k + 1] - dg.points[k]) if k + 1 < len(dg.points) else None
                    for k in range(len(dg.paths))]
            ref_dg = ref.digits[digit]
            if digit == "thumb":
                _bvh_thumb(out, have, col, side, dg, segs, ref_dg, ref_axes, to_bvh,
                           glob, hand.palm_joint)
                continue
            targets = FINGERS[1:] if lumped else (digit,)
            incoming = _unit(dg.points[0] - hand.wrist)
            for k, joint_k in enumerate(dg.joints[:3]):
                rot = _relative(glob, hand.palm_joint if k == 0 else dg.joints[k - 1], joint_k)
                d = segs[k] if segs[k] is not None else (segs[k - 1] if k else None)
                if d is None:
                    break
                n_perp = _unit(normal - (normal @ d) * d)
                if n_perp is None:
                    break
                axis = np.cross(d, n_perp)
                prev = incoming if k == 0 else segs[k - 1]
                curl = (_signed_angle(prev, segs[k], axis)
                        if prev is not None and segs[k] is not None else 0.0)
                joint = ("mcp_flex", "pip_flex", "dip_flex")[k]
                if k == 0 and segs[0] is not None:
                    sign = np.sign(ref_axes[f"{side}_{digit}_spread"] @ ref_frame[:, 2]) or 1.0
                    spread_axis = sign * n_perp
                    lat = np.cross(spread_axis, d)
                    v = rot @ d
                    flex = np.arctan2(v @ n_perp, np.hypot(v @ d, v @ lat)) + curl
                    spread = np.arctan2(v @ lat, v @ d)
                    for t in targets:
                        c = col[f"{side}_{t}_mcp_flex"]
                        out[:, c], have[c] = flex, True
                        if not lumped:
                            c = col[f"{side}_{t}_spread"]
                            out[:, c], have[c] = spread, True
                    continue
                angle = _hinge_angle(rot, axis, segs[k]) + curl
                for t in targets:
                    c = col[f"{side}_{t}_{joint}"]
                    out[:, c], have[c] = angle, True
    if not have.any():
        return None
    return out, have


def _bvh_thumb(out, have, col, side, dg, segs, ref_dg, ref_axes, to_bvh, glob,
               palm) -> None:
    """The thumb's four angles (see :func:`bvh_finger_angles`) into ``out`` / ``have``."""
    ref_segs = [_unit(ref_dg.points[k + 1] - ref_dg.points[k]) for k in range(3)]
    turn = to_bvh
    for k, joint_k in enumerate(dg.joints[:3]):
        if segs[k] is not None:
            turn = _align(to_bvh @ ref_segs[k], segs[k]) @ to_bvh
        rot = _relative(glob, palm if k == 0 else dg.joints[k - 1], joint_k)
        if k == 0:
            a1 = turn @ ref_axes[f"{side}_thumb_cmc_oppose"]
            a2 = turn @ ref_axes[f"{side}_thumb_cmc_flex"]
            t = segs[0] if segs[0] is not None else turn @ ref_segs[0]
            alpha, beta = _two_axis_angles(rot, a1, a2, t)
            for name, val in (("cmc_oppose", alpha), ("cmc_flex", beta)):
                c = col[f"{side}_thumb_{name}"]
                out[:, c], have[c] = val, True
            continue
        joint = ("mcp_flex", "ip_flex")[k - 1]
        axis = turn @ ref_axes[f"{side}_thumb_{joint}"]
        curl = (_signed_angle(segs[k - 1], segs[k], axis)
                if segs[k - 1] is not None and segs[k] is not None else 0.0)
        c = col[f"{side}_thumb_{joint}"]
        out[:, c] = _hinge_angle(rot, axis, segs[k]) + curl
        have[c] = True


def _clip_q(q: np.ndarray, model: mujoco.MjModel, margin: float = 0.01) -> np.ndarray:
    rng = np.array([model.jnt_range[model.joint(j).id] for j in FINGER_JOINTS])
    span = rng[:, 1] - rng[:, 0]
    return np.clip(q, rng[:, 0] + margin * span, rng[:, 1] - margin * span)


def bvh_finger_track(motion_or_path: SkeletonMotion | str | os.PathLike[str],
                     model: mujoco.MjModel, fps: float, n_frames: int) -> np.ndarray | None:
    """The humanoid's 40 finger joint targets (rad), shape (n_frames, 40), of a BVH's finger
    joints (:func:`bvh_finger_angles` less the mesh's rest, clamped into the joints' ranges
    less 1 % of each span), resampled to ``fps`` as :func:`smplx_finger_track` does; the
    joints the skeleton lacks (a digit it has not, CMU's PIP / DIP) hold the relaxed hand
    (:func:`relaxed_finger_q`). ``None`` when the skeleton has no finger joints, or finger
    joints that never leave their rest (every channel 0: no finger capture).
    ``motion_or_path``: a :class:`SkeletonMotion` read from a BVH, or the ``.bvh`` file.
    """
    if isinstance(motion_or_path, SkeletonMotion):
        motion = motion_or_path
    else:
        from gesture_sim.motion.bvh import read_bvh

        motion = read_bvh(motion_or_path)
    found = bvh_finger_angles(motion, model)
    if found is None:
        return None
    angles, have = found
    joints = {j for h in _bvh_hands(motion).values() for d in h.digits.values()
              for p in d.paths for j in p if not _is_finger_base(motion.names[j])}
    local = np.asarray(motion.local_rotations)[:, sorted(joints)]
    if not np.any(np.abs(local - np.eye(3)) > 1e-6):
        return None
    rest = np.radians([MESH_REST_DEG[j.split("_", 1)[1]] for j in FINGER_JOINTS])
    q = np.where(have[None, :], _clip_q(angles - rest, model), relaxed_finger_q()[None, :])
    t_src = np.arange(len(q)) / float(motion.fps)
    t = np.arange(n_frames) / float(fps)
    return np.stack([np.interp(t, t_src, q[:, k]) for k in range(q.shape[1])],
                    axis=1).astype(np.float32)
