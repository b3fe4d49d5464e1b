"""Prosody figure: waveform, F0, intensity and syllable marks (matplotlib, Agg backend)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from gesture_sim.contracts import SAMPLE_RATE
from gesture_sim.fileio import atomic_path

if TYPE_CHECKING:
    from gesture_sim.audio.prosody import ProsodyAnalysis


def drawable(text: str, replacement: str = "?") -> str:
    """``text`` with every character that matplotlib's default fonts lack replaced by
    ``replacement``: a figure title made of a file name in another script (``日本語.wav``)
    then draws without matplotlib's "Glyph ... missing from font(s)" warning per character.
    Characters any font of the default family has are kept; without matplotlib or its fonts
    the text is returned unchanged."""
    if text.isascii():
        return text
    have = _default_charmap()
    if have is None:
        return text
    return "".join(c if c.isspace() or ord(c) in have else replacement for c in text)


_CHARMAP: list[frozenset[int] | None] = []


def _default_charmap() -> frozenset[int] | None:
    """The code points of the fonts matplotlib draws default text with (cached), or None."""
    if not _CHARMAP:
        try:
            from matplotlib import font_manager, ft2font

            prop = font_manager.FontProperties()
            try:   # the family's fonts, as matplotlib's glyph fallback walks them
                paths = list(font_manager.fontManager._find_fonts_by_props(prop))
            except AttributeError:  # pragma: no cover - older matplotlib
                paths = [font_manager.findfont(prop)]
            codes: set[int] = set()
            for path in paths:
                codes.update(ft2font.FT2Font(str(path)).get_charmap())
            _CHARMAP.append(frozenset(codes))
        except Exception:  # noqa: BLE001 - no fonts to ask: draw the text as given
            _CHARMAP.append(None)
    return _CHARMAP[0]


def plot_prosody(
    analysis: ProsodyAnalysis, path: str | os.PathLike[str], title: str = "",
    width_in: float | None = None,
) -> None:
    """Write a three-panel PNG: waveform with syllable spans, F0 (Hz) with per-syllable means,
    intensity (dB) with the silent frames and syllable boundaries / emission times."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fr = analysis.frames
    x = analysis.samples
    dur = max(len(x) / SAMPLE_RATE, 1e-3)
    width = width_in or float(np.clip(4 + dur * 0.9, 8, 30))
    fig, axes = plt.subplots(3, 1, figsize=(width, 6.5), sharex=True,
                             gridspec_kw={"height_ratios": [1, 1.2, 1.2]})
    ax_w, ax_f, ax_i = axes
    # waveform (decimated min/max envelope for long files)
    step = max(1, len(x) // 20000)
    t = np.arange(len(x)) / SAMPLE_RATE
    if step > 1:
        n = len(x) // step * step
        xs = x[:n].reshape(-1, step)
        tt = t[:n:step]
        ax_w.fill_between(tt, xs.min(1), xs.max(1), color="0.35", lw=0)
    else:
        ax_w.plot(t, x, color="0.35", lw=0.5)
    for k, s in enumerate(analysis.syllables):
        col = "tab:orange" if s.voiced else "tab:gray"
        for ax in (ax_w,):
            ax.axvspan(s.t_start, s.t_end, color=col, alpha=0.18 if k % 2 else 0.3, lw=0)
    ax_w.set_ylabel("waveform")
    # F0
    ax_f.plot(fr.times, fr.f0_hz, ".", ms=2.5, color="tab:blue", label="F0 per frame")
    for s in analysis.syllables:
        if s.f0_hz is not None:
            ax_f.hlines(s.f0_hz, s.t_start, s.t_end, color="tab:red", lw=2)
    ax_f.plot([], [], color="tab:red", lw=2, label="syllable mean F0")
    ax_f.set_ylabel("F0 (Hz)")
    ax_f.legend(loc="upper right", fontsize=7)
    # intensity
    inten = np.where(np.isfinite(fr.intensity_db), fr.intensity_db, np.nan)
    ax_i.plot(fr.times, inten, color="tab:green", lw=1, label="intensity")
    sil = np.where(fr.silent, inten, np.nan)
    ax_i.plot(fr.times, sil, color="0.6", lw=2, label="silent")
    fin = inten[np.isfinite(inten)]
    hi = float(fin.max()) + 5 if len(fin) else 100.0
    lo = max(float(np.percentile(fin, 1)) - 10, hi - 80) if len(fin) else 0.0
    ax_i.set_ylim(lo - 3, hi)
    for s in analysis.syllables:
        ax_i.axvline(s.t_start, color="k", lw=0.5, alpha=0.5)
        ax_i.hlines(s.intensity_db, s.t_start, s.t_end, color="tab:purple", lw=2)
        ax_i.plot([s.t_end, s.t_emitted], [lo, lo], color="tab:red", lw=1.5)
        ax_i.plot(s.t_emitted, lo, "v", color="tab:red", ms=3)
    ax_i.plot([], [], color="tab:purple", lw=2, label="syllable mean I")
    ax_i.plot([], [], "v-", color="tab:red", ms=3, label="end -> emitted")
    ax_i.set_ylabel("intensity (dB)")
    ax_i.set_xlabel("time (s)")
    ax_i.legend(loc="upper right", fontsize=7, ncol=4)
    ax_i.set_xlim(0, dur)
    s = analysis.summary
    fig.suptitle(
        f"{drawable(title)}  —  {s['n_syllables']} syllables, "
        f"{s['syllable_rate']:.2f}/s of speech, "
        f"voiced {100 * s['voiced_share']:.0f} %", fontsize=9,
    )
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
