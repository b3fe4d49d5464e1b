"""Where the eyes look: a speaker's gaze aversion and return, a listener's gaze at the speaker,
and the small saccades of both. Causal, seeded, stepped once per control step.

The rules (Kendon 1967; Argyle & Cook 1976, as embodied-agent gaze models use them, e.g. Cassell
et al. 1999 and Okwechime 2011's *gaze at speaker* signal):

* **Speaker.** At the start of a phrase (speech onset after a pause, or the first accent after
  a phrase boundary) the speaker looks away with probability ``p_avert_phrase`` — to one side
  and a little up or down — and looks back at the listener by the end of the phrase (its
  boundary) or after ``avert_max_s``, whichever is first. Speakers look at their listener
  about 40 % of the time (Argyle & Cook); the aversions are what make it so.
* **Listener.** A listener looks at the speaker most of the time (about 75 %, Argyle & Cook):
  brief aversions start at ``listener_avert_per_min`` and last ``listener_avert_s``.
* **Saccades.** Around the current target the eyes jump by small amounts (SD ``saccade_rad``)
  at exponentially distributed intervals (mean ``saccade_interval_s``); a saccade is a step of
  the target that the eyes' fast PD servos (``class="eye"`` in ``humanoid.xml``) follow in a few
  tens of ms, as real saccades take 20-50 ms.

"Straight ahead" is the partner: in a conversation the two people face each other, alone the
person faces the camera. Angles in rad: yaw > 0 to the body's left, pitch > 0 down
(:func:`gesture_sim.signals.face_rig.gaze_offsets`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GazeConfig:
    """Settings (s, rad, per minute)."""

    p_avert_phrase: float = 0.7
    avert_yaw_rad: float = math.radians(14.0)
    avert_pitch_rad: float = math.radians(6.0)
    avert_min_s: float = 0.6
    avert_max_s: float = 2.5
    listener_avert_per_min: float = 5.0
    listener_avert_s: float = 0.9
    saccade_rad: float = math.radians(1.5)
    saccade_interval_s: float = 0.9


class Gaze:
    """The gaze scheduler. Call :meth:`step` every control step; :attr:`events` keeps the
    aversions and returns ``(t, text)``."""

    def __init__(self, config: GazeConfig | None = None, seed: int = 0) -> None:
        self.cfg = config or GazeConfig()
        self.seed = int(seed)
        self.reset()

    def reset(self) -> None:
        """A new stream at t = 0."""
        self.rng = np.random.default_rng(self.seed + 7919)
        self.events: list[tuple[float, str]] = []
        self._target = np.zeros(2)          # (yaw, pitch) the gaze holds, without saccades
        self._jitter = np.zeros(2)
        self._avert_until = -math.inf
        self._next_saccade = 0.0
        self._next_listener_avert = self._draw(0.0, self.cfg.listener_avert_per_min)
        self._was_speaking = False

    def _draw(self, t: float, per_min: float) -> float:
        return t + float(self.rng.exponential(60.0 / per_min)) if per_min > 0 else math.inf

    def _avert(self, t: float, duration: float, why: str) -> None:
        c = self.cfg
        side = 1.0 if self.rng.random() < 0.5 else -1.0
        up = -1.0 if self.rng.random() < 0.6 else 1.0          # away-looks tend upwards
        self._target = np.array([side * c.avert_yaw_rad * (0.7 + 0.6 * self.rng.random()),
                                 up * c.avert_pitch_rad * self.rng.random()])
        self._avert_until = t + duration
        self.events.append((round(t, 4), f"gaze away {why}"))

    def _return(self, t: float) -> None:
        if self._avert_until > t or self._target.any():
            self.events.append((round(t, 4), "gaze back"))
        self._target = np.zeros(2)
        self._avert_until = -math.inf

    def step(self, t: float, speaking: bool, phrase_start: bool = False,
             phrase_end: bool = False) -> tuple[float, float]:
        """The gaze (yaw, pitch) in rad at control step ``t`` (s).

        Args:
            speaking: this person speaks now (speaker rules) or not (listener rules).
            phrase_start, phrase_end: a phrase of this person's speech starts / ends here.
        """
        c = self.cfg
        onset = speaking and not self._was_speaking
        self._was_speaking = speaking
        if speaking:
            if (phrase_start or onset) and self._avert_until < t \
                    and self.rng.random() < c.p_avert_phrase:
                span = c.avert_min_s + (c.avert_max_s - c.avert_min_s) * self.rng.random()
                self._avert(t, span, "phrase")
            elif phrase_end:
                self._return(t)
        elif t >= self._next_listener_avert:
            self._avert(t, c.listener_avert_s, "listening")
            self._next_listener_avert = self._draw(t, c.listener_avert_per_min)
        if self._target.any() and t >= self._avert_until:
            self._return(t)
        if t >= self._next_saccade:
            self._jitter = self.rng.normal(0.0, c.saccade_rad, 2)
            self._next_saccade = t + float(self.rng.exponential(c.saccade_interval_s))
        yaw, pitch = self._target + self._jitter
        return float(yaw), float(pitch)

    def looking_at_partner(self) -> bool:
        """Whether the gaze holds on the partner now (no aversion)."""
        return not self._target.any()
