"""Score the keyword spotter (gesture_sim.audio.keywords) on known answers.

* ``--espeak``: espeak-ng sentences (voice en-us+f5) with each table phrase between carrier
  phrases, plus sentences without any, concatenated with numpy so every phrase's time is known:
  per-phrase recall, false hits, the margin of each phrase's scores over its threshold, and the
  latency from the phrase's end to ``t_emitted`` (median, p95).
* ``--takes``: real speech with word alignments (BEAT2 "scott" takes and their TextGrids):
  precision and recall of the table against the word tier at the table's thresholds, and a
  precision/recall curve over a threshold offset (decades; one decode at the loosest offset,
  then filtered).
* ``--utterances``: the recogniser of words said as utterances of their own
  (:mod:`gesture_sim.audio.utterances`) on espeak-ng greetings and foils in four voices.
* Always: the spotter's CPU cost (share of one core at real time).

    .venv/bin/python tools/score_keywords.py --espeak --takes DATA/2_scott_0_1_1.wav ... \
        [--json out.json]
"""

from __future__ import annotations

import argparse
import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gesture_sim.audio.keywords import (  # noqa: E402
    KeywordTable,
    SpotterStats,
    spot_file,
    transcript_keywords,
)
from gesture_sim.audio.sources import load_audio, resample_to_16k, to_float_mono  # noqa: E402
from gesture_sim.audio.utterances import UTTERANCE_WORDS  # noqa: E402

VOICE = "en-us+f5"
CARRIERS = [("So I just wanted to say", "and then we can start"),
            ("Well, as you know,", "is what they told me"),
            ("Let me think about it.", "That was a long day.")]
NEGATIVES = ["The weather was cold and the trains were late.",
             "We talked about the project for an hour.",
             "My brother bought a new car last week.",
             "Please open the window before you leave."]


def tts(text: str, voice: str = VOICE, speed: int = 160) -> np.ndarray:
    """espeak-ng speech of ``text`` as float32 16 kHz, leading/trailing silence trimmed."""
    import warnings

    from scipy.io import wavfile

    out = subprocess.run(["espeak-ng", "-v", voice, "-s", str(speed), "--stdout", text],
                         capture_output=True, check=True).stdout
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rate, data = wavfile.read(io.BytesIO(out))
    x = resample_to_16k(to_float_mono(data), rate)
    idx = np.flatnonzero(np.abs(x) > 0.01)
    return x[max(idx[0] - 80, 0): idx[-1] + 80]


def espeak_stream(phrases, voice=VOICE, gap_s=0.3):
    """One stream: carrier + phrase + carrier for every phrase and carrier, then the negatives.
    Returns (samples, [(phrase, t_start, t_end)], [(t_start, t_end)] of the negatives)."""
    gap = np.zeros(int(gap_s * 16000), np.float32)
    parts, truth, negs, n = [gap], [], [], len(gap)
    for pre_t, post_t in CARRIERS:
        pre, post = tts(pre_t, voice), tts(post_t, voice)
        for p in phrases:
            kw = tts(p, voice)
            a = n + len(pre) + len(gap) // 2
            parts += [pre, gap[: len(gap) // 2], kw, gap[: len(gap) // 2], post, gap]
            truth.append((p, a / 16000, (a + len(kw)) / 16000))
            n += len(pre) + len(kw) + len(post) + 2 * (len(gap) // 2) + len(gap)
    for s in NEGATIVES:
        x = tts(s, voice)
        parts += [x, gap]
        negs.append((n / 16000, (n + len(x)) / 16000))
        n += len(x) + len(gap)
    return np.concatenate(parts), truth, negs


def score_espeak(table: KeywordTable, voice: str = VOICE, confirm: bool = True) -> dict:
    from gesture_sim.audio.keywords import DEFAULT_CONFIRM

    x, truth, negs = espeak_stream(table.phrases, voice)
    stats = SpotterStats()
    hits = spot_file(x, table, stats=stats, confirm=DEFAULT_CONFIRM if confirm else None)
    found, lat, per = set(), [], {}
    for i, (p, a, b) in enumerate(truth):
        own = [h for h in hits if h.word == p and h.t_start < b and h.t_end > a]
        per.setdefault(p, {"n": 0, "found": 0, "scores": []})
        per[p]["n"] += 1
        if own:
            found.add(i)
            per[p]["found"] += 1
            per[p]["scores"].append(round(max(h.confidence for h in own), 1))
            lat.append(min(h.t_emitted for h in own) - b)
    false = [h for h in hits
             if not any(h.word == p and h.t_start < b and h.t_end > a for p, a, b in truth)]
    lat_a = np.asarray(lat) if lat else np.zeros(1)
    return {"duration_s": round(len(x) / 16000, 2), "instances": len(truth),
            "recall": len(found) / len(truth), "false_hits": len(false),
            "false_in_negatives": sum(1 for h in false
                                      if any(a <= h.t_start < b for a, b in negs)),
            "false": [(h.word, round(h.t_start, 2), round(h.confidence, 1)) for h in false],
            "latency_median_s": round(float(np.median(lat_a)), 3),
            "latency_p95_s": round(float(np.percentile(lat_a, 95)), 3),
            "per_phrase": {p: {**v, "log10_threshold": round(table.entry(p).log10_threshold, 1)}
                           for p, v in per.items()},
            "core_share": round(stats.core_share, 4)}


def _match(hits, truth, tol=0.25):
    """Greedy one-to-one matching of hits to truth keywords of the same phrase (overlap with
    ``tol`` s slack); returns the number of true positives."""
    used, tp = set(), 0
    for h in sorted(hits, key=lambda k: -k.confidence):
        for j, t in enumerate(truth):
            if j not in used and t.word == h.word and h.t_start < t.t_end + tol \
                    and h.t_end > t.t_start - tol:
                used.add(j)
                tp += 1
                break
    return tp


def score_takes(table: KeywordTable, takes: list[str],
                offsets=(-20, -10, -5, 0, 5, 10, 20), noise_db=(), confirm=True) -> dict:
    """``takes``: WAV paths; each is scored against ``tests/data/textgrids/<stem>.TextGrid``,
    clean and under the noise of :func:`gesture_sim.testing.noise.noisy_recording` (6 s lead,
    room tone + hiss + hum + click) at each level of ``noise_db`` (dBFS)."""
    from gesture_sim.audio.keywords import DEFAULT_CONFIRM
    from gesture_sim.testing import noise as nz

    grids = ROOT / "tests" / "data" / "textgrids"
    loose = table.scaled(min(offsets))
    per_take, all_hits, all_truth, dur, cpu, rejected = [], [], [], 0.0, 0.0, 0
    for wav in takes:
        name = Path(wav).stem
        x0, _ = load_audio(wav)
        grid = grids / f"{name}.TextGrid"
        for level in (None, *noise_db):
            lead = 0.0 if level is None else 6.0
            x = x0 if level is None else nz.noisy_recording(
                x0, nz.word_frames(grid, len(x0) // 160), level, lead)
            stats = SpotterStats()
            hits = spot_file(x, loose, stats=stats,
                             confirm=DEFAULT_CONFIRM if confirm else None)
            # the table's phrases and the words recognised as utterances of their own
            truth = [type(t)(t.word, t.t_start + lead, t.t_end + lead, t.confidence,
                             t.t_emitted + lead, t.label)
                     for t in transcript_keywords(grid, table)]
            per_take.append({"take": name, "noise_dbfs": level,
                             "duration_s": round(len(x) / 16000, 1),
                             "truth": [t.word for t in truth],
                             "false_at_default": [
                                 (h.word, round(h.t_start, 2), round(h.confidence, 1))
                                 for h in hits if (h.word in UTTERANCE_WORDS
                                                   or h.confidence >= table.entry(
                                                       h.word).log10_threshold)
                                 and not _match([h], truth)]})
            all_hits.append(hits)
            all_truth.append(truth)
            dur += len(x) / 16000
            cpu += stats.cpu_s
            rejected += stats.rejected
    curve = []
    for off in offsets:
        tp = fp = n_true = 0
        for hits, truth in zip(all_hits, all_truth, strict=True):
            keep = [h for h in hits if h.word in UTTERANCE_WORDS
                    or h.confidence >= table.entry(h.word).log10_threshold + off]
            t = _match(keep, truth)
            tp += t
            fp += len(keep) - t
            n_true += len(truth)
        curve.append({"offset_decades": off, "hits": tp + fp, "tp": tp, "fp": fp,
                      "truth": n_true,
                      "precision": round(tp / (tp + fp), 3) if tp + fp else None,
                      "recall": round(tp / n_true, 3) if n_true else None,
                      "false_per_min": round(fp / (dur / 60), 2)})
    at0 = [h for hits in all_hits for h in hits if h.word in UTTERANCE_WORDS
           or h.confidence >= table.entry(h.word).log10_threshold]
    truth_at0 = [(t.word, round(t.t_start, 2)) for truth in all_truth for t in truth]
    return {"duration_s": round(dur, 1), "takes": per_take, "curve": curve,
            "hits_at_default": [(h.word, round(h.t_start, 2), round(h.confidence, 1), h.label)
                                for h in at0],
            "truth": truth_at0, "rejected_by_recogniser": rejected,
            "core_share": round(cpu / dur, 4)}


UTTERANCE_VOICES = ("en-us+f5", "en-us+m3", "en-gb", "en-us")
UTTERANCE_SAYINGS = {"Hello?": "hello", "Hi!": "hi", "Hey.": "hey", "Thank you.": "thank you",
                     "Thanks.": "thanks", "Bye!": "bye", "Goodbye.": "goodbye", "Yes.": "yes",
                     "Okay.": "okay"}
UTTERANCE_FOILS = ("High.", "By the way.", "Oh well.", "I think so.", "No.", "Hold on.",
                   "I was just thinking about the weather today and how it changed.")


def score_utterances() -> dict:
    """The utterance recogniser on espeak-ng: each saying and foil as an utterance of its own
    (0.5 s apart) in four voices: recall per voice, false hits on the foils."""
    from gesture_sim.audio.utterances import UtteranceRecognizer

    out: dict = {"voices": {}, "false": []}
    gap = np.zeros(8000, np.float32)
    for voice in UTTERANCE_VOICES:
        parts, spans, t = [], [], 0.5
        for text in [*UTTERANCE_SAYINGS, *UTTERANCE_FOILS]:
            x = tts(text, voice)
            spans.append((text, t, t + len(x) / 16000))
            parts += [gap, x]
            t += len(x) / 16000 + 0.5
        rec = UtteranceRecognizer()
        x = np.concatenate([*parts, gap])
        hits = []
        for i in range(0, len(x), 160):
            hits += rec.push(x[i:i + 160], i / 16000)
        hits += rec.finish()
        found = 0
        for text, a, b in spans:
            mine = [h for h in hits if a - 0.2 <= h.t_start <= b + 0.2]
            want = UTTERANCE_SAYINGS.get(text)
            if want is not None and any(h.word == want for h in mine):
                found += 1
            out["false"] += [(voice, text, h.word) for h in mine if h.word != want]
        out["voices"][voice] = {"found": found, "of": len(UTTERANCE_SAYINGS)}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--espeak", action="store_true")
    ap.add_argument("--utterances", action="store_true",
                    help="the utterance recogniser on espeak-ng greetings and foils")
    ap.add_argument("--takes", nargs="+", default=[], metavar="WAV",
                    help="real takes with word alignments in tests/data/textgrids/<stem>.TextGrid"
                         " (e.g. the BEAT2 scott takes 2_scott_0_{1_1,2_2,3_3,4_4}.wav)")
    ap.add_argument("--noise-db", nargs="*", type=float, default=[], metavar="DBFS",
                    help="also score each take under room tone + hiss + hum + click at these "
                         "levels (e.g. -30 -45 -60)")
    ap.add_argument("--offsets", nargs="+", type=float, default=[-20, -10, -5, 0, 5, 10, 20],
                    help="threshold offsets of the curve (decades)")
    ap.add_argument("--no-confirm", action="store_true",
                    help="emit every spotted phrase (no confirmation by the recogniser)")
    ap.add_argument("--keywords", default=None, help="keyword table (default: the shipped one)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    table = KeywordTable.load(args.keywords)
    out = {}
    if args.espeak:
        out["espeak"] = score_espeak(table, confirm=not args.no_confirm)
    if args.takes:
        out["takes"] = score_takes(table, args.takes, tuple(args.offsets), tuple(args.noise_db),
                                   confirm=not args.no_confirm)
    if args.utterances:
        out["utterances"] = score_utterances()
    text = json.dumps(out, indent=1)
    print(text)
    if args.json:
        Path(args.json).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
