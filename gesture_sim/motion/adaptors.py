"""Self-touches (adaptors) among a library's segments, from the humanoid's own kinematics.

An adaptor (Ekman & Friesen 1969) is a hand touching one's own head, face, chin or neck — a
scratch, a chin rest, a hand smoothing the hair. It is not a co-speech gesture: like an emblem it
should play only when asked for, so the control layer leaves it out of the segments it chooses
without a label (:meth:`gesture_sim.control.inputs.ControlLibrary.from_motion_library`).

The rule (lengths in metres, time in frames of the segment):

* every frame of a segment is posed on the humanoid (``assets/mjcf/humanoid.xml``:
  :func:`~gesture_sim.sim.humanoid.qpos_from_targets`, ``mujoco.mj_kinematics``), the root at the
  standing pose — where the hand is relative to the head depends on the spine and arm joints
  only, not on the root or the legs;
* the **hand** is every geom of the body that carries ``left_hand_site`` / ``right_hand_site``
  and of its descendants (fingers, where the body has them); the **head** is every geom of the
  body that carries ``head_site`` and of its descendants (jaw, chin, brows, lids) and of its
  parent, the neck;
* a frame is a **touch** when the surface gap between a hand and the head (MuJoCo's signed geom
  distance, ``mj_geomDistance``; 0 at contact) is at most :data:`TOUCH_GAP_M` = 0.03 m. Contact
  itself is a gap of 0; the 3 cm allow for the humanoid's simple shapes against a real body
  (hair, ears and nose, fingers outside the hand's ellipsoid, the retargeted proportions). On the
  humanoid a touch puts the palm centre (``*_hand_site``) within about 0.11 m (the palm on the
  head: cranium semi-axes 0.078–0.097 m, hand half thickness 0.02 m) to 0.20 m (the fingers at
  the chin: the hand ellipsoid reaches 0.085 m beyond the palm centre) of the cranium's centre;
  a hand 5 cm in front of the face is no touch;
* a segment is an **adaptor** when at least :data:`MIN_TOUCH_SHARE` = 0.25 of its frames are
  touches, **or** when its touches include a continuous **hold** of at least
  :data:`MIN_HOLD_S` = 0.25 s (8 frames at 30 fps). The segmentation cuts at hand-speed minima,
  so a self-touch segment is usually the approach, the hold at the face and the retreat (the
  share); the hold catches a self-touch inside a longer segment (a long approach, a chin rest
  at the end of a gesture), whose share can fall under a quarter. What an adaptor is, is the
  hand *held* at the head: a chin rest or a scratch lasts half a second and more (the one
  self-touch of the shipped library, segment 390 of ``dataset-1_guide_feminine_001``, holds
  16 frames, 0.53 s, 47 % of its frames), while a hand passing the face crosses the 3-cm band
  in a few frames (at the co-speech hands' median speed, 0.75 m/s, 10 cm of path along the
  head take 0.13 s; the hand that the timing layer's amplitude once brought to the jaw on take
  2_2 stayed there 4 frames); 0.25 s is twice such a passage and half the shortest hold seen.

On the shipped library (``motion_library/default``, 497 segments, 67 of them in untagged clips)
the hold changes no tag: no frame of a co-speech segment comes within 10 cm of the head (the
closest, segment 66, 13.1 cm), so the 67 stay co-speech with either rule; of the 430 segments of
tagged clips (emblems, acting) one has touches at all (segment 390 above: 16 frames in a row,
an adaptor by both rules; a tagged clip plays only when asked for anyway).

The hands touching each other, the chest or the belly are not counted: those are rest positions
and deictics ("me") of ordinary co-speech motion.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

from gesture_sim.errors import GestureSimError

#: Largest surface gap (m) between a hand and the head/face/neck that counts as a touch.
TOUCH_GAP_M = 0.03
#: Smallest share of a segment's frames that must be touches for the segment to be an adaptor.
MIN_TOUCH_SHARE = 0.25
#: Shortest continuous run of touch frames (s) that makes a segment an adaptor whatever its share:
#: a hand held at the head, not one passing it (see the module docstring).
MIN_HOLD_S = 0.25
#: Frame rate (Hz) the hold is counted at when a caller gives none (the libraries' rate).
DEFAULT_FPS = 30.0
#: The tag (and semantic label) the control layer gives adaptor segments.
SELF_TOUCH_TAG = "self_touch"
#: Gaps are computed exactly up to this distance (m) and reported as this value beyond it.
GAP_CAP_M = 0.10


def _descendants(model, root: int) -> list[int]:
    """``root`` and every body below it (MuJoCo orders parents before their children)."""
    out = [root]
    for b in range(root + 1, model.nbody):
        if int(model.body_parentid[b]) in out:
            out.append(b)
    return out


class HeadTouch:
    """Hand-to-head surface gaps of humanoid poses (see the module docstring for the rule)."""

    def __init__(self, model=None) -> None:
        import mujoco

        from gesture_sim.sim import humanoid as hm

        self._mj = mujoco
        self.model = model if model is not None else hm.load_model(scene=False)
        self.data = mujoco.MjData(self.model)
        m = self.model
        head_body = int(m.site_bodyid[m.site(hm.HEAD_SITE).id])
        head_bodies = set(_descendants(m, head_body)) | {int(m.body_parentid[head_body])}
        self.head_geoms = np.array([g for g in range(m.ngeom)
                                    if int(m.geom_bodyid[g]) in head_bodies], dtype=int)
        self.hand_geoms = []
        for site in hm.HAND_SITES:
            bodies = set(_descendants(m, int(m.site_bodyid[m.site(site).id]))) - head_bodies
            self.hand_geoms.append(np.array([g for g in range(m.ngeom)
                                             if int(m.geom_bodyid[g]) in bodies], dtype=int))
        if not len(self.head_geoms) or not all(len(g) for g in self.hand_geoms):
            raise GestureSimError("the humanoid has no hand or head geoms to measure touches")
        self._hm = hm
        self._act_adr = hm.qpos_addresses(m)
        self._base = hm.qpos_from_targets(m, np.zeros(len(hm.ACTUATED_JOINTS)))

    def _addresses(self, joint_names) -> np.ndarray:
        return self._act_adr[self._hm.actuated_index(tuple(joint_names))]

    def gaps(self, qpos: np.ndarray, joint_names, cap: float = GAP_CAP_M) -> np.ndarray:
        """(T, 2) smallest surface gap (m) of the left and the right hand to the head, per frame
        of ``qpos`` (T, n_joints) whose columns are ``joint_names`` (humanoid joints; the others
        stay at the standing pose); gaps beyond ``cap`` are reported as ``cap``."""
        mj, m, d = self._mj, self.model, self.data
        qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
        adr = self._addresses(joint_names)
        if qpos.shape[1] != len(adr):
            raise GestureSimError(
                f"poses have {qpos.shape[1]} columns for {len(adr)} joint names")
        base = self._base
        rb = m.geom_rbound
        out = np.full((len(qpos), 2), float(cap))
        for t, q in enumerate(qpos):
            d.qpos[:] = base
            d.qpos[adr] = q
            mj.mj_kinematics(m, d)
            hc = d.geom_xpos[self.head_geoms]
            for h, hand in enumerate(self.hand_geoms):
                # bounding spheres first: most frames have both hands far from the head
                lower = (np.linalg.norm(d.geom_xpos[hand][:, None] - hc[None], axis=-1)
                         - rb[hand][:, None] - rb[self.head_geoms][None])
                for i, j in zip(*np.nonzero(lower < cap), strict=True):
                    g = mj.mj_geomDistance(m, d, int(hand[i]), int(self.head_geoms[j]),
                                           float(cap), None)
                    out[t, h] = min(out[t, h], g)
        return out

    def touches(self, qpos: np.ndarray, joint_names, gap: float = TOUCH_GAP_M) -> np.ndarray:
        """(T,) bool: frames where either hand is within ``gap`` (m) of the head's surface."""
        return self.gaps(qpos, joint_names, cap=max(GAP_CAP_M, gap)).min(axis=1) <= gap

    def is_adaptor(self, qpos: np.ndarray, joint_names, gap: float = TOUCH_GAP_M,
                   share: float = MIN_TOUCH_SHARE, hold_s: float | None = MIN_HOLD_S,
                   fps: float = DEFAULT_FPS) -> bool:
        """Whether a segment's poses (T, n_joints) at ``fps`` are a self-touch (the module's
        rule): touches on at least ``share`` of the frames, or a run of touch frames lasting at
        least ``hold_s`` seconds (None: the share alone)."""
        touch = self.touches(qpos, joint_names, gap)
        if not len(touch):
            return False
        if float(touch.mean()) >= share:
            return True
        return hold_s is not None and longest_run(touch) >= hold_frames(hold_s, fps)


def hold_frames(hold_s: float, fps: float = DEFAULT_FPS) -> int:
    """Frames a hold of ``hold_s`` seconds spans at ``fps`` (at least 1): n frames last n/fps."""
    return max(1, int(np.ceil(float(hold_s) * float(fps) - 1e-9)))


def longest_run(mask: np.ndarray) -> int:
    """Length of the longest run of consecutive True values of a (T,) bool array."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return int((edges[1::2] - edges[::2]).max()) if len(edges) else 0


@lru_cache(maxsize=1)
def head_touch() -> HeadTouch:
    """The :class:`HeadTouch` of the shipped humanoid (built once)."""
    return HeadTouch()


_CACHE: dict[tuple, np.ndarray] = {}


def adaptor_segments(library: Any, indices=None, gap: float = TOUCH_GAP_M,
                     share: float = MIN_TOUCH_SHARE,
                     hold_s: float | None = MIN_HOLD_S) -> np.ndarray:
    """(n_segments,) bool: the segments of ``library`` that are self-touches.

    ``library`` is duck-typed: ``segments``, ``segment_qpos(i)`` and ``joint_names`` (the
    humanoid's joint names, as a :class:`~gesture_sim.motion.library.MotionLibrary` has) and
    ``fps`` (default :data:`DEFAULT_FPS`) for the hold; ``indices``: only these segments are
    examined (the others are False). Results are cached per library fingerprint.

    Raises:
        GestureSimError: the library's joints are not the humanoid's.
    """
    n = len(library.segments)
    idx = tuple(range(n)) if indices is None else tuple(int(i) for i in indices)
    fp = getattr(library, "fingerprint", None)
    fps = float(getattr(library, "fps", DEFAULT_FPS) or DEFAULT_FPS)
    hold = None if hold_s is None else float(hold_s)
    key = (str(fp), n, idx, float(gap), float(share), hold, fps) if fp else None
    if key is not None and key in _CACHE:
        return _CACHE[key].copy()
    names = tuple(library.joint_names)
    touch = head_touch()
    out = np.zeros(n, dtype=bool)
    for i in idx:
        out[i] = touch.is_adaptor(library.segment_qpos(i), names, gap, share, hold, fps)
    if key is not None:
        if len(_CACHE) > 8:
            _CACHE.clear()
        _CACHE[key] = out.copy()
    return out
