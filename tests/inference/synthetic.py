"""Small synthetic stand-ins for the inference tests: known chains, syllable streams, takes."""

from __future__ import annotations

import numpy as np

from gesture_sim.contracts import Syllable
from gesture_sim.inference.train import MotionTake, TrainingTake


def sample_chain(trans: np.ndarray, n: int, rng: np.random.Generator, start: int = 0) -> np.ndarray:
    """A state path (n,) of a row-stochastic Markov chain."""
    q = np.empty(n, dtype=int)
    q[0] = start
    for t in range(1, n):
        q[t] = rng.choice(len(trans), p=trans[q[t - 1]])
    return q


def synthetic_take(rng: np.random.Generator, duration_s: float = 40.0, fps: float = 30.0
                   ) -> TrainingTake:
    """Motion whose segment energy follows the speech loudness, with syllables to match.

    Alternating "loud" and "quiet" phrases of 2-4 s: loud phrases have high, long, high-pitched
    syllables and fast, large, raised-hand segments; quiet phrases the opposite.
    """
    n_frames = int(duration_s * fps)
    segments, raw, syllables = [], [], []
    t, loud = 0.0, True
    while t < duration_s - 0.5:
        phrase = min(rng.uniform(2.0, 4.0), duration_s - t)
        end = t + phrase
        s_t = t
        while s_t < end - 0.3:  # segments of 0.4-0.8 s
            length = min(rng.uniform(0.4, 0.8), end - s_t)
            a, b = int(round(s_t * fps)), int(round((s_t + length) * fps))
            if b - a >= 4:
                segments.append((a, b))
                scale = 3.0 if loud else 0.6
                raw.append([length, 0.2 * scale, 0.5 * scale, 5.0 * scale, 3.0,
                            1.4 * (1.2 if loud else 0.9)] * np.exp(rng.normal(0, 0.1, 6)))
            s_t += length
        y = t + 0.05
        while y < end - 0.3:
            length = rng.uniform(0.15, 0.25)
            syllables.append(Syllable(
                t_start=y, t_end=y + length, t_emitted=y + length + 0.05,
                f0_hz=float((220.0 if loud else 120.0) * np.exp(rng.normal(0, 0.05))),
                intensity_db=float((78.0 if loud else 62.0) + rng.normal(0, 1.5)), voiced=True))
            y += length + rng.uniform(0.02, 0.08)
        t, loud = end, not loud
    segs = np.array(segments, dtype=int)
    segs[0, 0] = 0
    segs[:-1, 1] = segs[1:, 0]
    segs[-1, 1] = n_frames
    motion = MotionTake(fps, n_frames, segs, np.array(raw), "synthetic")
    return TrainingTake(motion, syllables, duration_s, "synthetic")
