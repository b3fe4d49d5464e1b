"""Procedural gesture streams for physics tests and benchmarks (seeded, no motion data needed).

The stream is a sequence of segments of random length (0.3-2 s by default). Each segment is one
of: *beats* (the forearms bob at 2-4 Hz around a pose in gesture space), a *sweep* (a wide
minimum-jerk arm movement), *hands to face* (one hand is brought to the chin), or a *hold*.
Torso and head move throughout (slow spine twists and bends, nods and head turns), and the face
talks (jaw) and blinks. A new segment starts from its own pose, not from where the last one
ended, so every segment boundary is a sudden target switch, mimicking an interrupted gesture.
The legs stay at the standing pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gesture_sim.sim import humanoid as hm
from gesture_sim.sim.targets import TargetStream

#: Arm poses (left-side joint values, rad; mirrored to the right by the sign conventions).
_ARM_POSES = {
    "rest": {},
    "low": {"shoulder_flex": 0.3, "shoulder_abduct": 0.15, "elbow_flex": 1.3},
    "mid": {"shoulder_flex": 0.6, "shoulder_abduct": 0.3, "elbow_flex": 1.4,
            "forearm_twist": 0.6},
    "open": {"shoulder_flex": 0.5, "shoulder_abduct": 0.9, "elbow_flex": 0.6,
             "forearm_twist": 1.0},
    "raised": {"shoulder_flex": 1.3, "shoulder_abduct": 0.25, "elbow_flex": 0.9,
               "clavicle_elevate": 0.15},
    "point": {"shoulder_flex": 1.1, "shoulder_abduct": 0.1, "elbow_flex": 0.25,
              "forearm_twist": -0.3, "wrist_flex": -0.2},
}
#: Hand near the chin (left arm), checked by tests to stay clear of the head.
_FACE_POSE = {"shoulder_flex": 1.0, "shoulder_abduct": 0.3, "shoulder_twist": -0.7,
              "elbow_flex": 2.3, "forearm_twist": 0.3, "wrist_flex": -0.3,
              "clavicle_protract": 0.1}
_ARM_JOINTS = ("clavicle_elevate", "clavicle_protract", "shoulder_flex", "shoulder_abduct",
               "shoulder_twist", "elbow_flex", "forearm_twist", "wrist_flex", "wrist_deviate")


@dataclass(frozen=True)
class Segment:
    """One procedural segment: kind, start time (s) and length (s)."""

    kind: str
    t_start: float
    length: float


def _min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk blend 10s³ - 15s⁴ + 6s⁵ of s in [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10 - 15 * s + 6 * s * s)


def _arm_vector(pose: dict[str, float], side: str) -> np.ndarray:
    """A (9,) vector of one arm's joint values in ``_ARM_JOINTS`` order."""
    return np.array([pose.get(j, 0.0) for j in _ARM_JOINTS])


def gesture_stream(duration: float = 60.0, seed: int = 0, rate: float = 30.0,
                   min_segment: float = 0.3, max_segment: float = 2.0, amplitude: float = 1.0
                   ) -> tuple[TargetStream, list[Segment]]:
    """A seeded procedural gesture stream and its segments.

    Args:
        duration: length (s); rate: samples per second (Hz).
        min_segment, max_segment: bounds of a segment's length (s); each boundary is a jump.
        amplitude: scales every excursion from the standing pose (1 = as designed).

    Returns:
        The stream (q of shape (round(duration * rate) + 1, n_act), inside the joint limits)
        and the list of segments.
    """
    rng = np.random.default_rng(seed)
    n_t = int(round(duration * rate)) + 1
    t = np.arange(n_t) / rate
    names = hm.ACTUATED_JOINTS
    q = np.zeros((n_t, len(names)))
    col = {n: i for i, n in enumerate(names)}
    arm_cols = {s: np.array([col[f"{s}_{j}"] for j in _ARM_JOINTS]) for s in ("left", "right")}
    poses = list(_ARM_POSES)

    segments: list[Segment] = []
    t0 = 0.0
    while t0 < duration:
        length = float(rng.uniform(min_segment, max_segment))
        kind = str(rng.choice(["beats", "sweep", "face", "hold"], p=[0.4, 0.3, 0.15, 0.15]))
        segments.append(Segment(kind, t0, length))
        sel = (t >= t0) & (t < t0 + length)
        tl = t[sel] - t0
        s = _min_jerk(tl / max(min(length, 0.9), 1e-3))
        face_side = "left" if rng.random() < 0.5 else "right"
        for side in ("left", "right"):
            a = _arm_vector(_ARM_POSES[poses[rng.integers(len(poses))]], side)
            a = a + rng.normal(0.0, 0.08, a.shape)
            if kind == "beats":
                b = a.copy()
                amp = rng.uniform(0.12, 0.3)
                freq = rng.uniform(2.0, 4.0)
                wave = amp * (1 - np.cos(2 * np.pi * freq * tl)) / 2
                arm = np.repeat(b[None], len(tl), axis=0)
                arm[:, _ARM_JOINTS.index("elbow_flex")] += wave
                arm[:, _ARM_JOINTS.index("wrist_flex")] += 0.4 * wave
            elif kind == "sweep":
                b = _arm_vector(_ARM_POSES[poses[rng.integers(len(poses))]], side)
                b = b + rng.normal(0.0, 0.1, b.shape)
                arm = a[None] + s[:, None] * (b - a)[None]
            elif kind == "face" and side == face_side:
                b = _arm_vector(_FACE_POSE, side)
                arm = a[None] + s[:, None] * (b - a)[None]
            else:
                arm = np.repeat(a[None], len(tl), axis=0)
            q[np.ix_(sel, arm_cols[side])] = arm
        t0 += length

    # torso and head: smooth random motion (sums of slow sinusoids), nods, turns
    def smooth(scale: float, fmin: float, fmax: float, k: int = 3) -> np.ndarray:
        out = np.zeros(n_t)
        for _ in range(k):
            f = rng.uniform(fmin, fmax)
            out += rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
        return scale * out / k

    q[:, col["upper_spine_twist"]] = smooth(0.25, 0.1, 0.5)
    q[:, col["lower_spine_twist"]] = smooth(0.1, 0.1, 0.4)
    q[:, col["upper_spine_flex"]] = 0.05 + smooth(0.12, 0.1, 0.5)
    q[:, col["lower_spine_bend"]] = smooth(0.1, 0.1, 0.4)
    q[:, col["neck_flex"]] = smooth(0.2, 0.3, 1.5)
    q[:, col["neck_twist"]] = smooth(0.5, 0.1, 0.6)
    q[:, col["head_flex"]] = smooth(0.25, 0.5, 2.5)
    q[:, col["head_bend"]] = smooth(0.1, 0.2, 1.0)
    q[:, col["head_twist"]] = smooth(0.3, 0.1, 0.8)
    q[:, col["jaw_open"]] = 0.12 * (1 + np.sin(2 * np.pi * 4.0 * t + smooth(3.0, 0.2, 1.0))) / 2
    brow = 0.006 * np.clip(smooth(2.0, 0.1, 0.6), 0, 1)
    q[:, col["left_brow_raise"]] = brow
    q[:, col["right_brow_raise"]] = brow
    blink = np.zeros(n_t)
    for tb in np.cumsum(rng.uniform(2.0, 5.0, size=int(duration / 2) + 2)):
        blink += 0.013 * np.exp(-0.5 * ((t - tb) / 0.05) ** 2)
    q[:, col["left_eyelid_close"]] = blink
    q[:, col["right_eyelid_close"]] = blink

    q *= amplitude
    model = hm.load_model(scene=False)
    rng_lim = hm.joint_ranges(model)
    margin = np.where([n in hm.SLIDE_JOINTS for n in names], 0.0005, np.deg2rad(3.0))
    q = np.clip(q, rng_lim[:, 0] + margin, rng_lim[:, 1] - margin)
    q[:, hm.actuated_index(hm.LEG_JOINTS)] = 0.0
    return TargetStream(q, rate=rate), segments
