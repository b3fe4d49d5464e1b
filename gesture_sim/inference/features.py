"""Per-step inputs X and outputs Y of the inference layer (Gesture Controllers §5.2, §6.1).

The inference/control step is one animation frame (:attr:`StepSettings.rate_hz`, 30 Hz by
default); step ``t`` is at time ``t / rate_hz`` seconds.

**Inputs X (n, 3).** At step t the input is the feature vector of the most recent syllable
*known* at that time (``t_emitted <= t / rate``), held stepwise — so training sees the same
prosody latency as live use. The **silence rule**: if the latest syllable was emitted more than
``silence_hold_s`` before the step (or none has been emitted yet), the input is the silence
vector ``(NaN, silence_intensity, silence_log_length)``: F0 unknown, intensity at a floor (in
the normaliser's z units) and a constant very short log length. The feature vector of a
syllable comes from a :class:`~gesture_sim.inference.normalize.SpeakerNormalizer` updated online
with each syllable in emission order (the same object type at training and run time).

**Outputs Y (n, 6).** The kinematic parameters (T, D, V, A, C, H) of the motion segment playing
at each step, held stepwise per segment.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from typing import Protocol

import numpy as np

from gesture_sim.contracts import Syllable


class Featurizer(Protocol):
    """What the step inputs need from a speaker normaliser."""

    def features(self, syllable: Syllable, update: bool = True) -> np.ndarray: ...


@dataclass(frozen=True)
class StepSettings:
    """Timing of the inference layer.

    Attributes:
        rate_hz: control/inference steps per second (the clip frame rate).
        silence_hold_s: a syllable's features are held this long (s) after its emission; after
            that, with no newer syllable, the input is the silence vector.
        silence_intensity: intensity of the silence vector (z units of the normaliser).
        silence_log_length: log length (log s) of the silence vector.
    """

    rate_hz: float = 30.0
    silence_hold_s: float = 0.5
    silence_intensity: float = -3.0
    silence_log_length: float = float(np.log(0.02))

    @property
    def dt(self) -> float:
        """Step length (s)."""
        return 1.0 / self.rate_hz

    def silence(self) -> np.ndarray:
        """The silence input (3,)."""
        return np.array([np.nan, self.silence_intensity, self.silence_log_length])

    def to_dict(self) -> dict:
        return asdict(self)


class StepInputs:
    """Causal per-step input: feed syllables as they are emitted, read one vector per step.

    ``push(syllable)`` featurises a newly emitted syllable (updating the normaliser);
    ``at(t)`` returns the input (3,) at time ``t`` (s): the features of the latest pushed
    syllable with ``t_emitted <= t`` unless it is older than the hold time. Syllables must be
    pushed in emission order and no later than the first step that may use them.
    """

    def __init__(self, featurizer: Featurizer, settings: StepSettings) -> None:
        self.featurizer = featurizer
        self.settings = settings
        self._pending: list[tuple[float, np.ndarray]] = []
        self._current = settings.silence()
        self._t_current = -np.inf

    def push(self, syllable: Syllable) -> None:
        """Featurise a syllable now (its features take effect from its ``t_emitted``)."""
        x = np.asarray(self.featurizer.features(syllable, update=True), dtype=float)
        self._pending.append((syllable.t_emitted, x))

    def at(self, t: float) -> np.ndarray:
        """Input vector (3,) at time t (s); F0 is NaN when unvoiced or silent."""
        while self._pending and self._pending[0][0] <= t + 1e-9:
            self._t_current, self._current = self._pending.pop(0)
        if t - self._t_current > self.settings.silence_hold_s:
            return self.settings.silence()
        return self._current.copy()


def step_inputs(
    syllables: Sequence[Syllable], n_steps: int, featurizer: Featurizer, settings: StepSettings,
) -> np.ndarray:
    """X (n_steps, 3) of a whole recording, through the same causal :class:`StepInputs`."""
    inputs = StepInputs(featurizer, settings)
    order = sorted(syllables, key=lambda s: s.t_emitted)
    out = np.empty((n_steps, 3))
    k = 0
    for t in range(n_steps):
        now = t * settings.dt
        while k < len(order) and order[k].t_emitted <= now + 1e-9:
            inputs.push(order[k])
            k += 1
        out[t] = inputs.at(now)
    return out


def step_outputs(
    segments: Iterable[tuple[int, int]] | np.ndarray, params: np.ndarray, motion_fps: float,
    n_steps: int, rate_hz: float,
) -> np.ndarray:
    """Y (n_steps, 6): the parameters of the segment playing at each step.

    Args:
        segments: (m, 2) frame ranges ``[start, end)`` covering the clip without gaps.
        params: (m, 6) normalised log parameters per segment.
        motion_fps: frame rate of the motion (Hz).
        n_steps: number of steps; steps past the last frame take the last segment.
        rate_hz: step rate (Hz).
    """
    seg = np.asarray(segments if isinstance(segments, np.ndarray) else list(segments), dtype=int)
    idx = step_segment_index(seg, motion_fps, n_steps, rate_hz)
    return np.asarray(params, dtype=float)[idx]


def step_segment_index(
    segments: np.ndarray, motion_fps: float, n_steps: int, rate_hz: float,
) -> np.ndarray:
    """Index (n_steps,) of the segment playing at each step (see :func:`step_outputs`)."""
    seg = np.asarray(segments, dtype=int).reshape(-1, 2)
    frames = np.floor(np.arange(n_steps) / rate_hz * motion_fps + 1e-9).astype(int)
    return np.clip(np.searchsorted(seg[:, 1], frames, side="right"), 0, len(seg) - 1)
