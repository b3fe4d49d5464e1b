"""The evaluation's summaries: per-method means and seed spreads, the coupling margins over
random selection and mismatched audio with a verdict, and the table (duck-typed on an
:class:`~gesture_sim.app.evaluation.EvalResult`: ``summary()``, ``methods``, ``seeds``,
``reference``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: Metrics shown in the table and the bar plot: (key, label, direction) where direction is
#: +1 higher is better, -1 lower is better, 0 closer to ``real`` is better.
TABLE_METRICS: tuple[tuple[str, str, int], ...] = (
    ("bc", "BC", 1),
    ("bc_excess", "BC − chance", 1),
    ("beat_align", "BeatAlign", 1),
    ("r_intensity_best", "r(speed, intensity)", 1),
    ("r_f0d_best", "r(speed, |dF0|)", 1),
    ("accent_hit_rate", "accent hits", 1),
    ("accent_hit_excess", "accent hits − chance", 1),
    ("stress_hit_rate", "stress hits (TextGrid)", 1),
    ("stress_hit_excess", "stress hits − chance", 1),
    ("stress_error_median_s", "stroke–stress error (s)", -1),
    ("head_accent_hits", "head peaks on accents", 1),
    ("head_accent_excess", "head peaks on accents − chance", 1),
    ("head_lag_median_s", "accent → head peak (s)", 0),
    ("head_peaks_per_s", "head movements / s", 0),
    ("blinks_per_min", "blinks / min", 0),
    ("nods_per_min", "nods / min", 0),
    ("bc_beat2", "BC (BEAT2 tools)", 1),
    ("disc_accuracy", "discriminator acc. (0.5 = real)", -1),
    ("fgd", "FGD", -1),
    ("hellinger_speed", "Hellinger speed", -1),
    ("feature_diversity", "diversity", 0),
    ("l1div", "L1div (m)", 0),
    ("mean_jerk", "jerk (m/s³)", 0),
    ("mean_acceleration", "accel (m/s²)", 0),
    ("transition_jerk_ratio", "transition jerk ratio", -1),
    ("hand_error_rms_mm", "hand error (mm)", -1),
    ("foot_skate_mm_s", "foot skate (mm/s)", -1),
    ("fell", "fell", -1),
    ("switches_per_min", "target switches / min", 0),
    ("distinct_segments", "distinct segments", 0),
)


def summarise_rows(rows: list[dict], methods: Sequence[str]) -> dict:
    """See :meth:`EvalResult.summary`."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for method in methods:
        sel = [r for r in rows if r["method"] == method]
        if not sel:
            continue
        keys = sorted({k for r in sel for k in r["metrics"]})
        out[method] = {}
        for k in keys:
            vals = np.array([r["metrics"].get(k, np.nan) for r in sel], dtype=float)
            ok = vals[np.isfinite(vals)]
            seed_sds = []
            for audio in sorted({r["audio"] for r in sel}):
                v = np.array([r["metrics"].get(k, np.nan) for r in sel if r["audio"] == audio])
                v = v[np.isfinite(v)]
                if len(v) >= 2:
                    seed_sds.append(float(np.std(v, ddof=1)))
            out[method][k] = {
                "mean": float(ok.mean()) if ok.size else float("nan"),
                "sd": float(ok.std(ddof=1)) if ok.size >= 2 else float("nan"),
                "seed_sd": float(np.mean(seed_sds)) if seed_sds else float("nan"),
                "n": int(ok.size),
            }
    return out


def comparisons(summary: dict, a: str = "controller", b: str = "random",
                keys: Sequence[str] = ("bc", "bc_excess", "beat_align", "r_intensity_best",
                                       "r_f0d_best",
                                       "accent_hit_rate", "fgd")) -> dict:
    """``a`` minus ``b`` per metric, with the larger of the two seed spreads and whether the
    difference exceeds it (the issue's acceptance rule)."""
    out = {}
    if a not in summary or b not in summary:
        return out
    for k in keys:
        if k not in summary[a] or k not in summary[b]:
            continue
        d = summary[a][k]["mean"] - summary[b][k]["mean"]
        spread = np.nanmax([summary[a][k]["seed_sd"], summary[b][k]["seed_sd"], 0.0])
        out[f"{a}-{b}:{k}"] = {"difference": d, "seed_spread": float(spread),
                               "exceeds_spread": bool(abs(d) > spread)}
    return out


#: The coupling figures a verdict rests on (higher is better), the first three decisive. The
#: hit shares, the hands' and the head's, are judged less their chance level (the same peaks
#: shifted in time): a raw share grows with the number of speed peaks, so a method that moves
#: more, or switches more, wins it without timing anything (the raw shares stay in the table).
COUPLING_KEYS = ("bc_excess", "accent_hit_excess", "r_intensity_best", "beat_align", "r_f0d_best",
                 "stress_hit_excess", "head_accent_excess")
DECISIVE_KEYS = COUPLING_KEYS[:3]


def coupling_verdicts(summary: dict, baselines: Sequence[str] = ("random", "mismatched")
                      ) -> dict[str, dict]:
    """Does each method follow the speech? Per method (other than the baselines) and coupling
    figure: its margin over each baseline and the seed spread it must exceed (the larger of the
    two methods' seed spreads), and a verdict.

    Returns ``{method: {"figures": {key: {"margin_<baseline>": d, "spread_<baseline>": s,
    "beats_<baseline>": bool, "beats_all": bool}}, "verdict": str}}``. The verdict is
    "follows the speech" when the method beats every baseline by more than the spread on each
    of :data:`DECISIVE_KEYS`, "partly" when on some of them, "does not follow" otherwise.
    """
    out: dict[str, dict] = {}
    present = [b for b in baselines if b in summary]
    for method, figs in summary.items():
        if method in baselines or not present:
            continue
        rows: dict[str, dict] = {}
        for key in COUPLING_KEYS:
            if key not in figs or not all(key in summary[b] for b in present):
                continue
            row: dict[str, float | bool] = {}
            ok = True
            for b in present:
                d = figs[key]["mean"] - summary[b][key]["mean"]
                spread = float(np.nanmax([figs[key]["seed_sd"], summary[b][key]["seed_sd"],
                                          0.0]))
                beats = bool(np.isfinite(d) and d > spread)
                row[f"margin_{b}"], row[f"spread_{b}"], row[f"beats_{b}"] = d, spread, beats
                ok = ok and beats
            row["beats_all"] = ok
            rows[key] = row
        decisive = [rows[k]["beats_all"] for k in DECISIVE_KEYS if k in rows]
        verdict = ("follows the speech" if decisive and all(decisive)
                   else "partly follows the speech" if any(decisive) else "does not follow")
        out[method] = {"figures": rows, "verdict": verdict}
    return out


def format_verdicts(verdicts: dict[str, dict]) -> str:
    """One line per method and figure (margins over the baselines with the seed spread), then
    the verdict line."""
    lines = []
    labels = dict((k, lab) for k, lab, _ in TABLE_METRICS)
    for method, v in verdicts.items():
        for key, row in v["figures"].items():
            parts = []
            for name in ("random", "mismatched"):
                if f"margin_{name}" in row:
                    d, sp = row[f"margin_{name}"], row[f"spread_{name}"]
                    mark = "✓" if row[f"beats_{name}"] else "✗"
                    parts.append(f"vs {name} {d:+.3f} (spread {sp:.3f}) {mark}")
            lines.append(f"  {method:11s} {labels.get(key, key):24s} " + ", ".join(parts))
        lines.append(f"{method}: {v['verdict']}")
    return "\n".join(lines)


def _fmt(v: float) -> str:
    if v is None or not np.isfinite(v):
        return "–"
    a = abs(v)
    if a >= 100:
        return f"{v:.0f}"
    if a >= 10:
        return f"{v:.1f}"
    if a >= 1:
        return f"{v:.2f}"
    return f"{v:.3f}"


def format_table(result: Any, markdown: bool = True) -> str:
    """The summary as a table: one row per metric, one column per method, ``mean ± sd``
    (sd over seeds and files; the seed spread in brackets where there are several seeds)."""
    summ = result.summary()
    methods = [m for m in result.methods if m in summ]
    head = ["metric", *methods, "real mocap"]
    lines = []
    ref = result.reference
    for key, label, direction in TABLE_METRICS:
        if not any(key in summ[m] for m in methods):
            continue
        arrow = {1: " ↑", -1: " ↓", 0: " ≈mocap"}[direction]
        cells = [label + arrow]
        for m in methods:
            s = summ[m].get(key)
            if s is None or s["n"] == 0:
                cells.append("–")
                continue
            cell = f"{_fmt(s['mean'])} ± {_fmt(s['sd'])}"
            if len(result.seeds) > 1 and np.isfinite(s["seed_sd"]):
                cell += f" [{_fmt(s['seed_sd'])}]"
            cells.append(cell)
        cells.append(_fmt(ref.get(key, float("nan"))) if key in ref else "")
        lines.append(cells)
    if markdown:
        out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        out += ["| " + " | ".join(c) + " |" for c in lines]
        return "\n".join(out)
    widths = [max(len(r[i]) for r in [head, *lines]) for i in range(len(head))]
    fmt = lambda r: "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True))  # noqa: E731
    return "\n".join([fmt(head), fmt(["-" * w for w in widths]), *[fmt(r) for r in lines]])
