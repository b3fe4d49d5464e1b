"""Chiu (2014) gestural signs on the motion library: two form-based labellers and their agreement.

Chiu's thesis (Table 3.1) describes co-speech motion by 14 *gestural signs* (:data:`SIGNS`) and
labels the mocap library with them; its annotators "judged the physical form only, ignoring
utterance content" (§4.2.1), with Beats the catch-all for a gesture matching no other sign and
Rest for speech without movement. This module does the same from the library's own motion, with
two procedures that can disagree (docs/SIGNS.md has the figures):

**Pass 1: rules** (:func:`label_segment`, :func:`label_library`). Every frame of a segment is
posed on the humanoid with the root at the standing pose (``mujoco.mj_kinematics``), which gives a
body frame (x forward, y left, z up, m) for the palm centres (``*_hand_site``), the shoulders
(the ``*_upper_arm`` bodies), the chest, the palm normals (the hand body's -y / +y axis for the
left / right hand: the palm faces the thigh at qpos 0) and the head's pitch (:class:`SegmentForm`).
A hand is *active* when its path is at least :attr:`SignSettings.active_path_m`; it is *in the
gesture space* when at its *apex* (its highest frame: a segment runs between hand-speed minima,
so it is often a preparation or a retraction, and the apex is where its stroke is) it is no more
than ``space_low_m`` below its shoulder. The rules are tried in this order and the first that
holds gives the sign (thresholds in :class:`SignSettings`, lengths in m, angles in rad):

1. No hand active: **Head-nod** when the head pitches through ``nod_range_rad`` with a reversal
   (the thesis's nod is "without arm gestures"); **Rest** when no hand is in the gesture space;
   else a hold -- **Frame** for two held hands with palms facing ``frame_gap_m`` apart,
   **Palm-face-up** for held hands palm up, else **Beats**.
2. Active hands only below the gesture space (swinging at the sides): **Rest**.
3. **Deictic.Self** -- an active hand ends within ``self_dist_m`` of the chest point with its
   palm towards the body (palm normal . unit(chest - hand) >= ``palm_towards``).
4. **Process** -- an active hand's path turns through ``process_turn_rad`` in its best-fit plane,
   is round (isoperimetric quotient of the closed path >= ``round``) and spans
   ``process_extent_m``.
5. **More-or-less** -- a palm-down hand (palm normal z <= -``palm_towards``) whose palm rolls
   back and forth (>= ``wobble_reversals`` reversals, range >= ``wobble_range_rad``) within
   ``wobble_extent_m``.
6. **Block** -- at its apex an active hand is ``front_m`` in front of its shoulder, at most
   ``block_side_m`` beside and ``high_m`` above it, palm forward (palm normal x >=
   ``palm_towards``), after moving forward by ``push_m``.
7. Two hands active alike (the smaller path >= half the larger) and mirror-symmetric (mirror
   velocity correlation >= ``symmetry``): **Frame** -- palms facing each other over
   ``frame_share`` of the frames, ``frame_gap_m`` apart, the separation held over the last third
   (< ``frame_hold_m``); **Shrug** -- the separation changes by ``apart_m`` and both palms are up
   at the apex (palm normal z >= ``palm_up``); **Palm-face-up** -- palms up without that;
   **Wipe** -- apart by ``apart_m`` with palms down or forward on a straight line (straightness
   >= ``straight``, vertical excursion off the chord < ``arc_m``); **Whole** -- the same on an
   arc.
8. **Deictic.Other** -- one hand (not two alike) reaching out: raised (no more than
   ``point_low_m`` below its shoulder) at ``point_reach`` of the arm's length, its apex
   ``front_m`` in front or ``side_m`` beside the shoulder and at most ``high_m`` above it.
9. One hand: **Palm-face-up** -- lifted by ``lift_m``, palm up at the apex; **Wipe** -- a
   straight sideways sweep (lateral range >= ``apart_m`` and >= its vertical range), palm down;
   **Dismiss** -- the same sweep on an arc, or outwards by ``apart_m``/2 and down by
   ``dismiss_drop_m``.
10. **Beats** -- anything else (the thesis's catch-all).

**Pass 2: nearest prototype** (:func:`prototype_label`). A different procedure on different
features: the library's key points only (no palm orientation, no forward kinematics), ten
features per segment (:func:`keypoint_features`), and for each sign a prototype written from the
thesis's one-line description (:data:`PROTOTYPES`: the value of each feature the description
implies, NaN where it says nothing); a segment gets the sign whose prototype is nearest in
scaled, NaN-skipping RMS distance, or Beats (the catch-all) when none is within
:data:`MAX_PROTOTYPE_DISTANCE`. :func:`cohen_kappa` gives the agreement of the two passes.

Honest limits: both passes see physical form only and were written by one person; the
shipped library's co-speech part is one speaker (BEAT2 ``2_scott_0_1_1``, 67 segments) and its
fingers are not retargeted (all finger joints at rest), so a pointing index finger cannot be seen
and Deictic.Other rests on the arm alone; emblem and acting clips are labelled by the same rules
but were recorded as other gestures (waves, bows).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any

import numpy as np

from gesture_sim.errors import GestureSimError

#: The 14 gestural signs of Chiu (2014) Table 3.1, in the thesis's order (index = Table A.1's).
SIGNS: tuple[str, ...] = (
    "Rest", "Palm-face-up", "Head-nod", "Wipe", "Whole", "Frame", "Dismiss", "Block", "Shrug",
    "More-or-less", "Process", "Deictic.Other", "Deictic.Self", "Beats")

#: Other spellings of the signs (lower case, spaces/underscores as '-') seen in annotations:
#: the thesis's Table A.1 calls Whole "Everything".
SIGN_ALIASES: dict[str, str] = {
    "everything": "Whole", "whole/everything": "Whole", "beat": "Beats",
    "palm-up": "Palm-face-up", "palms-up": "Palm-face-up", "head-nods": "Head-nod",
    "nod": "Head-nod", "deictic-other": "Deictic.Other", "deictic-self": "Deictic.Self",
    "deictic.other": "Deictic.Other", "deictic.self": "Deictic.Self", "more-less": "More-or-less",
}


def canonical_sign(value: str) -> str:
    """The :data:`SIGNS` name of an annotation value (case, spaces and aliases forgiven).

    Raises:
        GestureSimError: a value that names no sign.
    """
    key = "-".join(str(value).strip().lower().replace("_", " ").split())
    for s in SIGNS:
        if key == s.lower():
            return s
    if key in SIGN_ALIASES:
        return SIGN_ALIASES[key]
    raise GestureSimError(f"{value!r} is not a gestural sign (one of {', '.join(SIGNS)})")


@dataclass(frozen=True)
class SignSettings:
    """Thresholds of the rule labeller (pass 1); lengths in m, angles in rad, shares in [0, 1]."""

    active_path_m: float = 0.10     #: a hand moving at least this far (path length) is active
    nod_range_rad: float = 0.10     #: Head-nod: head pitch range (about 6 degrees)
    self_dist_m: float = 0.16       #: Deictic.Self: palm centre this close to the chest point
    palm_towards: float = 0.5       #: cosine for "palm faces X" (60 degrees)
    palm_up: float = 0.4            #: palm normal z at least this = palm up (Shrug, Palm-face-up)
    process_turn_rad: float = 1.6 * math.pi  #: Process: path turning (a circle is 2 pi)
    process_extent_m: float = 0.08  #: Process: smallest circle (extent)
    round: float = 0.25             #: Process: isoperimetric quotient of the closed path
    wobble_reversals: int = 2       #: More-or-less: reversals of the palm's roll rate
    wobble_range_rad: float = 0.5   #: More-or-less: roll range
    wobble_extent_m: float = 0.15   #: More-or-less: the hand stays within this extent
    front_m: float = 0.25           #: Block / Deictic.Other: hand this far in front of shoulder
    push_m: float = 0.08            #: Block: forward movement of the hand
    symmetry: float = 0.3           #: two-handed: mirror velocity correlation at least this
    frame_share: float = 0.4        #: Frame: share of frames with the palms facing
    frame_gap_m: tuple[float, float] = (0.12, 0.6)  #: Frame: hand separation range
    frame_hold_m: float = 0.04      #: Frame: separation change over the last third below this
    apart_m: float = 0.12           #: Wipe/Whole/Shrug: the hands separate by at least this
    straight: float = 0.8           #: Wipe: straightness (net / path length) at least this
    arc_m: float = 0.05             #: Wipe: vertical excursion off the chord below this
    lift_m: float = 0.04            #: Palm-face-up: the hand rises at least this
    point_reach: float = 0.9        #: Deictic.Other: shoulder-hand distance / arm length
    side_m: float = 0.30            #: Deictic.Other: hand this far beside its shoulder
    point_low_m: float = 0.15       #: Deictic.Other: hand at most this far below its shoulder
    space_low_m: float = 0.45       #: gesture space: apex at most this far below the shoulder
    block_side_m: float = 0.20      #: Block: apex at most this far beside the shoulder
    high_m: float = 0.20            #: Block / Deictic.Other: apex at most this far above the
    #: shoulder (a hand above the head is a wave or a raised hand, not a push or a point)
    dismiss_drop_m: float = 0.05    #: Dismiss: outwards and down by this
    arm_length_m: float = 0.62      #: shoulder to palm centre of the humanoid's straight arm


@dataclass(frozen=True)
class SegmentForm:
    """The physical form of one segment in the body frame (x forward, y left, z up; m).

    Attributes:
        fps: frame rate (Hz).
        hand: (T, 2, 3) palm centres, [:, 0] left, [:, 1] right.
        shoulder: (T, 2, 3) shoulder joint centres.
        chest: (T, 3) the chest point a self-deictic hand goes to.
        palm: (T, 2, 3) unit palm normals (out of the palm).
        head_pitch: (T,) head pitch (rad, > 0 down).
    """

    fps: float
    hand: np.ndarray
    shoulder: np.ndarray
    chest: np.ndarray
    palm: np.ndarray
    head_pitch: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.hand.shape[0])


# --------------------------------------------------------------------------------------------
# Forward kinematics: the form of a library segment
# --------------------------------------------------------------------------------------------


class FormReader:
    """Poses joint values on the humanoid and reads a :class:`SegmentForm` (one per model)."""

    def __init__(self, model=None) -> None:
        import mujoco

        from gesture_sim.sim import humanoid as hm

        self._mj = mujoco
        self.model = model if model is not None else hm.load_model(scene=False)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._hm = hm
        self.hand_sites = [m.site(s).id for s in hm.HAND_SITES]
        self.hand_bodies = [int(m.site_bodyid[s]) for s in self.hand_sites]
        self.shoulders = [m.body(n).id for n in ("left_upper_arm", "right_upper_arm")]
        self.chest = m.body("chest").id
        self.head = int(m.site_bodyid[m.site(hm.HEAD_SITE).id])
        self._adr = hm.qpos_addresses(m)
        self._base = hm.qpos_from_targets(m, np.zeros(len(hm.ACTUATED_JOINTS)))
        # the chest point: in front of the chest body's origin, at the sternum's height
        self.chest_offset = np.array([0.10, 0.0, 0.10])

    def form(self, qpos: np.ndarray, joint_names, fps: float) -> SegmentForm:
        """The form of poses ``qpos`` (T, n_joints), columns ``joint_names``, at ``fps`` Hz."""
        mj, m, d = self._mj, self.model, self.data
        qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
        adr = self._adr[self._hm.actuated_index(tuple(joint_names))]
        if qpos.shape[1] != len(adr):
            raise GestureSimError(f"poses have {qpos.shape[1]} columns for {len(adr)} joints")
        t = len(qpos)
        hand, shoulder, palm = np.empty((t, 2, 3)), np.empty((t, 2, 3)), np.empty((t, 2, 3))
        chest, pitch = np.empty((t, 3)), np.empty(t)
        root = self._base[:3].copy()
        for k, q in enumerate(qpos):
            d.qpos[:] = self._base
            d.qpos[adr] = q
            mj.mj_kinematics(m, d)
            for h in range(2):
                hand[k, h] = d.site_xpos[self.hand_sites[h]] - root
                shoulder[k, h] = d.xpos[self.shoulders[h]] - root
                axis_y = d.xmat[self.hand_bodies[h]].reshape(3, 3)[:, 1]
                palm[k, h] = -axis_y if h == 0 else axis_y
            rc = d.xmat[self.chest].reshape(3, 3)
            chest[k] = d.xpos[self.chest] - root + rc @ self.chest_offset
            fwd = d.xmat[self.head].reshape(3, 3)[:, 0]
            pitch[k] = math.atan2(-fwd[2], math.hypot(fwd[0], fwd[1]))
        return SegmentForm(fps=float(fps), hand=hand, shoulder=shoulder, chest=chest, palm=palm,
                           head_pitch=pitch)


@lru_cache(maxsize=1)
def form_reader() -> FormReader:
    """The :class:`FormReader` of the shipped humanoid (built once)."""
    return FormReader()


def segment_form(library: Any, i: int) -> SegmentForm:
    """The :class:`SegmentForm` of segment ``i`` of a :class:`MotionLibrary`."""
    return form_reader().form(library.segment_qpos(i), library.joint_names, library.fps)


# --------------------------------------------------------------------------------------------
# Pass 1: rules
# --------------------------------------------------------------------------------------------


def _path(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(p, axis=0), axis=-1).sum()) if len(p) > 1 else 0.0


def _extent(p: np.ndarray) -> float:
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


def _turning(p: np.ndarray) -> float:
    """Total signed turning (rad) of the path ``p`` (T, 3) in its best-fit plane."""
    if len(p) < 4:
        return 0.0
    c = p - p.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    xy = c @ vt[:2].T
    v = np.diff(xy, axis=0)
    speed = np.linalg.norm(v, axis=1)
    v = v[speed > max(1e-4, 0.2 * float(speed.max()))]   # turning of the moving parts only
    if len(v) < 3:
        return 0.0
    ang = np.arctan2(v[:, 1], v[:, 0])
    dang = (np.diff(ang) + np.pi) % (2 * np.pi) - np.pi
    return float(abs(dang.sum()))


def _roundness(p: np.ndarray) -> float:
    """Isoperimetric quotient 4 pi A / P^2 of the path ``p`` (T, 3) closed by its chord, in its
    best-fit plane: 1 for a circle, 0 for a straight or out-and-back stroke."""
    if len(p) < 4:
        return 0.0
    c = p - p.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    xy = c @ vt[:2].T
    x, y = xy[:, 0], xy[:, 1]
    area = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
    per = _path(p) + float(np.linalg.norm(p[-1] - p[0]))
    return 4 * math.pi * area / per ** 2 if per > 1e-9 else 0.0


def _arc(p: np.ndarray) -> float:
    """Largest vertical distance (m) of the path ``p`` (T, 3) from its start-end chord."""
    if len(p) < 3:
        return 0.0
    a, b = p[0], p[-1]
    u = np.linspace(0.0, 1.0, len(p))[:, None]
    return float(np.abs((p - (a + u * (b - a)))[:, 2]).max())


def _mirror_corr(hand: np.ndarray) -> float:
    """Correlation of the left hand's velocity with the mirrored (y -> -y) right hand's."""
    v = np.diff(hand, axis=0)
    if len(v) < 2:
        return 0.0
    left, right = v[:, 0].ravel(), (v[:, 1] * np.array([1.0, -1.0, 1.0])).ravel()
    den = float(np.linalg.norm(left) * np.linalg.norm(right))
    return float(left @ right / den) if den > 1e-9 else 0.0


def _reversals(x: np.ndarray, dead: float) -> int:
    """Sign changes of the rate of ``x`` ignoring rates within ``dead``."""
    r = np.diff(x)
    s = np.sign(r[np.abs(r) > dead])
    return int((np.diff(s) != 0).sum()) if len(s) > 1 else 0


def _roll(form: SegmentForm, h: int) -> np.ndarray:
    """(T,) roll angle (rad) of the palm normal about the forearm-ish axis (the hand's path is
    short for More-or-less; the roll is measured about the shoulder-hand direction)."""
    axis = form.hand[:, h] - form.shoulder[:, h]
    axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-9)
    ref = np.cross(axis, np.array([0.0, 0.0, 1.0]))
    ref = ref / np.maximum(np.linalg.norm(ref, axis=1, keepdims=True), 1e-9)
    other = np.cross(axis, ref)
    n = form.palm[:, h]
    return np.unwrap(np.arctan2(np.einsum("ij,ij->i", n, other), np.einsum("ij,ij->i", n, ref)))


def form_features(form: SegmentForm, settings: SignSettings | None = None) -> dict[str, Any]:
    """The pass-1 figures of a segment's form (what the rules test; JSON-ready).

    Per hand (lists of two, left then right): path and extent (m), the *apex* (the frame where
    the hand is highest: a segment runs between hand-speed minima, so it is often a preparation
    or a retraction, and the apex is its stroke end) with the palm normal and the hand's offset
    from its shoulder there, and the path's turning (rad) and roundness.
    """
    st = settings or SignSettings()
    hand, sh = form.hand, form.shoulder
    paths = [_path(hand[:, h]) for h in range(2)]
    extents = [_extent(hand[:, h]) for h in range(2)]
    active = [p >= st.active_path_m for p in paths]
    sep = np.linalg.norm(hand[:, 0] - hand[:, 1], axis=1)
    third = max(len(sep) // 3, 1)
    rel = hand - sh                                # (T, 2, 3) hand from its shoulder
    apex = [int(np.argmax(hand[:, h, 2])) for h in range(2)]
    reach = np.linalg.norm(rel, axis=2) / st.arm_length_m
    raised = rel[:, :, 2] >= -st.point_low_m       # hand no lower than this below the shoulder
    to_chest = form.chest[:, None, :] - hand       # (T, 2, 3)
    dist_chest = np.linalg.norm(to_chest, axis=2)
    towards = np.einsum("thk,thk->th", form.palm,
                        to_chest / np.maximum(dist_chest, 1e-9)[..., None])
    other = hand[:, ::-1] - hand
    facing = np.einsum("thk,thk->th", form.palm,
                       other / np.maximum(np.linalg.norm(other, axis=2), 1e-9)[..., None])
    rolls = [_roll(form, h) for h in range(2)]
    out: dict[str, Any] = {
        "path_m": paths, "extent_m": extents, "active": active,
        "pitch_range_rad": float(np.ptp(form.head_pitch)) if form.n_frames else 0.0,
        "pitch_reversals": _reversals(form.head_pitch, 0.002),
        "chest_dist_m": [float(dist_chest[-1, h]) for h in range(2)],   # at the end (a stop)
        "palm_to_chest": [float(towards[-1, h]) for h in range(2)],
        "turning_rad": [_turning(hand[:, h]) for h in range(2)],
        "roundness": [_roundness(hand[:, h]) for h in range(2)],
        "roll_range_rad": [float(np.ptp(r)) for r in rolls],
        "roll_reversals": [_reversals(r, 0.01) for r in rolls],
        "palm_apex": [form.palm[apex[h], h].tolist() for h in range(2)],
        "apex_rel_m": [rel[apex[h], h].tolist() for h in range(2)],
        "raised": [bool(raised[:, h].any()) for h in range(2)],
        "in_space": [bool(rel[apex[h], h, 2] >= -st.space_low_m) for h in range(2)],
        "forward_m": [float(hand[apex[h], h, 0] - hand[:, h, 0].min()) for h in range(2)],
        "mirror": _mirror_corr(hand),
        "facing_share": float(((facing[:, 0] >= st.palm_towards)
                               & (facing[:, 1] >= st.palm_towards)).mean()),
        "sep_mean_m": float(sep.mean()),
        "sep_change_m": float(sep.max() - sep.min()),
        "sep_hold_m": float(np.ptp(sep[-third:])),
        "straightness": [float(np.linalg.norm(hand[-1, h] - hand[0, h]) / max(paths[h], 1e-9))
                         for h in range(2)],
        "arc_m": [_arc(hand[:, h]) for h in range(2)],
        "lift_m": [float(hand[:, h, 2].max() - hand[0, h, 2]) for h in range(2)],
        "drop_m": [float(hand[0, h, 2] - hand[-1, h, 2]) for h in range(2)],
        "reach_raised": [float(reach[raised[:, h], h].max()) if raised[:, h].any() else 0.0
                         for h in range(2)],
        "lateral_m": [float(np.ptp(hand[:, h, 1])) for h in range(2)],
        "vertical_m": [float(np.ptp(hand[:, h, 2])) for h in range(2)],
        "outward_m": [float((hand[-1, h, 1] - hand[0, h, 1]) * (1 if h == 0 else -1))
                      for h in range(2)],
    }
    return out


def label_form(form: SegmentForm, settings: SignSettings | None = None) -> tuple[str, str]:
    """(sign, the rule that gave it) of a segment's :class:`SegmentForm` (pass 1)."""
    st = settings or SignSettings()
    f = form_features(form, st)
    act = [h for h in range(2) if f["active"][h]]
    if not act:
        if f["pitch_range_rad"] >= st.nod_range_rad and f["pitch_reversals"] >= 1:
            return "Head-nod", "no hand active; the head pitches down and up"
        if not any(f["in_space"]):
            return "Rest", "no hand active, hands below the gesture space"
        # a held hand in the gesture space: its posture decides (a hold of a sign)
        held = [h for h in range(2) if f["in_space"][h]]
        if len(held) == 2 and f["facing_share"] >= st.frame_share:
            lo, hi = st.frame_gap_m
            if lo <= f["sep_mean_m"] <= hi:
                return "Frame", "two hands held, palms facing"
        if all(f["palm_apex"][h][2] >= st.palm_up for h in held):
            return "Palm-face-up", "hands held palm up"
        return "Beats", "a hand held in the gesture space (no other sign's form)"
    act = [h for h in act if f["in_space"][h]]
    if not act:
        return "Rest", "hands moving below the gesture space (at the sides)"
    for h in act:
        if f["chest_dist_m"][h] <= st.self_dist_m and f["palm_to_chest"][h] >= st.palm_towards:
            return "Deictic.Self", "hand at the chest, palm towards the body"
    for h in act:
        if (f["turning_rad"][h] >= st.process_turn_rad and f["roundness"][h] >= st.round
                and f["extent_m"][h] >= st.process_extent_m):
            return "Process", "circular hand path"
    for h in act:
        if (f["palm_apex"][h][2] <= -st.palm_towards and f["extent_m"][h] <= st.wobble_extent_m
                and f["roll_reversals"][h] >= st.wobble_reversals
                and f["roll_range_rad"][h] >= st.wobble_range_rad):
            return "More-or-less", "palm-down hand rolling back and forth"
    for h in act:
        if (f["apex_rel_m"][h][0] >= st.front_m and f["palm_apex"][h][0] >= st.palm_towards
                and abs(f["apex_rel_m"][h][1]) <= st.block_side_m
                and f["apex_rel_m"][h][2] <= st.high_m
                and f["forward_m"][h] >= st.push_m and f["raised"][h]):
            return "Block", "hand pushed forward, palm to the front"
    both = len(act) == 2 and min(f["path_m"]) >= 0.5 * max(f["path_m"])
    if both and f["mirror"] >= st.symmetry:
        lo, hi = st.frame_gap_m
        palms_up = min(p[2] for p in f["palm_apex"]) >= st.palm_up
        apart = f["sep_change_m"] >= st.apart_m
        if (f["facing_share"] >= st.frame_share and lo <= f["sep_mean_m"] <= hi
                and f["sep_hold_m"] <= st.frame_hold_m):
            return "Frame", "two hands, palms facing, separation held"
        if palms_up and apart:
            return "Shrug", "two hands apart, palms up at the apex"
        if palms_up:
            return "Palm-face-up", "two hands, palms up at the apex"
        down_or_fwd = all(p[2] <= -0.3 or p[0] >= st.palm_towards for p in f["palm_apex"])
        if apart and down_or_fwd:
            straight = (min(f["straightness"]) >= st.straight and max(f["arc_m"]) < st.arc_m)
            return ("Wipe", "two hands apart on a straight line") if straight else (
                "Whole", "two hands apart on an arc")
    main = max(act, key=lambda h: f["path_m"][h])
    rel = f["apex_rel_m"][main]
    if (not both and f["reach_raised"][main] >= st.point_reach and rel[2] <= st.high_m
            and (rel[0] >= st.front_m or abs(rel[1]) >= st.side_m)):
        return "Deictic.Other", "arm reaching out, raised"
    if not both:
        h = main
        if f["palm_apex"][h][2] >= st.palm_up and f["lift_m"][h] >= st.lift_m:
            return "Palm-face-up", "hand lifted, palm up at the apex"
        if (f["lateral_m"][h] >= st.apart_m and f["lateral_m"][h] >= f["vertical_m"][h]
                and f["raised"][h]):
            if (f["straightness"][h] >= st.straight and f["arc_m"][h] < st.arc_m
                    and f["palm_apex"][h][2] <= -0.3):
                return "Wipe", "one hand sweeping sideways on a straight line, palm down"
            return "Dismiss", "one hand sweeping sideways on an arc"
        if f["outward_m"][h] >= st.apart_m / 2 and f["drop_m"][h] >= st.dismiss_drop_m:
            return "Dismiss", "one hand outwards and down"
    return "Beats", "no other sign's form (the catch-all)"


def label_segment(library: Any, i: int, settings: SignSettings | None = None) -> str:
    """The pass-1 sign of segment ``i`` of a :class:`MotionLibrary`."""
    return label_form(segment_form(library, i), settings)[0]


_LABELS: dict[tuple, list[str]] = {}

#: Bump when the rules of pass 1 change, so labels stored in library manifests are recomputed.
LABELLER_VERSION = 1


def labeller_key(settings: SignSettings | None = None) -> str:
    """Names the pass-1 labeller and its settings (the key of labels stored with a library)."""
    st = settings or SignSettings()
    digest = hashlib.sha256(repr(st).encode()).hexdigest()[:12]
    return f"form-v{LABELLER_VERSION}-{digest}"


def stored_form_signs(library: Any) -> tuple[str, tuple[str, ...]]:
    """``(key, signs)`` of the default labeller for ``library`` (what
    :meth:`~gesture_sim.motion.library.MotionLibrary.save` writes): the labels the library
    carries when their key is current, else labelled now and kept on the library."""
    key = labeller_key()
    form = getattr(library, "form_signs", None)
    if form is None or form[0] != key or len(form[1]) != len(library.segments):
        form = (key, tuple(label_library(library)))
        library.form_signs = form
    return form


def label_library(library: Any, settings: SignSettings | None = None) -> list[str]:
    """Pass-1 signs of every segment of ``library``: the labels stored with it when they were
    made by this labeller with these settings (:attr:`MotionLibrary.form_signs`), else labelled
    from the segments' forms (cached per fingerprint and settings)."""
    st = settings or SignSettings()
    form = getattr(library, "form_signs", None)
    if (form is not None and form[0] == labeller_key(st)
            and len(form[1]) == len(library.segments)):
        return list(form[1])
    key = (str(getattr(library, "fingerprint", id(library))), len(library.segments), st)
    if key not in _LABELS:
        if len(_LABELS) > 8:
            _LABELS.clear()
        _LABELS[key] = [label_segment(library, s.index, st) for s in library.segments]
    return list(_LABELS[key])


def library_signs(library: Any) -> tuple[list[str], str]:
    """(sign of each segment, where they came from): the signs stored on the library's segments
    (``Segment.sign``, from ``library build --signs``) where it has them, else pass 1.

    The source is ``"annotations"``, ``"form labeller"`` or ``"annotations + form labeller"``.
    """
    stored = [getattr(s, "sign", None) for s in library.segments]
    if all(s is None for s in stored):
        return label_library(library), "form labeller"
    if all(s is not None for s in stored):
        return [str(s) for s in stored], "annotations"
    auto = label_library(library)
    return ([str(s) if s is not None else a for s, a in zip(stored, auto, strict=True)],
            "annotations + form labeller")


def sign_counts(signs: list[str]) -> dict[str, int]:
    """{sign: count} in :data:`SIGNS` order, every sign listed (0 when absent)."""
    return {s: sum(1 for x in signs if x == s) for s in SIGNS}


# --------------------------------------------------------------------------------------------
# Pass 2: nearest prototype on key-point features
# --------------------------------------------------------------------------------------------

#: Names of the pass-2 features (:func:`keypoint_features`), all from the library's key points.
FEATURES: tuple[str, ...] = (
    "log_motion",     # log10 of the two hands' summed path (m), per second
    "two_handed",     # smaller / larger hand path (0 one hand, 1 both alike)
    "spread",         # change of the hands' separation, end - start (m)
    "height",         # mean height of the moving hand relative to the head (m)
    "forward",        # largest forward distance of the moving hand from the head (m)
    "straight",       # net / path of the moving hand
    "loops",          # turning of the moving hand's path / 2 pi
    "near_chest",     # smallest distance of a hand to the chest point (m)
    "nod",            # head height range / hand extent (head moving while hands do not)
    "forearm_up",     # elbow-to-hand direction z at the end (>0 forearm raised)
)

_NAN = float("nan")
#: The prototype of each sign over :data:`FEATURES`, written from its Table 3.1 description
#: (NaN: the description says nothing about that feature). Rest/Head-nod: hardly any motion;
#: Wipe/Whole/Shrug: two hands moving apart (Wipe straight, Whole and Shrug arcs, Shrug ending
#: low and open); Frame: two hands, separation kept; Dismiss: one hand to the side on an arc;
#: Block: one hand forward at chest height; More-or-less: one hand, little path, at the
#: body's front; Process: circles; Deictic.Other: the arm far out; Deictic.Self: a hand at
#: the chest; Beats: small one-handed up-down strokes.
PROTOTYPES: dict[str, tuple[float, ...]] = {
    #               motion two  spread height fwd  straight loops chest nod  forearm
    "Rest":         (-1.2, _NAN, 0.0, -0.75, 0.10, _NAN, _NAN, _NAN, 0.0, -0.9),
    "Palm-face-up": (-0.5, 0.8, 0.05, -0.45, 0.30, 0.7, 0.2, _NAN, _NAN, 0.3),
    "Head-nod":     (-1.2, _NAN, 0.0, -0.75, _NAN, _NAN, _NAN, _NAN, 1.0, -0.9),
    "Wipe":         (-0.2, 0.9, 0.25, -0.45, 0.30, 0.9, 0.1, _NAN, _NAN, 0.0),
    "Whole":        (-0.1, 0.9, 0.25, -0.40, 0.30, 0.6, 0.3, _NAN, _NAN, 0.2),
    "Frame":        (-0.4, 0.9, 0.0, -0.40, 0.30, 0.5, _NAN, _NAN, _NAN, 0.2),
    "Dismiss":      (-0.3, 0.2, _NAN, -0.45, 0.25, 0.6, 0.3, _NAN, _NAN, 0.0),
    "Block":        (-0.3, 0.2, _NAN, -0.35, 0.45, 0.8, 0.1, _NAN, _NAN, 0.3),
    "Shrug":        (-0.3, 0.9, 0.20, -0.55, 0.25, 0.6, 0.3, _NAN, _NAN, 0.1),
    "More-or-less": (-0.6, 0.2, _NAN, -0.45, 0.30, 0.3, 0.5, _NAN, _NAN, 0.1),
    "Process":      (-0.2, _NAN, _NAN, -0.45, 0.30, 0.2, 1.0, _NAN, _NAN, 0.2),
    "Deictic.Other": (-0.3, 0.1, _NAN, -0.30, 0.55, 0.8, 0.1, _NAN, _NAN, 0.5),
    "Deictic.Self": (-0.4, _NAN, _NAN, -0.45, 0.15, 0.7, _NAN, 0.05, _NAN, 0.3),
    "Beats":        (-0.6, 0.3, 0.0, -0.55, 0.25, 0.4, 0.2, _NAN, _NAN, 0.0),
}
#: Scale of each feature in the prototype distance (its unit's typical spread).
FEATURE_SCALES: tuple[float, ...] = (0.3, 0.3, 0.1, 0.15, 0.12, 0.25, 0.3, 0.08, 0.5, 0.4)


def keypoint_features(keypoints: np.ndarray, fps: float) -> np.ndarray:
    """(len(FEATURES),) pass-2 features of a segment's key points (T, K, 3) (heading frame, m;
    K >= 5 in :data:`gesture_sim.motion.retarget.KEYPOINTS` order: hands, elbows, head)."""
    kp = np.asarray(keypoints, dtype=float)
    hands, elbows, head = kp[:, 0:2], kp[:, 2:4], kp[:, 4]
    t = max(len(kp), 2)
    paths = np.array([_path(hands[:, h]) for h in range(2)])
    main = int(np.argmax(paths))
    p = hands[:, main]
    sep = np.linalg.norm(hands[:, 0] - hands[:, 1], axis=1)
    chest = head + np.array([0.08, 0.0, -0.30])
    near = np.linalg.norm(hands - chest[:, None], axis=2).min()
    ext = max(_extent(p), 1e-3)
    fa = hands[-1, main] - elbows[-1, main]
    fa = fa / max(float(np.linalg.norm(fa)), 1e-9)
    return np.array([
        math.log10(max(paths.sum() * fps / t, 1e-3)),
        float(paths.min() / max(paths.max(), 1e-9)),
        float(sep[-1] - sep[0]),
        float((p[:, 2] - head[:, 2]).mean()),
        float((p[:, 0] - head[:, 0]).max()),
        float(np.linalg.norm(p[-1] - p[0]) / max(paths[main], 1e-9)),
        _turning(p) / (2 * math.pi),
        float(near),
        min(float(np.ptp(head[:, 2])) / ext, 3.0),
        float(fa[2]),
    ])


#: Pass 2's catch-all: a segment farther than this (scaled RMS) from every prototype is Beats,
#: as the thesis's annotators gave Beats to a gesture matching no sign ("within one typical
#: spread per stated feature", chosen before looking at the result).
MAX_PROTOTYPE_DISTANCE = 1.0


def prototype_distances(features: np.ndarray) -> dict[str, float]:
    """{sign: scaled RMS distance of ``features`` to its :data:`PROTOTYPES` row}, over the
    features that row states."""
    x = np.asarray(features, dtype=float)
    scale = np.asarray(FEATURE_SCALES)
    out = {}
    for sign in SIGNS:
        proto = np.asarray(PROTOTYPES[sign])
        ok = ~np.isnan(proto)
        out[sign] = float(np.sqrt(np.mean(((x[ok] - proto[ok]) / scale[ok]) ** 2)))
    return out


def prototype_label(features: np.ndarray,
                    max_distance: float = MAX_PROTOTYPE_DISTANCE) -> str:
    """The sign whose :data:`PROTOTYPES` row is nearest to ``features`` (pass 2): RMS of the
    scaled differences over the features the prototype states; Beats when none is within
    ``max_distance``."""
    d = prototype_distances(features)
    best = min(SIGNS, key=lambda s: (d[s], SIGNS.index(s)))
    return best if d[best] <= max_distance else "Beats"


def prototype_library(library: Any) -> list[str]:
    """Pass-2 signs of every segment of ``library``."""
    return [prototype_label(keypoint_features(library.segment_keypoints(s.index), library.fps))
            for s in library.segments]


def cohen_kappa(a: list[str], b: list[str]) -> dict[str, float]:
    """Agreement of two labellings of the same items: ``{"agreement", "kappa", "n"}``
    (Cohen's kappa = (p_o - p_e) / (1 - p_e); 1.0 when both are one and the same constant)."""
    if len(a) != len(b):
        raise GestureSimError(f"{len(a)} labels against {len(b)}")
    n = len(a)
    if n == 0:
        return {"agreement": math.nan, "kappa": math.nan, "n": 0}
    po = sum(x == y for x, y in zip(a, b, strict=True)) / n
    cats = set(a) | set(b)
    pe = sum((a.count(c) / n) * (b.count(c) / n) for c in cats)
    kappa = 1.0 if pe >= 1.0 else (po - pe) / (1.0 - pe)
    return {"agreement": round(po, 4), "kappa": round(kappa, 4), "n": n}


def settings_dict(settings: SignSettings | None = None) -> dict[str, Any]:
    """The thresholds as a JSON-ready dict."""
    st = settings or SignSettings()
    return {f.name: getattr(st, f.name) for f in fields(st)}


# --------------------------------------------------------------------------------------------
# Annotations: a CSV or an ELAN tab-delimited export -> signs on a library's segments
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SignAnnotation:
    """One annotated span: ``sign`` over ``[start_s, end_s)`` (s, clip time) of a clip.

    Attributes:
        clip: the clip's name (a CSV's ``clip`` column), or ``None`` for an ELAN row (then
            ``tier`` or the file's stem names the clip, see :func:`apply_sign_annotations`).
        start_s, end_s: span (s from the clip's first frame).
        sign: one of :data:`SIGNS`.
        tier: the ELAN tier name ("" for a CSV row).
        stem: the annotation file's stem.
        line: the line number in the file.
        file: the annotation file's path (for messages).
    """

    clip: str | None
    start_s: float
    end_s: float
    sign: str
    tier: str = ""
    stem: str = ""
    line: int = 0
    file: str = ""


def _seconds(text: str) -> float | None:
    """Seconds of ``ss.msec`` or ``[hh:]mm:ss.mmm``; ``None`` when it is no time."""
    t = text.strip()
    try:
        if ":" in t:
            parts = [float(p) for p in t.split(":")]
            if len(parts) > 3:
                return None
            v = 0.0
            for p in parts:
                v = v * 60.0 + p
            return v
        return float(t)
    except ValueError:
        return None


def read_sign_annotations(path: str | Any) -> list[SignAnnotation]:
    """Read sign annotations from a CSV or an ELAN tab-delimited export.

    * **CSV** (comma-separated, with a header naming ``clip,start_s,end_s,sign``; other columns
      are ignored): one span per row, times in seconds.
    * **ELAN** "Export as tab-delimited text": per line the tier name first, the annotation
      value last, and between them the begin, end (and optionally duration) times, as
      ``ss.msec`` or ``hh:mm:ss.mmm`` (empty columns, e.g. no participant, are skipped); a header
      line (no times) is skipped.

    Sign values are matched by :func:`canonical_sign` (case, spaces, "Everything" forgiven).

    Raises:
        GestureSimError: an unreadable file, a row without two times, a value that names no
            sign, or an end before its start (each naming the file and the line).
    """
    import csv
    from pathlib import Path

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise GestureSimError(f"cannot read sign annotations {p}: {exc}") from exc
    lines = text.splitlines()
    first = next((ln for ln in lines if ln.strip()), "")
    out: list[SignAnnotation] = []

    def bad(n: int, why: str) -> GestureSimError:
        return GestureSimError(f"{p}:{n}: {why}")

    def sign_of(n: int, value: str) -> str:
        try:
            return canonical_sign(value)
        except GestureSimError as exc:
            raise bad(n, str(exc)) from None

    header = [h.strip().lower() for h in first.split(",")]
    if "\t" not in first and {"clip", "start_s", "end_s", "sign"} <= set(header):
        rows = csv.DictReader(lines)
        for n, row in enumerate(rows, start=2):
            row = {str(k).strip().lower(): (v or "").strip() for k, v in row.items() if k}
            if not any(row.values()):
                continue
            a, b = _seconds(row.get("start_s", "")), _seconds(row.get("end_s", ""))
            if a is None or b is None:
                raise bad(n, "start_s and end_s must be times in seconds")
            if b <= a:
                raise bad(n, f"end {b} s is not after start {a} s")
            out.append(SignAnnotation(clip=row["clip"], start_s=a, end_s=b,
                                      sign=sign_of(n, row["sign"]), stem=p.stem, line=n,
                                      file=str(p)))
        return out
    if "\t" not in first:
        raise GestureSimError(
            f"{p}: neither a CSV with the header clip,start_s,end_s,sign nor an ELAN "
            "tab-delimited export")
    for n, line in enumerate(lines, start=1):
        cells = [c.strip() for c in line.split("\t")]
        cells = [c for c in cells if c != ""]
        if len(cells) < 3:
            if cells:
                raise bad(n, "expected tier, begin, end (duration) and value separated by tabs")
            continue
        times = [_seconds(c) for c in cells[1:-1]]
        if not any(t is not None for t in times):
            if n == 1:
                continue                      # a header line
            raise bad(n, "no begin and end times")
        ts = [t for t in times if t is not None]
        if len(ts) < 2:
            raise bad(n, "expected a begin and an end time")
        a, b = ts[0], ts[1]
        if b <= a:
            raise bad(n, f"end {b} s is not after begin {a} s")
        out.append(SignAnnotation(clip=None, start_s=a, end_s=b, sign=sign_of(n, cells[-1]),
                                  tier=cells[0], stem=p.stem, line=n, file=str(p)))
    return out


def _clip_of(a: SignAnnotation, names: list[str]) -> str | None:
    """The clip an annotation is for (the rules of :func:`apply_sign_annotations`), or None
    when ``names`` hold none of its candidates."""
    if a.clip is not None:
        return a.clip if a.clip in names else None
    for candidate in (a.tier, a.stem):
        if candidate in names:
            return candidate
    return names[0] if len(names) == 1 else None


def check_annotation_times(annotations: list[SignAnnotation],
                           durations: dict[str, float]) -> None:
    """Every annotation's span within its clip (``durations``: clip name -> seconds, the
    motion files' lengths): none before 0 s, none past the clip's end by more than
    :data:`~gesture_sim.validation.SIDE_FILE_OVERRUN_S` (the one rule of every side file).
    Annotations of clips not in ``durations`` are left to :func:`apply_sign_annotations`.

    Raises:
        GestureSimError: one line naming the annotation file, its line and the clip.
    """
    from gesture_sim.validation import side_file_times

    names = list(durations)
    for a in annotations:
        clip = _clip_of(a, names)
        if clip is None:
            continue
        side_file_times("--signs", f"{a.file or a.stem}:{a.line}",
                        [(a.start_s, a.end_s, f"the {a.sign} span")], durations[clip],
                        f"the clip {clip}", "is the file for this motion?")


def apply_sign_annotations(library: Any, annotations: list[SignAnnotation],
                           min_overlap: float = 0.5) -> dict[str, Any]:
    """Give each segment of ``library`` the sign of the annotation that overlaps it most, if
    that covers at least ``min_overlap`` of the segment's length; the others keep their sign
    (``None`` when not annotated). Changes ``library.segments`` in place.

    An ELAN row's clip is its tier name when that names a clip, else the file's stem, else the
    library's only clip.

    Returns:
        ``{"annotations", "labelled", "unlabelled", "counts"}`` (counts of the signs given).

    Raises:
        GestureSimError: an annotation whose clip the library does not have.
    """
    names = [c.name for c in library.clips]
    index = {n: k for k, n in enumerate(names)}
    per_clip: dict[int, list[SignAnnotation]] = {}
    for a in annotations:
        if a.clip is not None:
            clip = a.clip
        elif a.tier in index:
            clip = a.tier
        elif a.stem in index:
            clip = a.stem
        elif len(names) == 1:
            clip = names[0]
        else:
            more = " ..." if len(names) > 4 else ""
            raise GestureSimError(
                f"{a.file or a.stem}:{a.line}: tier {a.tier!r} names no clip of the library; "
                f"name the tier or the file as the clip ({', '.join(names[:4])}{more})")
        if clip not in index:
            raise GestureSimError(
                f"{a.file or a.stem}:{a.line}: the library has no clip {clip!r}")
        per_clip.setdefault(index[clip], []).append(a)
    given: list[str] = []
    fps = float(library.fps)
    for seg in library.segments:
        spans = per_clip.get(seg.clip)
        if not spans:
            continue
        s0, s1 = seg.start / fps, seg.end / fps
        best, best_ov = None, 0.0
        for a in spans:
            ov = min(s1, a.end_s) - max(s0, a.start_s)
            if ov > best_ov + 1e-12:
                best, best_ov = a, ov
        if best is not None and best_ov >= min_overlap * (s1 - s0) - 1e-9:
            seg.sign = best.sign
            given.append(best.sign)
    n = len(library.segments)
    return {"annotations": len(annotations), "labelled": len(given),
            "unlabelled": n - len(given), "counts": sign_counts(given)}
