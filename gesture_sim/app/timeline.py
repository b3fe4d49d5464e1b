"""The timeline figure: why the character moved.

Panels, sharing the time axis (s): the waveform with syllable spans; F0 (Hz) and intensity (dB);
the belief over hidden states as a heat map (rows sorted by the states' velocity parameter, so
"calm" is at the bottom and "energetic" at the top); the chosen segments as coloured bars with
interruptions and semantic/style events marked; the hand speed of the simulated body (m/s).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE, Syllable
from gesture_sim.fileio import atomic_path
from gesture_sim.metrics.selection import SegmentSpan


@dataclass
class TimelineData:
    """Everything the figure draws; every time axis in seconds since the stream began.

    Attributes:
        audio: (n,) float32 samples at ``sample_rate``.
        frame_times, f0_hz, intensity_db: prosody frames (m,), F0 NaN where unvoiced.
        syllables: the tracker's syllables.
        step_times: (k,) control-step times; belief: (k, S) belief per step.
        state_velocity: (S,) the velocity parameter of each hidden state (for row order).
        spans: the segments that played.
        events: (t, text) markers, e.g. semantic labels and style changes.
        hand_times, hand_speed: (h,) times and (h,) or (h, 2) hand speeds (m/s).
        accents: times (s) of the accents the detector emitted (▲ on the waveform).
        strokes: times (s) the timing layer passed a stroke peak (| on the hand speed).
        rest_spans: (t0, t1) spans at rest (grey on the segment row).
        energy_times, energy: the vocal energy in (-1, 1) per control step.
        signals: (t, text) face and head signals (nods, brows, blinks; on the F0 panel).
        words: (t_start, t_end, word) spotted keywords (on the waveform).
        state_names: names of the belief's states when they have them (``chiu14``: the 14
            gestural signs; the belief row then shows the signs, with the most probable one per
            step outlined), else None (hidden states, sorted by velocity).
    """

    audio: np.ndarray
    frame_times: np.ndarray
    f0_hz: np.ndarray
    intensity_db: np.ndarray
    syllables: Sequence[Syllable]
    step_times: np.ndarray
    belief: np.ndarray
    spans: Sequence[SegmentSpan]
    hand_times: np.ndarray
    hand_speed: np.ndarray
    state_velocity: np.ndarray | None = None
    events: Sequence[tuple[float, str]] = field(default_factory=list)
    sample_rate: int = SAMPLE_RATE
    title: str = ""
    accents: Sequence[float] = ()
    strokes: Sequence[float] = ()
    rest_spans: Sequence[tuple[float, float]] = ()
    energy_times: np.ndarray | None = None
    energy: np.ndarray | None = None
    signals: Sequence[tuple[float, str]] = ()
    words: Sequence[tuple[float, float, str]] = ()
    state_names: Sequence[str] | None = None


def plot_timeline(data: TimelineData, path: str | os.PathLike[str], *, width_in: float = 14.0,
                  dpi: int = 110) -> None:
    """Draw the timeline to a PNG at ``path`` (written atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    duration = max(len(data.audio) / data.sample_rate,
                   float(data.step_times[-1]) if len(data.step_times) else 0.0)
    fig, axes = plt.subplots(
        5, 1, figsize=(width_in, 9.5), sharex=True,
        gridspec_kw={"height_ratios": [1.0, 1.2, 1.6, 0.9, 1.1]},
    )
    ax_wave, ax_pros, ax_belief, ax_seg, ax_hand = axes

    # Waveform with syllable spans.
    n = len(data.audio)
    stride = max(1, n // 20000)
    t_audio = np.arange(0, n, stride) / data.sample_rate
    ax_wave.plot(t_audio, data.audio[::stride], lw=0.4, color="0.3")
    for s in data.syllables:
        ax_wave.axvspan(s.t_start, s.t_end, color="tab:orange" if s.voiced else "0.8", alpha=0.25,
                        lw=0)
        ax_wave.axvline(s.t_emitted, color="tab:red", lw=0.4, alpha=0.5)
    if len(data.accents):
        top = float(np.max(np.abs(data.audio))) if n else 1.0
        ax_wave.plot(data.accents, np.full(len(data.accents), 0.9 * top), "^",
                     color="tab:purple", ms=4, label="accents")
        ax_wave.legend(loc="upper right", fontsize=7)
    for w0, w1, word in data.words:
        ax_wave.axvspan(w0, w1, color="tab:purple", alpha=0.25, lw=0)
        ax_wave.text(w0, ax_wave.get_ylim()[0], word, fontsize=6, color="tab:purple",
                     va="bottom")
    ax_wave.set_ylabel("audio")
    ax_wave.set_yticks([])
    if data.title:
        ax_wave.set_title(data.title, fontsize=10, loc="left")

    # F0 and intensity.
    ax_pros.plot(data.frame_times, data.f0_hz, ".", ms=1.5, color="tab:blue")
    ax_pros.set_ylabel("F0 (Hz)", color="tab:blue")
    ax_int = ax_pros.twinx()
    ax_int.plot(data.frame_times, data.intensity_db, lw=0.6, color="tab:green")
    ax_int.set_ylabel("intensity (dB)", color="tab:green")
    finite = np.asarray(data.intensity_db)[np.isfinite(data.intensity_db)]
    if finite.size:   # the analysis start-up frames can be far below the speech range
        lo, hi = np.percentile(finite, [2, 99.5])
        ax_int.set_ylim(lo - 3, hi + 3)
    f0 = np.asarray(data.f0_hz)[np.isfinite(data.f0_hz)]
    if f0.size:
        lo, hi = np.percentile(f0, [1, 99])
        ax_pros.set_ylim(0.8 * lo, 1.15 * hi)
    marks = {"nod": ("v", "tab:brown"), "jog": ("v", "tab:brown"), "brow": ("^", "tab:pink"),
             "smile": ("s", "tab:orange"), "blink": ("o", "0.4"), "gaze": ("<", "tab:cyan")}
    # the accents' ToBI types (RUTH's typing from the F0 contour), small, along the bottom
    typed = [(t, text.split()[1]) for t, text in data.signals if text.startswith("accent ")]
    if 0 < len(typed) <= 400:
        y_low = ax_pros.get_ylim()[0]
        for t, kind in typed:
            ax_pros.text(t, y_low, kind, fontsize=4, color="tab:purple", ha="center",
                         va="bottom", rotation=90)
    y_top = ax_pros.get_ylim()[1]
    for kind, (marker, color) in marks.items():
        ts = [t for t, text in data.signals if text.split()[0].lower().startswith(kind)]
        if ts:
            ax_pros.plot(ts, np.full(len(ts), 0.97 * y_top), marker, ms=3, color=color,
                         ls="none", label=kind)
    if data.signals:
        ax_pros.legend(loc="upper left", fontsize=6, ncol=4)

    # Belief heat map, rows sorted by state velocity.
    belief = np.asarray(data.belief)
    if belief.size:
        order = (np.argsort(data.state_velocity) if data.state_velocity is not None
                 else np.arange(belief.shape[1]))
        dt = float(np.median(np.diff(data.step_times))) if len(data.step_times) > 1 else 1 / 30
        extent = (float(data.step_times[0]) - dt / 2, float(data.step_times[-1]) + dt / 2,
                  -0.5, belief.shape[1] - 0.5)
        ax_belief.imshow(belief[:, order].T, aspect="auto", origin="lower", extent=extent,
                         cmap="magma", vmin=0.0, vmax=1.0, interpolation="nearest")
        ax_belief.set_yticks(range(belief.shape[1]))
        names = data.state_names
        if names is not None and len(names) == belief.shape[1]:
            ax_belief.set_yticklabels([names[i] for i in order], fontsize=6)
            # the most probable sign per step (the decoded sign's row)
            top = np.argsort(order)[np.argmax(belief, axis=1)]
            ax_belief.plot(data.step_times, top, color="#39c", lw=0.0, marker="s", ms=1.2)
        else:
            ax_belief.set_yticklabels([str(i) for i in order], fontsize=6)
    ax_belief.set_ylabel("gestural sign" if data.state_names is not None
                         else "hidden state\n(slow → fast)")

    # Segment bars.
    cmap = plt.get_cmap("tab20")
    for span in data.spans:
        ax_seg.barh(0, span.t_end - span.t_start, left=span.t_start, height=0.8,
                    color=cmap(span.segment_id % 20), edgecolor="k", lw=0.3)
        if span.t_end - span.t_start > 0.25 * duration / 30:
            ax_seg.text(0.5 * (span.t_start + span.t_end), 0, str(span.segment_id), ha="center",
                        va="center", fontsize=5)
        if span.interrupted:
            ax_seg.plot([span.t_end], [0.45], marker="v", color="tab:red", ms=4)
        if span.kind == "label":
            ax_seg.plot([span.t_start], [-0.45], marker="^", color="tab:purple", ms=5)
    for t0, t1 in data.rest_spans:
        ax_seg.axvspan(t0, min(t1, duration), color="0.85", lw=0, zorder=0)
    if data.energy is not None and len(data.energy):
        ax_en = ax_seg.twinx()
        ax_en.plot(data.energy_times, data.energy, lw=0.7, color="tab:olive")
        ax_en.set_ylim(-1.05, 1.05)
        ax_en.set_ylabel("vocal\nenergy", color="tab:olive", fontsize=7)
    for t, text in data.events:
        ax_seg.axvline(t, color="tab:purple", lw=0.8, ls="--")
        ax_seg.text(t, 0.55, text, fontsize=6, color="tab:purple", rotation=0, va="bottom")
    ax_seg.set_ylim(-0.7, 0.9)
    ax_seg.set_yticks([])
    ax_seg.set_ylabel("segments\n(▼ interrupted,\ngrey: rest)")

    # Hand speed.
    speed = np.asarray(data.hand_speed)
    if speed.ndim == 1:
        speed = speed[:, None]
    for j, (label, color) in enumerate((("left hand", "tab:blue"), ("right hand", "tab:red"))):
        if j < speed.shape[1]:
            ax_hand.plot(data.hand_times, speed[:, j], lw=0.7, color=color, label=label)
    for t in data.strokes:
        ax_hand.axvline(t, color="tab:purple", lw=0.4, alpha=0.5)
    ax_hand.set_ylabel("hand speed\n(m/s)\n(| strokes)")
    ax_hand.set_xlabel("time (s)")
    ax_hand.legend(loc="upper right", fontsize=7)
    ax_hand.set_xlim(0, duration)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
