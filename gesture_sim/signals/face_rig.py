"""The face rig: articulation and expression values -> the humanoid's face joint offsets.

The humanoid's face (``assets/mjcf/humanoid.xml``) has a hinged jaw and light slide joints for
the lips, mouth corners, inner and outer brows and upper lids, and two hinges per eye; the
human look's skin follows those bodies (``tools/build_skin.py``). This module is the one place
that knows how a mouth shape or an action unit becomes joint offsets (m for slides, rad for
hinges), so that the visemes (:mod:`gesture_sim.signals.visemes`), RUTH's signals and the gaze
all drive the face the same way.

Mouth (:func:`mouth_offsets`), from the viseme channels :data:`MOUTH_CHANNELS`:

* ``jaw_open`` (rad) opens the jaw; the lower lip rides on it, so the lips part by about
  ``LIP_RADIUS_M * sin(jaw_open)`` (the lower lip's distance from the jaw hinge).
* ``lip_close`` (0..1) closes that gap: the lower lip rises by ``LOWER_SHARE`` of it and the
  upper lip comes down by the rest (/p b m/ close the lips over a slightly open jaw).
* ``lip_round`` (0..1) pushes both lips forward and draws the corners in; ``lip_spread`` (0..1)
  draws the corners out.
* ``lip_tuck`` (0..1) lifts the lower lip up and back under the upper teeth (/f v/).
* ``tongue_tip`` has no joint (the tongue moves with the jaw): it is accepted and not shown.

A smile (``smile`` 0..1, RUTH's ``S``) competes with the mouth shape as RUTH has it (its own
dominance, DeCarlo et al. 2004 §1.4): the corners are the dominance-weighted mean of the
viseme's corners (weight 1) and the smile's corners (weight ``SMILE_DOMINANCE * smile``), so
a full smile still lets /uw/ round the lips a little.

Brows (:func:`brow_offsets`): AU1 raises the inner brows, AU2 the outer brows, AU4 lowers the
inner brows and draws them together (RUTH's ``1+2`` drives AU1 and AU2 together, ``4`` AU4).
Eyes (:func:`gaze_offsets`): yaw > 0 looks to the body's left, pitch > 0 down (rad); the upper
lids follow the eyes down.
"""

from __future__ import annotations

import numpy as np

#: The viseme channels, in the order of :meth:`gesture_sim.signals.visemes.Coarticulator.at`.
MOUTH_CHANNELS: tuple[str, ...] = ("jaw_open", "lip_close", "lip_round", "lip_spread",
                                   "lip_tuck", "tongue_tip")
#: The joints :func:`mouth_offsets` drives, in the order of its output.
MOUTH_JOINTS: tuple[str, ...] = (
    "jaw_open", "lower_lip_raise", "lower_lip_forward", "upper_lip_raise", "upper_lip_forward",
    "left_lip_corner_out", "left_lip_corner_up", "right_lip_corner_out", "right_lip_corner_up",
)
#: The lower lip's distance from the jaw hinge (m): the lips part by about this times
#: sin(jaw opening).
LIP_RADIUS_M = 0.105
#: Share of the lip gap the lower lip closes (the upper lip closes the rest).
LOWER_SHARE = 0.75
#: Full-scale offsets (m): lips forward when rounded, corners in when rounded, corners out when
#: spread, the lower lip back when tucked (and up by the gap plus ``TUCK_LIFT_M``).
ROUND_FORWARD_M = 0.005
ROUND_CORNER_IN_M = 0.007
SPREAD_CORNER_OUT_M = 0.005
SPREAD_CORNER_UP_M = 0.001
TUCK_BACK_M = 0.005
TUCK_LIFT_M = 0.002
#: A full smile's corners (m) and its dominance against the mouth shape.
SMILE_CORNER_UP_M = 0.007
SMILE_CORNER_OUT_M = 0.004
SMILE_DOMINANCE = 3.0
#: Full-scale brow action units (m): AU1 inner raise, AU2 outer raise, AU4 inner lowering and
#: the inner brows drawn together.
AU1_M = 0.010
AU2_M = 0.010
AU4_DOWN_M = 0.005
AU4_SQUEEZE_M = 0.004
#: The joints :func:`brow_offsets` drives, in the order of its output.
BROW_JOINTS: tuple[str, ...] = (
    "left_brow_inner_raise", "right_brow_inner_raise", "left_brow_raise", "right_brow_raise",
    "left_brow_inner_squeeze", "right_brow_inner_squeeze",
)
#: The joints :func:`gaze_offsets` drives, in the order of its output.
GAZE_JOINTS: tuple[str, ...] = ("left_eye_yaw", "left_eye_pitch", "right_eye_yaw",
                                "right_eye_pitch", "left_eyelid_close", "right_eyelid_close")
#: Upper-lid travel (m) per radian of looking down.
LID_FOLLOW_M_PER_RAD = 0.012


def mouth_offsets(channels: np.ndarray, smile: float | np.ndarray = 0.0) -> np.ndarray:
    """Offsets on :data:`MOUTH_JOINTS` (rad, m) of a mouth shape.

    Args:
        channels: (6,) or (T, 6) values of :data:`MOUTH_CHANNELS`.
        smile: the smile's level in [0, 1] (scalar or (T,)).

    Returns:
        (9,) or (T, 9) offsets.
    """
    c = np.asarray(channels, dtype=float)
    one = c.ndim == 1
    c = np.atleast_2d(c)
    jaw, close, rnd, spread, tuck = (np.clip(c[:, k], lo, hi) for k, (lo, hi) in
                                     enumerate(((0.0, 0.45), (0, 1), (0, 1), (0, 1), (0, 1))))
    s = np.clip(np.broadcast_to(np.asarray(smile, dtype=float), jaw.shape), 0.0, 1.0)
    gap = LIP_RADIUS_M * np.sin(jaw)
    out = np.zeros((len(c), len(MOUTH_JOINTS)))
    out[:, 0] = jaw
    out[:, 1] = LOWER_SHARE * gap * close + tuck * (gap + TUCK_LIFT_M)
    out[:, 2] = ROUND_FORWARD_M * rnd - TUCK_BACK_M * tuck
    out[:, 3] = -(1.0 - LOWER_SHARE) * gap * close
    out[:, 4] = ROUND_FORWARD_M * rnd
    corner_out = SPREAD_CORNER_OUT_M * spread - ROUND_CORNER_IN_M * rnd
    corner_up = SPREAD_CORNER_UP_M * spread
    w = SMILE_DOMINANCE * s
    corner_out = (corner_out + w * SMILE_CORNER_OUT_M) / (1.0 + w)
    corner_up = (corner_up + w * SMILE_CORNER_UP_M) / (1.0 + w)
    out[:, 5] = out[:, 7] = corner_out
    out[:, 6] = out[:, 8] = corner_up
    return out[0] if one else out


def brow_offsets(au1: float, au2: float, au4: float) -> np.ndarray:
    """Offsets on :data:`BROW_JOINTS` (m) of the brow action units, each in [0, 1]: (6,)."""
    a1, a2, a4 = (float(np.clip(a, 0.0, 1.0)) for a in (au1, au2, au4))
    inner = AU1_M * a1 - AU4_DOWN_M * a4
    return np.array([inner, inner, AU2_M * a2, AU2_M * a2, AU4_SQUEEZE_M * a4,
                     AU4_SQUEEZE_M * a4])


def gaze_offsets(yaw: float, pitch: float) -> np.ndarray:
    """Offsets on :data:`GAZE_JOINTS` of a gaze direction (rad; both eyes alike, the lids
    following a downward look): (6,)."""
    lid = LID_FOLLOW_M_PER_RAD * max(float(pitch), 0.0)
    return np.array([yaw, pitch, yaw, pitch, lid, lid], dtype=float)
