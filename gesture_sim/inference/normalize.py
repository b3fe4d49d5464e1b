"""Per-speaker normalisation of syllable prosody and the Levine 2009 discrete features.

* :class:`SpeakerNormalizer` turns a :class:`~gesture_sim.contracts.Syllable` into the
  Gesture Controllers feature vector x = (F̄0, Ī, L) (Levine 2010 §5.2), normalised per speaker
  so that a novel speaker falls inside clusters fitted on the training speaker (the paper gives
  no normalisation; its digest §3 recommends per-speaker z-scores):

  ``features(s) = [(log f0 - mu_logf0) / sd_logf0  or NaN when unvoiced,
                   (I_dB - mu_I) / sd_I,
                   log(length_s)]``   shape (3,), float64.

  Means and variances are running statistics that adapt online
  (:class:`~gesture_sim.running.RunningStat`, ``location="prior"``): each update moves them by a
  weight ``max(1 / (n + prior_count), min_weight)``, i.e. a cumulative average that starts from
  a prior (``prior_count`` pseudo-syllables) and becomes an exponentially weighted average with
  a memory of about ``1 / min_weight`` syllables. ``from_syllables`` seeds them from training
  data; ``to_dict`` / ``from_dict`` store them with a model as
  ``{"mean", "var", "count", "min_weight", "n_mean"}`` (``count``: the observations they are
  worth; ``n_mean`` >= 0 marks the location-free ``"anchored"`` variant and counts its
  observations, -1 otherwise).

* :func:`levine09_features` gives the Levine 2009 discrete observation per syllable (thesis
  Table 3.1, digest §2.3): pitch inflection up / down (binary), intensity class
  {0 silent, 1 standard, 2 high}, length class {0 short, 1 medium, 2 long}, as
  :class:`Levine09Observation` with an integer ``code`` in [0, 36). Its running statistics are
  Welford's cumulative mean and SD from a prior (:func:`levine09_stat`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gesture_sim.contracts import Syllable
from gesture_sim.running import RunningStat
from gesture_sim.units import semitones

#: Prior speaker statistics (used until data arrive): F0 160 Hz ± 0.2 in natural-log units
#: (about ± 3.5 semitones), intensity 70 dB ± 6 dB.
DEFAULT_PRIOR = {"logf0_mean": math.log(160.0), "logf0_var": 0.2**2,
                 "intensity_mean": 70.0, "intensity_var": 6.0**2}


class SpeakerNormalizer:
    """Online per-speaker z-scoring of log-F0 and intensity; see the module docstring.

    Args:
        prior: starting statistics (keys of :data:`DEFAULT_PRIOR`).
        prior_count: how many syllables the prior is worth.
        memory: long-run memory of the running statistics, in syllables.
    """

    def __init__(self, prior: dict[str, float] | None = None, prior_count: float = 5.0,
                 memory: float = 200.0) -> None:
        p = DEFAULT_PRIOR | (prior or {})
        self.logf0 = RunningStat(p["logf0_mean"], p["logf0_var"], prior_count, 1.0 / memory)
        self.intensity = RunningStat(p["intensity_mean"], p["intensity_var"], prior_count,
                                     1.0 / memory)

    def update(self, syllable: Syllable) -> None:
        """Absorb a syllable: log-F0 if voiced, intensity if finite."""
        if syllable.voiced and syllable.f0_hz is not None and syllable.f0_hz > 0:
            self.logf0.update(math.log(syllable.f0_hz))
        if math.isfinite(syllable.intensity_db):
            self.intensity.update(syllable.intensity_db)

    def features(self, syllable: Syllable, update: bool = True) -> np.ndarray:
        """The 3-vector (normalised log-F0 or NaN if unvoiced, normalised intensity,
        log length in log-seconds). With ``update`` the syllable is absorbed first (online
        use: the statistics include everything heard so far)."""
        if update:
            self.update(syllable)
        if syllable.voiced and syllable.f0_hz is not None and syllable.f0_hz > 0:
            f = self.logf0.z(math.log(syllable.f0_hz))
        else:
            f = float("nan")
        i = self.intensity.z(syllable.intensity_db)
        length = math.log(max(syllable.length, 1e-3))
        return np.array([f, i, length], dtype=np.float64)

    def features_batch(self, syllables: Sequence[Syllable], update: bool = True) -> np.ndarray:
        """:meth:`features` over a sequence, shape (n, 3)."""
        return np.array([self.features(s, update) for s in syllables],
                        dtype=np.float64).reshape(-1, 3)

    @classmethod
    def from_syllables(cls, syllables: Sequence[Syllable], memory: float = 200.0,
                       ) -> SpeakerNormalizer:
        """Seed from training syllables: exact means/variances, counted as their number."""
        f0 = np.array([math.log(s.f0_hz) for s in syllables
                       if s.voiced and s.f0_hz is not None and s.f0_hz > 0])
        it = np.array([s.intensity_db for s in syllables if math.isfinite(s.intensity_db)])
        norm = cls(memory=memory)
        if len(f0) >= 2:
            norm.logf0 = RunningStat(float(f0.mean()), float(f0.var()), float(len(f0)),
                                     1.0 / memory)
        if len(it) >= 2:
            norm.intensity = RunningStat(float(it.mean()), float(it.var()), float(len(it)),
                                         1.0 / memory)
        return norm

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready state (see the module docstring)."""
        return {"logf0": _stat_to_dict(self.logf0), "intensity": _stat_to_dict(self.intensity)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SpeakerNormalizer:
        """Inverse of :meth:`to_dict` (``n_mean`` may be missing: -1)."""
        norm = cls()
        norm.logf0 = _stat_from_dict(d["logf0"])
        norm.intensity = _stat_from_dict(d["intensity"])
        return norm


_STAT_KEYS = ("mean", "var", "count", "min_weight", "n_mean")


def _stat_to_dict(s: RunningStat) -> dict[str, Any]:
    """A normaliser statistic as stored: ``count`` = prior + observations; ``n_mean`` = the
    observations of an ``"anchored"`` statistic, -1 for the others."""
    n_mean = float(s.n) if s.location == "anchored" else -1.0
    return {"mean": s.mean, "var": s.var, "count": s.count, "min_weight": s.min_weight,
            "n_mean": n_mean}


def _stat_from_dict(d: dict[str, Any]) -> RunningStat:
    """Inverse of :func:`_stat_to_dict`."""
    unknown = sorted(set(d) - set(_STAT_KEYS))
    if unknown:
        raise TypeError(f"unexpected normaliser statistic keys {unknown}")
    n_mean = d.get("n_mean", -1.0)
    if n_mean >= 0:
        n = int(n_mean)
        return RunningStat(d["mean"], d["var"], d["count"] - n, d["min_weight"], "anchored",
                           n=n)
    return RunningStat(d["mean"], d["var"], d["count"], d["min_weight"])


# ------------------------------------------------------------------------- Levine 2009


@dataclass(frozen=True)
class Levine09Observation:
    """One discrete Levine 2009 prosody observation.

    Attributes:
        t_start, t_end: span (s). Silent observations cover pauses between syllables.
        up, down: 1 when the syllable's largest F0 rise / fall is at least one standard
            deviation beyond its running mean (both may be set); 0 for silence.
        intensity: 0 silent, 1 standard, 2 high (>= mean + ``high_sigma`` · sd).
        length: 0 short (<= mean - sd/2), 1 medium, 2 long (>= mean + sd).
    """

    t_start: float
    t_end: float
    up: int
    down: int
    intensity: int
    length: int

    @property
    def code(self) -> int:
        """Integer in [0, 36): ((up·2 + down)·3 + intensity)·3 + length."""
        return levine09_code(self.up, self.down, self.intensity, self.length)


def levine09_code(up: int, down: int, intensity: int, length: int) -> int:
    """The Levine 2009 observation symbol in [0, 36): ((up·2 + down)·3 + intensity)·3 + length."""
    return ((up * 2 + down) * 3 + intensity) * 3 + length


def levine09_stat(mean: float, sd: float, n0: float = 3.0) -> RunningStat:
    """A Levine 2009 variable's running statistic: Welford's cumulative mean/SD starting from
    ``(mean, sd)`` (units of the variable) worth ``n0`` observations."""
    return RunningStat(mean, sd * sd, n0, form="welford")


def _pitch_changes(syllable: Syllable, times: np.ndarray | None, f0: np.ndarray | None,
                   prev_f0: float | None) -> tuple[float, float]:
    """Largest F0 rise and fall (semitones, both >= 0) within the syllable's voiced frames;
    without frames, the change from the previous voiced syllable's mean F0."""
    if times is not None and f0 is not None:
        sel = (times >= syllable.t_start) & (times < syllable.t_end) & np.isfinite(f0)
        st = semitones(f0[sel]) if sel.any() else np.zeros(0)
        if len(st) >= 2:
            rise = float(np.max(st - np.minimum.accumulate(st)))
            fall = float(np.max(np.maximum.accumulate(st) - st))
            return rise, fall
        return 0.0, 0.0
    if syllable.f0_hz is None or prev_f0 is None:
        return 0.0, 0.0
    d = semitones(syllable.f0_hz, prev_f0)
    return max(d, 0.0), max(-d, 0.0)


def levine09_features(
    syllables: Sequence[Syllable], frames: Any = None, *, high_sigma: float = 0.5,
    min_pause_s: float = 0.1, stats: dict[str, tuple[float, float]] | None = None,
    online: bool = True,
) -> list[Levine09Observation]:
    """Levine 2009 discrete observations for a syllable sequence (thesis Table 3.1).

    Args:
        syllables: tracker output in time order.
        frames: optional :class:`~gesture_sim.audio.prosody.ProsodyFrames`; with it the pitch
            variables are the largest rise and largest fall within each syllable (semitones),
            so up and down can both be set (the thesis's ~26 reachable states); without it, the
            F0 change from the previous voiced syllable (then up/down are exclusive).
        high_sigma: high-intensity threshold in standard deviations (0.5 in the thesis prose,
            1 in its table as transcribed).
        min_pause_s: gaps between syllables at least this long become silent observations;
            gaps longer than the running mean length are cut into medium-length chunks (the
            thesis truncates long silences into medium observations).
        stats: ``{"rise": (mean, sd), "fall": ..., "intensity": ..., "length": ...}`` from
            training (e.g. :func:`levine09_stats`); otherwise a neutral prior.
        online: update the statistics with each syllable before classifying it (synthesis);
            ``False`` keeps ``stats`` fixed (training with whole-set statistics).

    Returns:
        observations in time order, silent ones interleaved.
    """
    base = {"rise": (1.0, 1.0), "fall": (1.0, 1.0), "intensity": (70.0, 6.0),
            "length": (0.2, 0.1)} | (stats or {})
    run = {k: levine09_stat(*v) for k, v in base.items()}
    times = f0 = None
    if frames is not None:
        times, f0 = np.asarray(frames.times), np.asarray(frames.f0_hz)
    out: list[Levine09Observation] = []
    prev_end: float | None = None
    prev_f0: float | None = None
    for s in syllables:
        if prev_end is not None and s.t_start - prev_end >= min_pause_s:
            gap_start, gap = prev_end, s.t_start - prev_end
            ml = max(run["length"].mean, 0.05)
            n_chunks = max(1, int(gap // ml)) if gap > ml else 1
            edges = np.linspace(gap_start, s.t_start, n_chunks + 1)
            mu, sd = run["length"].mean, run["length"].sd
            for a, b in zip(edges[:-1], edges[1:], strict=True):
                short = (b - a) - mu <= -sd / 2
                out.append(Levine09Observation(float(a), float(b), 0, 0, 0, 0 if short else 1))
        rise, fall = _pitch_changes(s, times, f0, prev_f0)
        if online:
            run["rise"].update(rise)
            run["fall"].update(fall)
            if math.isfinite(s.intensity_db):
                run["intensity"].update(s.intensity_db)
            run["length"].update(s.length)
        up = int(s.f0_hz is not None and rise - run["rise"].mean >= run["rise"].sd)
        down = int(s.f0_hz is not None and fall - run["fall"].mean >= run["fall"].sd)
        hi = s.intensity_db - run["intensity"].mean >= high_sigma * run["intensity"].sd
        dl = s.length - run["length"].mean
        length = 0 if dl <= -run["length"].sd / 2 else (2 if dl >= run["length"].sd else 1)
        out.append(Levine09Observation(s.t_start, s.t_end, up, down, 2 if hi else 1, length))
        prev_end = s.t_end
        if s.f0_hz is not None:
            prev_f0 = s.f0_hz
    return out


def levine09_stats(syllables: Sequence[Syllable], frames: Any = None,
                   ) -> dict[str, tuple[float, float]]:
    """Whole-set (mean, sd) of the Levine 2009 variables, for training-time normalisation."""
    times = f0 = None
    if frames is not None:
        times, f0 = np.asarray(frames.times), np.asarray(frames.f0_hz)
    rises, falls, prev = [], [], None
    for s in syllables:
        r, f = _pitch_changes(s, times, f0, prev)
        rises.append(r)
        falls.append(f)
        if s.f0_hz is not None:
            prev = s.f0_hz
    inten = [s.intensity_db for s in syllables if math.isfinite(s.intensity_db)]
    lengths = [s.length for s in syllables]

    def ms(a: list[float], default: tuple[float, float]) -> tuple[float, float]:
        return (float(np.mean(a)), float(np.std(a))) if len(a) >= 2 else default

    return {"rise": ms(rises, (1.0, 1.0)), "fall": ms(falls, (1.0, 1.0)),
            "intensity": ms(inten, (70.0, 6.0)), "length": ms(lengths, (0.2, 0.1))}
