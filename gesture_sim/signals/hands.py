"""The hands: finger poses and a relaxed hand that lives.

The humanoid's fingers (``assets/mjcf/humanoid.xml``, header "Fingers") are placed on the
MakeHuman rig's finger bones; their qpos = 0 is the mesh's own rest hand, whose fingers are
slightly curled (:data:`MESH_REST_DEG`). This module speaks of finger angles *from straight*
(degrees, flexion > 0 curls, spread > 0 abducts away from the middle finger, thumb opposition
> 0 swings the thumb in front of the palm) and turns them into joint values q (rad) by
subtracting the mesh's rest (:func:`hand_q`).

* :data:`SHAPES`: a fist, a point, an open spread hand, a flat hand and the relaxed hand.
* :class:`HandLayer`: a layer stage (``name``, ``joints``, ``reset()``, ``step(t, heard)``, as
  :class:`gesture_sim.stages.FaceLayer`) whose offsets hold the relaxed hand, with a slow
  seeded band-limited noise of a few degrees per joint, a little more curl in silence (the
  hand at rest at the side) and a little more extension while speaking, more with energy.
* The SMPL-X hand pose -> finger joints mapping and the mesh's rest hand live with the finger
  tracks (:mod:`gesture_sim.motion.finger_tracks`), where the library build uses them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gesture_sim.motion.finger_tracks import HAND_JOINTS, MESH_REST_DEG, RELAXED_DEG, _shape
from gesture_sim.sim.humanoid import FINGER_JOINTS, FINGERS

if TYPE_CHECKING:

    from gesture_sim.audio.speech import Heard

_SIDES = ("left", "right")


#: Hand shapes (deg from straight) for figures and tests.
SHAPES: dict[str, dict[str, float]] = {
    "relaxed": RELAXED_DEG,
    "flat": {j: 0.0 for j in HAND_JOINTS},
    "spread": _shape((20.0, -15.0, 0.0, 0.0),
                     {"index": (15.0, 0.0, 0.0, 0.0), "middle": (3.0, 0.0, 0.0, 0.0),
                      "ring": (12.0, 0.0, 0.0, 0.0), "little": (18.0, 0.0, 0.0, 0.0)}),
    "fist": _shape((40.0, 30.0, 40.0, 45.0),
                   {f: (0.0, 85.0, 95.0, 60.0) for f in FINGERS[1:]}),
    "point": _shape((40.0, 30.0, 40.0, 45.0),
                    {"index": (0.0, 0.0, 0.0, 0.0), "middle": (0.0, 85.0, 95.0, 60.0),
                     "ring": (0.0, 85.0, 95.0, 60.0), "little": (0.0, 85.0, 95.0, 60.0)}),
}


def hand_q(angles_deg: dict[str, float]) -> np.ndarray:
    """Joint values (rad) of one hand, shape (20,) in :data:`HAND_JOINTS` order, from angles
    from straight (deg, keyed by :data:`HAND_JOINTS`; missing joints: the mesh's rest)."""
    return np.radians([angles_deg.get(j, MESH_REST_DEG[j]) - MESH_REST_DEG[j]
                       for j in HAND_JOINTS])


def both_hands_q(left: dict[str, float], right: dict[str, float] | None = None) -> np.ndarray:
    """Joint values (rad) of both hands, shape (40,) in :data:`FINGER_JOINTS` order."""
    return np.concatenate([hand_q(left), hand_q(left if right is None else right)])


# --------------------------------------------------------------------------------------------
# the relaxed hand that lives

#: Band-limited noise: a knot every ``NOISE_KNOT_S`` seconds, Catmull-Rom interpolated (a
#: spectrum below about 1 / (2 * NOISE_KNOT_S) Hz); per joint an own part of SD
#: ``NOISE_JOINT_DEG`` and a part shared by the flexions of the hand, SD ``NOISE_HAND_DEG``
#: (the fingers of a resting hand drift together, each a little on its own): about 3 deg a
#: flexion joint in all.
NOISE_KNOT_S = 1.3
NOISE_JOINT_DEG = 2.0
NOISE_HAND_DEG = 2.2
#: Curl added in silence (x the relaxed flexion) and extension while speaking at the top of
#: the energy (x the relaxed flexion), with the spread added then (deg); time constant of the
#: change (s).
REST_CURL = 0.08
SPEAK_OPEN = 0.35
SPEAK_SPREAD_DEG = 4.0
OPEN_TAU_S = 0.7
#: Crossfade (s) between the relaxed hand and a clip's own finger motion.
TRACK_FADE_S = 0.25

_FLEX = np.array(["flex" in j for j in HAND_JOINTS])
_SPREAD = np.array([j.endswith("spread") for j in HAND_JOINTS])


def _catmull_rom(p0, p1, p2, p3, u: float):
    u2, u3 = u * u, u * u * u
    return 0.5 * ((2.0 * p1) + (p2 - p0) * u + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * u2
                  + (3.0 * (p1 - p2) + p3 - p0) * u3)


class HandLayer:
    """Finger offsets of both hands: the relaxed hand (:data:`RELAXED_DEG`), alive.

    A layer stage as :class:`gesture_sim.stages.FaceLayer`: ``name`` "hands", ``joints``
    :data:`~gesture_sim.sim.humanoid.FINGER_JOINTS` (40), :meth:`reset`, :meth:`step`. The
    offsets (rad) are added onto the clip's finger targets (0 in a library without finger
    motion: the mesh's rest hand). The noise is a function of ``t`` and the seed only, so a
    run is reproducible at any control rate; the openness follows ``heard.speaking`` and
    ``heard.energy`` through a first-order low-pass (:data:`OPEN_TAU_S`).

    **Clips with finger motion.** With ``tracks`` (clip index -> (T, 40) finger targets in rad,
    :mod:`gesture_sim.motion.finger_tracks`) and ``playing`` (a function giving the (clip,
    frame) the body plays, or None at rest), the fingers play the clip's own finger motion
    while a clip that has one plays, crossfaded with the relaxed hand over
    :data:`TRACK_FADE_S` when such a clip starts or ends.

    Args:
        seed: seeds the noise (each hand its own).
        amplitude: scales the noise (1: :data:`NOISE_JOINT_DEG`, :data:`NOISE_HAND_DEG`).
        tracks, playing: as above (none: the relaxed hand throughout).
    """

    name = "hands"

    def __init__(self, seed: int = 0, amplitude: float = 1.0, tracks: dict | None = None,
                 playing=None) -> None:
        self.seed = int(seed)
        self.amplitude = float(amplitude)
        self.tracks = dict(tracks or {})
        self.playing = playing
        self.joints: tuple[str, ...] = FINGER_JOINTS
        self._relaxed = np.array([RELAXED_DEG[j] for j in HAND_JOINTS])
        self._rest = np.array([MESH_REST_DEG[j] for j in HAND_JOINTS])
        self._knots: dict[int, np.ndarray] = {}
        self.reset()

    def reset(self) -> None:
        """Back to the start: openness 0 (the hand at rest), no time seen."""
        self.openness = 0.0
        self._t: float | None = None
        self.track_weight = 0.0                  # 0: the relaxed hand, 1: the clip's fingers
        self._track_q = np.zeros(len(self.joints))

    def _knot(self, k: int) -> np.ndarray:
        """Noise knot ``k`` (deg), shape (2, 20): deterministic in (seed, k)."""
        if k not in self._knots:
            rng = np.random.default_rng([self.seed, 29, k + 1_000_000])
            own = rng.normal(0.0, NOISE_JOINT_DEG, (2, len(HAND_JOINTS)))
            shared = rng.normal(0.0, NOISE_HAND_DEG, (2, 1)) * _FLEX
            self._knots[k] = own + shared
            if len(self._knots) > 64:
                self._knots.pop(min(self._knots))
        return self._knots[k]

    def noise(self, t: float) -> np.ndarray:
        """The noise (deg) at time ``t`` (s), shape (2, 20): (left, right) x :data:`HAND_JOINTS`."""
        x = max(float(t), 0.0) / NOISE_KNOT_S
        k = int(np.floor(x))
        u = x - k
        p = [self._knot(k + i) for i in (-1, 0, 1, 2)]
        return self.amplitude * _catmull_rom(*p, u)

    def pose_deg(self, t: float, openness: float) -> np.ndarray:
        """Angles from straight (deg), shape (2, 20), at time ``t`` and ``openness`` in [0, 1]
        (0: in silence, a little more curl; 1: speaking at the top of the energy)."""
        o = float(np.clip(openness, 0.0, 1.0))
        scale = 1.0 + REST_CURL * (1.0 - o) - (REST_CURL + SPEAK_OPEN) * o
        pose = np.where(_FLEX, self._relaxed * scale, self._relaxed)
        pose = pose + SPEAK_SPREAD_DEG * o * _SPREAD
        return pose[None, :] + self.noise(t)

    def step(self, t: float, heard: Heard) -> tuple[np.ndarray, list[tuple[float, str]]]:
        """Offsets (rad) on :attr:`joints` at time ``t`` (s), shape (40,), and no events."""
        target = (0.6 + 0.4 * float(np.clip(heard.energy, -1.0, 1.0))) if heard.speaking else 0.0
        dt = 0.0 if self._t is None else max(float(t) - self._t, 0.0)
        self._t = float(t)
        self.openness += (target - self.openness) * (1.0 - np.exp(-dt / OPEN_TAU_S))
        pose = self.pose_deg(t, self.openness)
        relaxed = np.radians(pose - self._rest[None, :]).reshape(-1)
        where = self.playing() if self.playing is not None and self.tracks else None
        track = self.tracks.get(where[0]) if where is not None else None
        if track is not None:
            self._track_q = track[min(max(where[1], 0), len(track) - 1)]
        goal = 1.0 if track is not None else 0.0
        step = dt / TRACK_FADE_S if dt > 0 else 0.0
        self.track_weight = float(np.clip(self.track_weight + np.sign(goal - self.track_weight)
                                          * step, 0.0, 1.0)) if step else goal
        w = self.track_weight
        return (1.0 - w) * relaxed + w * self._track_q, []


def per_finger(values: np.ndarray) -> dict[str, np.ndarray]:
    """Columns of (…, 40) finger values grouped by finger (both hands): name -> (…, 8)."""
    out = {}
    for f in FINGERS:
        cols = [i for i, j in enumerate(FINGER_JOINTS) if j.split("_", 2)[1] == f]
        out[f] = values[..., cols]
    return out
