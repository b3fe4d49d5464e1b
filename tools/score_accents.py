"""Score the causal accent detector against the lexical-stress marks of TextGrid alignments.

Usage::

    python tools/score_accents.py AUDIO TEXTGRID [AUDIO TEXTGRID ...] [--json] [--seed N]
                                  [--margin 0.1] [--secondary] [--threshold-sd X]

For each pair: the detector runs causally over the audio (``analyze_accents``); each accent is
matched one-to-one to the nearest stressed vowel (ARPAbet stress 1; ``--secondary`` adds 2)
whose interval widened by ``--margin`` s on both sides contains ``accent.t`` (greedy, nearest
first; distance = 0 inside the interval, else to its nearer edge, ties by the centre).

Figures: precision (matched accents / accents), recall (matched vowels / stressed vowels), F1;
recall over the stressed vowels of content words only; timing ``accent.t - vowel onset``
(median, median absolute); latency ``t_emitted - t`` and ``t_emitted - vowel onset`` of matched
accents (median, p95). Chance baselines with the same number of accents: ``syllable peaks`` =
random intensity peaks of the tracker's syllables (without replacement), ``uniform`` = random
times in non-silent frames; both averaged over 200 draws (seeded). ``every syllable`` puts one
accent on every syllable peak (the recall ceiling of a syllable-based detector). The last row
pools all pairs. Also checks that the same audio 12 dB quieter gives the same accents (share
of accents within 10 ms), scores the ``pause`` boundaries against the pauses of the word tier
(empty intervals >= 0.15 s; a boundary matches in [pause start - 0.3 s, pause end]) and gives
the median time from the voice onset after a pause boundary to the next accent's emission.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from gesture_sim.audio.accents import AccentAnalysis, AccentConfig, analyze_accents
from gesture_sim.audio.sources import load_audio
from gesture_sim.audio.textgrid import read_textgrid, stressed_vowels
from gesture_sim.errors import GestureSimError


def match(times: np.ndarray, vowels: np.ndarray, margin: float) -> list[tuple[int, int]]:
    """One-to-one greedy matching of accent times (n,) to vowel intervals (m, 2).

    Returns (accent index, vowel index) pairs; a pair needs the vowel's interval widened by
    ``margin`` to contain the time."""
    cand = []
    for i, t in enumerate(times):
        lo = np.searchsorted(vowels[:, 1], t - margin)  # first vowel ending after t - margin
        j = lo
        while j < len(vowels) and vowels[j, 0] - margin <= t:
            a, b = vowels[j]
            d = 0.0 if a <= t <= b else min(abs(t - a), abs(t - b))
            cand.append((d, abs(t - 0.5 * (a + b)), i, j))
            j += 1
    cand.sort()
    used_a, used_v, out = set(), set(), []
    for _, _, i, j in cand:
        if i not in used_a and j not in used_v:
            used_a.add(i)
            used_v.add(j)
            out.append((i, j))
    return out


def prf(n_acc: int, n_vow: int, n_match: int) -> tuple[float, float, float]:
    p = n_match / n_acc if n_acc else 0.0
    r = n_match / n_vow if n_vow else 0.0
    return p, r, (2 * p * r / (p + r) if p + r else 0.0)


def _pct(x: list[float] | np.ndarray, q: float) -> float:
    return float(np.percentile(x, q)) if len(x) else float("nan")


def score_pair(audio: str, textgrid: str, margin: float = 0.1, secondary: bool = False,
               config: AccentConfig | None = None, seed: int = 0, draws: int = 200) -> dict:
    """All figures for one audio/TextGrid pair (see the module docstring)."""
    x, _ = load_audio(audio)
    an = analyze_accents(x, config=config)
    tg = read_textgrid(textgrid)
    vow = np.array(stressed_vowels(tg, include_secondary=secondary), float).reshape(-1, 2)
    content = np.array(stressed_vowels(tg, include_secondary=secondary,
                                       content_words_only=True), float).reshape(-1, 2)
    t = np.array([a.t for a in an.accents])
    pairs = match(t, vow, margin)
    p, r, f1 = prf(len(t), len(vow), len(pairs))
    rc = len(match(t, content, margin)) / len(content) if len(content) else float("nan")
    err = [t[i] - vow[j, 0] for i, j in pairs]
    lat_t = [a.t_emitted - a.t for a in an.accents]
    lat_on = [an.accents[i].t_emitted - vow[j, 0] for i, j in pairs]
    # chance baselines with the same number of accents
    rng = np.random.default_rng(seed)
    frames_t = an.times
    speech_t = frames_t[an.speaking] if an.speaking.any() else frames_t
    peaks = _syllable_peaks(an)
    n = len(t)
    ch_syl, ch_uni = [], []
    for _ in range(draws):
        if len(peaks):
            ts = np.sort(rng.choice(peaks, size=min(n, len(peaks)), replace=False))
            ch_syl.append(prf(len(ts), len(vow), len(match(ts, vow, margin))))
        tu = np.sort(rng.choice(speech_t, size=n, replace=len(speech_t) < n))
        ch_uni.append(prf(len(tu), len(vow), len(match(tu, vow, margin))))
    every = prf(len(peaks), len(vow), len(match(np.sort(peaks), vow, margin)))
    # phrase boundaries vs the TextGrid's pauses (empty word intervals >= 0.15 s inside the
    # take): a boundary matches when its t lies in [pause start - 0.3 s, pause end]
    words = tg.tier("words")
    pauses = [(w.xmin, w.xmax) for i, w in enumerate(words)
              if not w.text.strip() and w.xmax - w.xmin >= 0.15 and 0 < i < len(words) - 1]
    bt = [b.t for b in an.boundaries if b.kind == "pause"]
    used: set[int] = set()
    for pa, pb in pauses:
        hit = [i for i, tb in enumerate(bt) if pa - 0.3 <= tb <= pb and i not in used]
        if hit:
            used.add(hit[0])
    # voice onset after a pause boundary -> the first accent's emission
    first = []
    for b in an.boundaries:
        k = int(np.searchsorted(frames_t, b.t_emitted))
        while k < len(frames_t) and an.frames.silent[k]:
            k += 1
        nxt = [a.t_emitted for a in an.accents if k < len(frames_t)
               and a.t >= frames_t[k] - 0.01]
        if nxt:
            first.append(nxt[0] - frames_t[k])
    # gain invariance
    quiet = analyze_accents(x * np.float32(10 ** (-12 / 20)), config=config)
    tq = np.array([a.t for a in quiet.accents])
    same = (len(match(t, np.c_[tq, tq], 0.0105)) / max(len(t), len(tq), 1)) if len(t) else 1.0
    return {
        "audio": str(audio), "textgrid": str(textgrid), "duration_s": len(x) / 16000,
        "n_stressed": len(vow), "n_content_stressed": len(content), "n_accents": n,
        "n_syllables": len(peaks), "n_boundaries": len(an.boundaries),
        "precision": p, "recall": r, "f1": f1, "recall_content": rc,
        "chance_syllable": np.mean(ch_syl, axis=0).tolist() if ch_syl else None,
        "chance_uniform": np.mean(ch_uni, axis=0).tolist(),
        "every_syllable": list(every),
        "timing_median_s": _pct(err, 50), "timing_abs_median_s": _pct(np.abs(err), 50),
        "latency_t_median_s": _pct(lat_t, 50), "latency_t_p95_s": _pct(lat_t, 95),
        "latency_onset_median_s": _pct(lat_on, 50), "latency_onset_p95_s": _pct(lat_on, 95),
        "gain_minus12db_same_share": same,
        "boundary_precision": len(used) / len(bt) if bt else float("nan"),
        "boundary_recall": len(used) / len(pauses) if pauses else float("nan"),
        "onset_to_first_accent_median_s": _pct(first, 50),
        "_bnd": (len(bt), len(pauses), len(used)), "_first": first,
        "_err": err, "_lat_t": lat_t, "_lat_on": lat_on, "_counts": (n, len(vow), len(pairs)),
        "_content": (len(content), len(match(t, content, margin))),
        "_ch": (ch_syl, ch_uni), "_every": (len(peaks), len(match(np.sort(peaks), vow, margin))),
    }


def _syllable_peaks(an: AccentAnalysis) -> np.ndarray:
    """Times (s) of the intensity maximum inside each of the tracker's syllables."""
    fr = an.frames
    out = []
    for s in an.syllables:
        m = (fr.times >= s.t_start - 1e-9) & (fr.times < s.t_end - 1e-9)
        if m.any():
            out.append(fr.times[m][int(np.argmax(fr.intensity_db[m]))])
    return np.array(out)


def pooled(rows: list[dict]) -> dict:
    n_acc = sum(r["_counts"][0] for r in rows)
    n_vow = sum(r["_counts"][1] for r in rows)
    n_m = sum(r["_counts"][2] for r in rows)
    p, r, f1 = prf(n_acc, n_vow, n_m)
    err = [e for r_ in rows for e in r_["_err"]]
    lat_t = [e for r_ in rows for e in r_["_lat_t"]]
    lat_on = [e for r_ in rows for e in r_["_lat_on"]]
    nc = sum(r["_content"][0] for r in rows)
    mc = sum(r["_content"][1] for r in rows)
    ev = prf(sum(r["_every"][0] for r in rows), n_vow, sum(r["_every"][1] for r in rows))
    return {
        "audio": "pooled", "n_stressed": n_vow, "n_accents": n_acc,
        "n_syllables": sum(r["n_syllables"] for r in rows),
        "precision": p, "recall": r, "f1": f1, "recall_content": mc / nc if nc else float("nan"),
        "chance_syllable": np.mean([r["chance_syllable"] for r in rows], axis=0).tolist(),
        "chance_uniform": np.mean([r["chance_uniform"] for r in rows], axis=0).tolist(),
        "every_syllable": list(ev),
        "timing_median_s": _pct(err, 50), "timing_abs_median_s": _pct(np.abs(err), 50),
        "latency_t_median_s": _pct(lat_t, 50), "latency_t_p95_s": _pct(lat_t, 95),
        "latency_onset_median_s": _pct(lat_on, 50), "latency_onset_p95_s": _pct(lat_on, 95),
        "gain_minus12db_same_share": float(np.mean([r["gain_minus12db_same_share"]
                                                    for r in rows])),
        "boundary_precision": sum(r["_bnd"][2] for r in rows) / sum(r["_bnd"][0] for r in rows),
        "boundary_recall": sum(r["_bnd"][2] for r in rows) / sum(r["_bnd"][1] for r in rows),
        "onset_to_first_accent_median_s": _pct([f for r in rows for f in r["_first"]], 50),
    }


def table(rows: list[dict]) -> str:
    head = ("| take | stressed | accents | P | R | F1 | chance at syllable peaks P / R / F1 | "
            "chance uniform F1 | "
            "every syllable P / R / F1 | R content words | t − onset median (abs) | "
            "latency t_emitted − t median / p95 | t_emitted − onset median / p95 | "
            "−12 dB same | pause boundaries P / R | voice onset → 1st accent median |")
    lines = [head, "| " + " | ".join(["---"] * 16) + " |"]
    for r in rows:
        cs, cu, ev = r["chance_syllable"], r["chance_uniform"], r["every_syllable"]
        lines.append(
            f"| {Path(r['audio']).stem} | {r['n_stressed']} | {r['n_accents']} | "
            f"{r['precision']:.2f} | {r['recall']:.2f} | **{r['f1']:.2f}** | "
            f"{cs[0]:.2f} / {cs[1]:.2f} / {cs[2]:.2f} | {cu[2]:.2f} | "
            f"{ev[0]:.2f} / {ev[1]:.2f} / {ev[2]:.2f} | "
            f"{r['recall_content']:.2f} | "
            f"{1000 * r['timing_median_s']:+.0f} ms ({1000 * r['timing_abs_median_s']:.0f}) | "
            f"{1000 * r['latency_t_median_s']:.0f} / {1000 * r['latency_t_p95_s']:.0f} ms | "
            f"{1000 * r['latency_onset_median_s']:.0f} / "
            f"{1000 * r['latency_onset_p95_s']:.0f} ms | "
            f"{100 * r['gain_minus12db_same_share']:.0f} % | "
            f"{r['boundary_precision']:.2f} / {r['boundary_recall']:.2f} | "
            f"{1000 * r['onset_to_first_accent_median_s']:.0f} ms |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", help="AUDIO TEXTGRID pairs")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    ap.add_argument("--margin", type=float, default=0.1, help="match window around a vowel (s)")
    ap.add_argument("--secondary", action="store_true", help="count stress 2 as stressed")
    ap.add_argument("--threshold-sd", type=float, default=None,
                    help="override AccentConfig.threshold_sd")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if len(args.files) % 2:
        print("gesture-sim: error: give AUDIO TEXTGRID pairs", file=sys.stderr)
        return 2
    cfg = AccentConfig() if args.threshold_sd is None else AccentConfig(
        threshold_sd=args.threshold_sd)
    try:
        rows = [score_pair(a, g, args.margin, args.secondary, cfg, args.seed)
                for a, g in zip(args.files[::2], args.files[1::2], strict=True)]
    except GestureSimError as e:
        print(f"gesture-sim: error: {e}", file=sys.stderr)
        return 2
    if len(rows) > 1:
        rows.append(pooled(rows))
    if args.json:
        print(json.dumps([{k: v for k, v in r.items() if not k.startswith("_")}
                          for r in rows], indent=1))
    else:
        print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
