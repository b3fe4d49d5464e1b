"""The audio side of an evaluation: one speech file and what the metrics need of it (prosody
frames, onsets, stressed vowels from a TextGrid), the one-file mismatched control, the chance
level of beat consistency and the stroke-to-stress timing."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.errors import GestureSimError
from gesture_sim.metrics import motion as mm
from gesture_sim.metrics.points import EVAL_FPS

#: Circular shifts of the audio beats used for the chance level of BC (see :func:`bc_chance`).
CHANCE_SHIFTS = 64


@dataclass
class AudioInput:
    """One speech file and what the metrics need of it.

    Attributes:
        path: the file; name: its stem (unique within an evaluation).
        samples: (n,) float32 mono 16 kHz.
        f0_hz, intensity_db: (N,) tracker frames on the 10 ms grid from t = 0 (F0 NaN unvoiced).
        onsets: (K,) audio beat times (s), :func:`gesture_sim.metrics.motion.detect_onsets`.
        reference: path of its motion capture, or None.
        accents: (A,) times (s) of the accents the causal detector finds in it
            (:func:`gesture_sim.audio.accents.detect_accents`), for the head-signal timing.
        stress: (M,) centres (s) of the stressed vowels of its word/phone alignment (a TextGrid),
            or None.
        words: its timed words ``(start_s, end_s, word)`` from that TextGrid's word tier (for a
            method that reads words, ``chiu14``), or None.
    """

    path: Path
    name: str
    samples: np.ndarray
    f0_hz: np.ndarray
    intensity_db: np.ndarray
    onsets: np.ndarray
    reference: Path | None = None
    stress: np.ndarray | None = None
    accents: np.ndarray | None = None
    words: list[tuple[float, float, str]] | None = None

    @property
    def duration(self) -> float:
        return len(self.samples) / SAMPLE_RATE


def prosody_frames(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The prosody tracker's F0 (Hz, NaN unvoiced) and intensity (dB) on the grid ``n * 0.01`` s
    for ``n = 0 .. len(samples) // 160``, each ``(N,)`` (held at the ends)."""
    from gesture_sim.audio.prosody import ProsodyTracker
    from gesture_sim.audio.sources import iter_blocks

    samples = np.asarray(samples, dtype=np.float32)
    tracker = ProsodyTracker()
    tracker.expect(samples)
    for block in iter_blocks(samples, SAMPLE_RATE):
        tracker.push(block)
    tracker.flush()
    fr = tracker.frames()
    grid = np.arange(len(samples) // 160 + 1) * mm.FRAME_STEP_S
    times = np.asarray(fr.times, dtype=float)
    f0 = np.asarray(fr.f0_hz, dtype=float)
    f0 = np.where(np.isfinite(f0) & (f0 > 0), f0, np.nan)
    if len(times) == 0:
        return np.full(len(grid), np.nan), np.full(len(grid), -80.0)
    k = np.clip(np.round((grid - times[0]) / mm.FRAME_STEP_S).astype(int), 0, len(times) - 1)
    return f0[k], np.asarray(fr.intensity_db, dtype=float)[k]


#: A reference motion and its audio may differ by this share of the longer one (and by 1 s),
#: as the motion and speech of a training pair may (``gesture-sim train``).
REFERENCE_MISMATCH_SHARE = 0.1


def check_reference_length(reference: str | os.PathLike[str], audio: str | os.PathLike[str],
                           duration_s: float) -> None:
    """GestureSimError (one line) if the motion file ``reference`` lasts more than 10 % (and
    1 s) longer or shorter than its audio (``duration_s``): it is another take's motion."""
    from gesture_sim.motion.build import motion_duration

    m_s = motion_duration(reference)
    if m_s is None:
        return   # the motion reader says what is wrong with it
    if abs(m_s - duration_s) > max(1.0, REFERENCE_MISMATCH_SHARE * max(m_s, duration_s)):
        raise GestureSimError(
            f"--reference {reference}: the motion lasts {m_s:.1f} s but its audio {audio} "
            f"{duration_s:.1f} s; a reference must be the motion capture of the same take")


def check_textgrid_times(grid, where: str | os.PathLike[str], duration_s: float) -> None:
    """GestureSimError (one line naming ``where``) if the TextGrid holds no labelled interval
    at all (empty tiers: every figure it adds would silently be "–"), or if one lies outside
    the audio (``duration_s``): a negative time, or one past the end by more than
    :data:`~gesture_sim.validation.SIDE_FILE_OVERRUN_S` (it aligns another recording: the one
    rule of every side file, :func:`gesture_sim.validation.side_file_times`)."""
    from gesture_sim.audio.textgrid import timed_items
    from gesture_sim.validation import side_file_times

    items = timed_items(grid)
    if not items:
        tiers = ", ".join(repr(k) for k in grid) or "none"
        raise GestureSimError(
            f"--textgrid {where}: no labelled interval in any tier (tiers: {tiers}); give the "
            "alignment of the recording (words, and ARPAbet phones with stress digits)")
    side_file_times("--textgrid", where, items, duration_s, "the audio",
                    "is the TextGrid for this recording?")


def stress_note(grid, where: str | os.PathLike[str]) -> str | None:
    """Why a TextGrid adds no stroke-to-stress figure (no ``phones`` tier, or no stressed
    vowel in it: the figures stay "–"), for one warning line; None when it has stressed
    vowels."""
    from gesture_sim.audio.textgrid import stressed_vowels

    if "phones" in grid and stressed_vowels(grid):
        return None
    what = "no 'phones' tier" if "phones" not in grid else "no stressed vowel in its 'phones' tier"
    return (f"--textgrid {where}: {what}, so the stroke-to-stress figures stay '–' (they need "
            "ARPAbet phones with stress digits, AY1, as the Montreal Forced Aligner writes); "
            "its words are still used")


def load_input(path: str | os.PathLike[str], reference: str | os.PathLike[str] | None = None,
               textgrid: str | os.PathLike[str] | None = None) -> AudioInput:
    """Read an audio file and compute its prosody frames and onsets (and, with a TextGrid,
    the centres of its primary-stressed vowels and its timed words)."""
    from gesture_sim.audio.sources import load_audio

    samples, _ = load_audio(path)
    if len(samples) < 1600:
        raise GestureSimError(f"{path}: shorter than 0.1 s")
    duration = len(samples) / SAMPLE_RATE
    if reference is not None:
        check_reference_length(reference, path, duration)
    grid = None
    if textgrid is not None:
        from gesture_sim.audio.textgrid import read_textgrid

        grid = read_textgrid(textgrid)
        check_textgrid_times(grid, textgrid, duration)
    f0, inten = prosody_frames(samples)
    stress = None
    if grid is not None:
        from gesture_sim.audio.textgrid import stressed_vowels

        vowels = stressed_vowels(grid)
        stress = np.array([(a + b) / 2.0 for a, b in vowels], dtype=float)
    from gesture_sim.audio.accents import detect_accents

    accents = np.array([a.t for a in detect_accents(samples)[0]], dtype=float)
    words = None
    if grid is not None and "words" in grid:
        from gesture_sim.audio.keywords import read_word_list

        words = read_word_list(textgrid)
    return AudioInput(Path(path), Path(path).stem, samples, f0, inten,
                      mm.detect_onsets(samples), Path(reference) if reference else None,
                      stress, accents, words)


def rotated(inp: AudioInput, name: str) -> AudioInput:
    """The same audio rotated by half its length (prosody rotated with it): the one-file
    mismatched control."""
    half = len(inp.samples) // 2
    k = half // 160
    samples = np.roll(inp.samples, -half)
    stress = None
    if inp.stress is not None:
        stress = np.sort((inp.stress - half / SAMPLE_RATE) % inp.duration)
    accents = None
    if inp.accents is not None:
        accents = np.sort((inp.accents - half / SAMPLE_RATE) % inp.duration)
    return AudioInput(inp.path, name, samples, np.roll(inp.f0_hz, -k),
                      np.roll(inp.intensity_db, -k), mm.detect_onsets(samples), stress=stress,
                      accents=accents)


def stress_timing(stress_s: np.ndarray, hand_speed: np.ndarray, duration: float,
                  window_s: float = 0.2) -> dict[str, float]:
    """Stroke-to-stress timing: for each stressed vowel centre (s) inside the motion, the signed
    time (s) from it to the nearest hand-speed peak (:func:`~gesture_sim.metrics.motion.speed_peaks`
    of ``hand_speed`` (T,) at :data:`EVAL_FPS`).

    Returns ``stress_hit_rate`` (share within ±``window_s``), ``stress_hit_excess`` (that share
    less the share the same peaks reach shifted in time,
    :func:`~gesture_sim.metrics.motion.accent_hit_chance`: the hits the timing earns, at any peak
    density, as accent hits − chance), ``stress_error_median_s`` (median absolute error) and
    ``stress_lag_median_s`` (median signed error: > 0, the hand comes late).
    """
    stress = np.asarray(stress_s, dtype=float)
    stress = stress[(stress >= 0) & (stress <= duration)]
    peaks = mm.speed_peaks(hand_speed, EVAL_FPS)
    if stress.size == 0 or peaks.size == 0:
        return {"stress_hit_rate": float("nan") if stress.size == 0 else 0.0,
                "stress_hit_excess": float("nan") if stress.size == 0 else 0.0,
                "stress_error_median_s": float("nan"), "stress_lag_median_s": float("nan")}
    idx = np.clip(np.searchsorted(peaks, stress), 1, len(peaks) - 1) if len(peaks) > 1 else \
        np.zeros(len(stress), int)
    cand = np.stack([peaks[np.maximum(idx - 1, 0)], peaks[idx]], axis=1) - stress[:, None]
    err = cand[np.arange(len(stress)), np.argmin(np.abs(cand), axis=1)]
    rate = float(np.mean(np.abs(err) <= window_s + 1e-9))
    chance = mm.accent_hit_chance(stress, peaks, duration, window_s)
    return {"stress_hit_rate": rate, "stress_hit_excess": rate - chance,
            "stress_error_median_s": float(np.median(np.abs(err))),
            "stress_lag_median_s": float(np.median(err)),
            "n_stressed": float(stress.size)}


def head_timing(accents_s: np.ndarray, times: np.ndarray, head_speed: np.ndarray,
                duration: float, window_s: float = 0.2, prominence: float = 0.5
                ) -> dict[str, float]:
    """Accent-to-head timing: the share of the audio's accents (s) inside ``[0, duration]``
    with a head-speed peak within ±``window_s``, and the median signed delay (s) of the
    nearest peak (> 0: the head comes after the accent). Peaks: maxima of the head's angular
    speed (rad/s, smoothed over 30 ms) with at least ``prominence`` rad/s, i.e. head
    movements, not the tracker's small oscillations; ``head_peaks_per_s`` says how dense they
    are (the chance level of the share grows with it): ``head_accent_excess`` is the share less
    the share the same peaks reach shifted in time
    (:func:`~gesture_sim.metrics.motion.accent_hit_chance`), as the hands' accent hits − chance."""
    from scipy.ndimage import gaussian_filter1d
    from scipy.signal import find_peaks

    acc = np.asarray(accents_s, dtype=float)
    acc = acc[(acc >= 0) & (acc <= duration)]
    t = np.asarray(times, dtype=float)
    if acc.size == 0 or len(t) < 3:
        return {}
    dt = float(np.median(np.diff(t)))
    v = gaussian_filter1d(np.asarray(head_speed, dtype=float), 0.03 / max(dt, 1e-6))
    idx, _ = find_peaks(v, prominence=prominence)
    peaks = t[idx]
    out = {"head_peaks_per_s": len(peaks) / max(duration, 1e-9)}
    if peaks.size == 0:
        return {**out, "head_accent_hits": 0.0, "head_accent_excess": 0.0}
    d = peaks[None, :] - acc[:, None]
    nearest = d[np.arange(len(acc)), np.argmin(np.abs(d), axis=1)]
    hits = float(np.mean(np.abs(nearest) <= window_s + 1e-9))
    chance = mm.accent_hit_chance(acc, peaks, duration, window_s)
    return {**out, "head_accent_hits": hits, "head_accent_excess": hits - chance,
            "head_lag_median_s": float(np.median(nearest))}


def bc_chance(onsets: np.ndarray, positions: np.ndarray, joints: Sequence[int],
              duration: float, n_shifts: int = CHANCE_SHIFTS, seed: int = 0) -> float:
    """Chance level of BC for this motion: the mean BC against the audio beats circularly
    shifted by uniform random offsets in ``[0, duration)`` (``n_shifts`` draws, fixed seed).

    BC grows with the density of motion beats alone, so BC is read against this level (the
    shuffled-audio baseline of BEAT, ENGINEERING_NOTES §7.1). NaN without audio beats.
    """
    onsets = np.asarray(onsets, dtype=float)
    if onsets.size == 0 or duration <= 0:
        return float("nan")
    spd = mm.joint_speeds(positions, EVAL_FPS)
    beats = [mm.motion_beats(spd[:, j], EVAL_FPS) / EVAL_FPS for j in joints]
    rng = np.random.default_rng(seed)
    shifts = rng.uniform(0.0, duration, n_shifts)
    vals = []
    for sh in shifts:
        a = np.mod(onsets + sh, duration)
        vals.append(np.mean([mm.beat_kernel_score(a, b) for b in beats]))
    return float(np.mean(vals))
