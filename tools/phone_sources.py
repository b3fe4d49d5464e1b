"""Phone sources and lip sync on the four BEAT2 TextGrid takes.

For each take (``--takes-dir DIR``: ``DIR/textgrids/NAME.TextGrid`` with ``DIR/NAME.wav``, the
BEAT2 layout):

* (a) the TextGrid's own phones: the reference;
* (b) :func:`gesture_sim.audio.phones.align_transcript` with the TextGrid's word sequence as the
  transcript: word-boundary error (|start| and |end| differences of the same words, ms: median,
  90th percentile) and phone-boundary error (start of the phones paired by an edit-distance
  alignment of the label sequences, same label only);
* (c) :class:`gesture_sim.audio.phones.PhoneRecogniser` fed 10 ms chunks (each mode asked for):
  phone error rate (Levenshtein distance of the non-silence label sequences / reference length),
  the same on viseme classes, latency (emission time - phone end: median, p90, max, ms) and CPU
  time per second of audio.
  Word-boundary errors are over the aligned words paired with the TextGrid's by an edit-distance
  alignment of the texts (``words_paired``).

Lip sync, per source: the share of the TextGrid's /P B M/ segments during which the source's
``lip_close`` reaches 0.9 (max over the 10 ms frames inside the segment and its centre), the
per-frame viseme-class agreement with the TextGrid-driven track (class of the phone at each
frame, and the nearest-class of the track values), and the mean |difference| of ``jaw_open``
(rad) and ``lip_close`` against the TextGrid-driven track. The live recogniser's phones drive a
:class:`~gesture_sim.signals.visemes.LiveCoarticulator` (each phone counts from its emission
time) shown with ``lag_s`` 0 and with its p90 latency (``live_lag_0``, ``live_lag_p90``), and,
for comparison, an offline :class:`~gesture_sim.signals.visemes.Coarticulator` over the same
recognised phones (``offline_from_phones``: what the recognised labels allow at best).

Usage::

    .venv/bin/python tools/phone_sources.py [--json OUT.json] [--modes allphone,words]
                                            [--takes 2] [--seconds 30]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gesture_sim.audio.phones import (  # noqa: E402
    SIL,
    Phone,
    align_transcript,
    number_words,
    phones_from_textgrid,
    recognise_phones,
    words_from_textgrid,
)
from gesture_sim.audio.sources import load_audio  # noqa: E402
from gesture_sim.metrics.alignment import edit_ops  # noqa: E402
from gesture_sim.signals.visemes import (  # noqa: E402
    Coarticulator,
    LiveCoarticulator,
    classify_track,
    labels_at,
    viseme_class,
)

FPS = 100
BILABIAL = ("P", "B", "M")


def _pct(x: list[float] | np.ndarray, q: float) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.percentile(x, q)) if len(x) else float("nan")


def _speech(phones: list[Phone]) -> list[Phone]:
    return [p for p in phones if p.label != SIL]


def lip_sync(ref: list[Phone], track: np.ndarray, times: np.ndarray, at_centres: np.ndarray,
             ref_track: np.ndarray) -> dict[str, float]:
    """Bilabial closure share, class agreement, channel differences of a track (T, 6)."""
    bil = [i for i, p in enumerate(ref) if p.label in BILABIAL]
    closed = 0
    for k, i in enumerate(bil):
        p = ref[i]
        m = (times >= p.start_s) & (times < p.end_s)
        v = max(float(track[m, 1].max()) if m.any() else 0.0, float(at_centres[k]))
        closed += v >= 0.9
    cls_ref = [viseme_class(lab) for lab in labels_at(ref, times)]
    tr_cls, ref_cls = classify_track(track), classify_track(ref_track)
    return {
        "bilabial_n": len(bil),
        "bilabial_closed": closed / max(1, len(bil)),
        "track_class_agree": float(np.mean([a == b for a, b in zip(tr_cls, ref_cls,
                                                                   strict=True)])),
        "jaw_mae_rad": float(np.mean(np.abs(track[:, 0] - ref_track[:, 0]))),
        "lip_close_mae": float(np.mean(np.abs(track[:, 1] - ref_track[:, 1]))),
        "_cls_ref": cls_ref,  # dropped before output
    }


def label_agreement(cls_ref: list[str], phones: list[Phone], times: np.ndarray) -> float:
    cls = [viseme_class(lab) for lab in labels_at(phones, times)]
    return float(np.mean([a == b for a, b in zip(cls, cls_ref, strict=True)]))


def run_take(tg: Path, wav: Path, modes: list[str], seconds: float | None) -> dict:
    ref = phones_from_textgrid(tg)
    words = words_from_textgrid(tg)
    x, _ = load_audio(wav)
    if seconds is not None:
        # cut inside a pause (the aligner needs whole words): the last pause before `seconds`
        pauses = [p for p in ref if p.label == SIL and p.start_s < seconds and p.start_s > 0]
        end = min(seconds, pauses[-1].centre_s) if pauses else seconds
        x = x[: int(end * 16000)]
        end = len(x) / 16000
        ref = [p for p in ref if p.end_s <= end]
        words = [w for w in words if w.end_s <= end]
    dur = len(x) / 16000
    times = np.arange(0.0, dur, 1.0 / FPS)
    bil_centres = np.array([p.centre_s for p in ref if p.label in BILABIAL])
    ref_co = Coarticulator(ref)
    ref_track = ref_co.track(times)
    out: dict = {"take": tg.stem, "duration_s": dur, "words": len(words),
                 "phones": len(_speech(ref))}
    res = lip_sync(ref, ref_track, times, ref_co.track(bil_centres)[:, 1], ref_track)
    cls_ref = res.pop("_cls_ref")
    res["label_class_agree"] = 1.0
    out["textgrid"] = res

    # (b) forced alignment
    t0 = time.process_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tr = align_transcript(x, 16000, " ".join(w.text for w in words))
    a_cpu = time.process_time() - t0
    aw = list(tr.words)
    # pair the aligned words with the TextGrid's by an edit-distance alignment of the texts
    # (numbers are read out by the aligner: "5" -> "five"; a number of several words pairs
    # by its first word)
    ref_txt = [number_words(int(w.text))[0] if w.text.isdigit() else w.text for w in words]
    _, wpairs = edit_ops(ref_txt, [w.text for w in aw])
    n_ok = len(wpairs)
    wd = ([abs(aw[j].start_s - words[i].start_s) for i, j in wpairs]
          + [abs(aw[j].end_s - words[i].end_s) for i, j in wpairs])
    rs, hs = _speech(ref), _speech(list(tr.phones))
    dist, pairs = edit_ops([p.label for p in rs], [p.label for p in hs])
    pb = [abs(rs[i].start_s - hs[j].start_s) for i, j in pairs]
    al_co = Coarticulator(tr.phones)
    res = lip_sync(ref, al_co.track(times), times, al_co.track(bil_centres)[:, 1], ref_track)
    res.pop("_cls_ref")
    res["label_class_agree"] = label_agreement(cls_ref, list(tr.phones), times)
    out["aligned"] = {
        "cpu_s": a_cpu, "words_aligned": len(aw), "words_paired": n_ok,
        "fallback": list(tr.fallback), "skipped": list(tr.skipped),
        "warnings": [str(w.message) for w in caught],
        "word_boundary_ms_median": 1000 * _pct(wd, 50),
        "word_boundary_ms_p90": 1000 * _pct(wd, 90),
        "phone_boundary_ms_median": 1000 * _pct(pb, 50),
        "phone_boundary_ms_p90": 1000 * _pct(pb, 90),
        "phone_label_error": dist / max(1, len(rs)), **res,
    }

    # (c) live recogniser
    for mode in modes:
        t0 = time.process_time()
        em = recognise_phones(x, 16000, chunk_s=0.01, mode=mode)
        cpu = time.process_time() - t0
        hyp = [e.phone for e in em]
        hs = _speech(hyp)
        dist, _ = edit_ops([p.label for p in rs], [p.label for p in hs])
        vdist, _ = edit_ops([viseme_class(p.label) for p in rs],
                            [viseme_class(p.label) for p in hs])
        lat = np.array([e.latency_s for e in em if e.phone.label != SIL])
        p90 = _pct(lat, 90)
        entry = {
            "cpu_per_audio_s": cpu / dur, "phones_emitted": len(hs),
            "phone_error_rate": dist / max(1, len(rs)),
            "viseme_class_error_rate": vdist / max(1, len(rs)),
            "latency_ms_median": 1000 * _pct(lat, 50), "latency_ms_p90": 1000 * p90,
            "latency_ms_max": 1000 * float(lat.max()) if len(lat) else float("nan"),
            "label_class_agree": label_agreement(cls_ref, hyp, times),
        }
        offline = Coarticulator(hyp)
        res = lip_sync(ref, offline.track(times), times, offline.track(bil_centres)[:, 1],
                       ref_track)
        res.pop("_cls_ref")
        entry["offline_from_phones"] = res
        p90_lag = round(float(np.ceil(p90 * 100 - 1e-6) / 100), 2)
        for name, lag in (("live_lag_0", 0.0), ("live_lag_p90", p90_lag)):
            live = LiveCoarticulator(lag_s=lag)
            for e in em:
                live.push(e.phone, e.emitted_s)
            # the bilabial centre as seen lag_s later, with what is known then
            cen = np.array([live.track(np.array([c + lag]))[0, 1] for c in bil_centres])
            shown = live.track(times + lag)
            res = lip_sync(ref, shown, times, cen, ref_track)
            res.pop("_cls_ref")
            res["lag_ms"] = 1000 * lag
            entry[name] = res
        out[f"live_{mode}"] = entry
    return out


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.3f}" if abs(v) < 10 else f"{v:.0f}"
    return str(v)


def summary(takes: list[dict]) -> dict:
    """Pooled figures: means over takes (bilabial share weighted by the bilabials)."""
    def flat(d: dict, prefix: str = "") -> dict:
        o = {}
        for k, v in d.items():
            if isinstance(v, dict):
                o.update(flat(v, f"{prefix}{k}."))
            elif isinstance(v, (int, float)) and not isinstance(v, bool):
                o[f"{prefix}{k}"] = float(v)
        return o
    flats = [flat(t) for t in takes]
    keys = [k for k in flats[0] if all(k in f for f in flats)]
    out = {}
    for k in keys:
        if k.endswith("bilabial_closed"):
            nk = k.replace("bilabial_closed", "bilabial_n")
            w = np.array([f[nk] for f in flats])
            out[k] = float(np.sum([f[k] for f in flats] * w) / w.sum())
        else:
            out[k] = float(np.mean([f[k] for f in flats]))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--takes-dir", type=Path, required=True,
                    help="folder with NAME.wav and textgrids/NAME.TextGrid")
    ap.add_argument("--json", help="write the figures as JSON here")
    ap.add_argument("--modes", default="allphone,words", help="live recogniser modes")
    ap.add_argument("--takes", type=int, default=4, help="how many takes (first N)")
    ap.add_argument("--seconds", type=float, default=None, help="only the first S s of each")
    args = ap.parse_args(argv)
    modes = [m for m in args.modes.split(",") if m]
    t_start = time.perf_counter()
    data = args.takes_dir
    grids = sorted((data / "textgrids").glob("*.TextGrid"))[: args.takes]
    takes = []
    for tg in grids:
        t0 = time.perf_counter()
        r = run_take(tg, data / f"{tg.stem}.wav", modes, args.seconds)
        r["wall_s"] = time.perf_counter() - t0
        takes.append(r)
        print(f"{tg.stem}: {r['duration_s']:.1f} s audio, {r['wall_s']:.1f} s", flush=True)
    pooled = summary(takes)
    rows = [k for k in pooled if not k.endswith(("bilabial_n", "duration_s", "wall_s"))]
    print(f"\n{'figure':58s} " + " ".join(f"{t['take'][-5:]:>8s}" for t in takes)
          + f" {'pooled':>8s}")
    for k in rows:
        vals = []
        for t in takes:
            d: object = t
            for part in k.split("."):
                d = d.get(part, float("nan")) if isinstance(d, dict) else float("nan")
            vals.append(_fmt(d))
        print(f"{k:58s} " + " ".join(f"{v:>8s}" for v in vals) + f" {_fmt(pooled[k]):>8s}")
    wall = time.perf_counter() - t_start
    print(f"\nrun time {wall:.1f} s")
    if args.json:
        Path(args.json).write_text(json.dumps({"takes": takes, "pooled": pooled,
                                               "run_time_s": wall, "modes": modes,
                                               "seconds": args.seconds}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
