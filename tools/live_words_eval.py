"""Live word recognition (gesture_sim.audio.live_words) against TextGrid word tiers.

For each ``WAV TEXTGRID`` pair and each setting (``--config``, repeatable; default: the
settings compared in the report), the recording is fed through
:func:`gesture_sim.audio.live_words.recognise_words` in 10 ms blocks (the streaming code,
deterministic) and scored:

* word error rate: Levenshtein distance (substitutions, deletions, insertions) between the
  TextGrid's word tier (lower case; empty intervals and silence marks such as ``sil``, ``sp``,
  ``<sil>`` left out) and the recognised words, summed over the takes / reference words;
* latency: ``t_emitted - end_s`` of every recognised word (median, 90th percentile, max, ms),
  and the same against the end of the reference word each correct word is paired with on the
  edit path (``ref_*``);
* real-time factor: the worker's thread CPU time per second of audio (``rtf_cpu``), and wall
  time per second (``rtf_wall``) on this machine.

A setting is ``key=value`` pairs of :class:`~gesture_sim.audio.live_words.LiveWordsSettings`
separated by commas (``emit=stable,stable_s=0.2``; ``hangover_s=`` sets the detector's), with
an optional ``name:`` in front.

Usage::

    .venv/bin/python tools/live_words_eval.py A.wav A.TextGrid [B.wav B.TextGrid ...]
        [--config NAME:emit=stable,stable_s=0.2 ...] [--seconds S] [--json OUT.json]
        [--jobs N]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
import shlex
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gesture_sim.audio.keywords import read_word_list  # noqa: E402
from gesture_sim.audio.live_words import (  # noqa: E402
    LiveWordsSettings,
    LiveWordsStats,
    recognise_words,
)
from gesture_sim.audio.sources import load_audio  # noqa: E402
from gesture_sim.audio.vad import VadConfig  # noqa: E402
from gesture_sim.metrics.alignment import edit_ops  # noqa: E402

#: The settings compared by default (name: key=value,...).
DEFAULT_CONFIGS = (
    "stable-0.1:emit=stable,stable_s=0.1",
    "stable-0.2:emit=stable,stable_s=0.2",
    "stable-0.3:emit=stable,stable_s=0.3",
    "utterance:emit=utterance",
    "utterance-3s:emit=utterance,max_utterance_s=3",
    "stable-0.2-beam1e-60:emit=stable,stable_s=0.2,beam=1e-60,wbeam=1e-40",
)
_SILENCE = {"", "sil", "sp", "spn", "<sil>", "<s>", "</s>", "#", "{sl}", "{lg}"}


def norm_words(words: list[str]) -> list[str]:
    """Lower case, punctuation other than apostrophes dropped, silence marks left out."""
    out = []
    for w in words:
        w = w.strip().lower()
        if w in _SILENCE or (w.startswith(("<", "[")) and w.endswith((">", "]"))):
            continue
        w = re.sub(r"[^a-z0-9']+", " ", w.replace("\u2019", "'"))
        out.extend(t for t in w.split() if t not in _SILENCE)
    return out


def parse_config(text: str) -> tuple[str, LiveWordsSettings]:
    name, _, body = text.rpartition(":") if ":" in text else ("", "", text)
    kw: dict[str, object] = {}
    vad: dict[str, object] = {}
    types = {f.name: f.type for f in dataclasses.fields(LiveWordsSettings)}
    for item in filter(None, body.split(",")):
        k, _, v = item.partition("=")
        k = k.strip()
        if k in ("hangover_s", "engine", "onset", "offset"):
            vad[k] = v if k == "engine" else float(v)
        elif k == "emit":
            kw[k] = v
        elif k in types:
            kw[k] = float(v)
        else:
            raise SystemExit(f"unknown setting {k!r} in {text!r}")
    if vad:
        kw["vad"] = VadConfig(**{"hangover_s": 0.25, **vad})
    return name or body, LiveWordsSettings(**kw)


def run_one(args: tuple[str, str, str, float | None]) -> dict:
    cfg_text, wav, grid, seconds = args
    name, settings = parse_config(cfg_text)
    x, _ = load_audio(wav)
    ref_t = read_word_list(grid)
    if seconds is not None:
        x = x[: int(seconds * 16000)]
        ref_t = [w for w in ref_t if w[1] <= seconds]
    ref_items = [(a, b, t) for a, b, w in ref_t for t in norm_words([w])]
    ref = [t for _, _, t in ref_items]
    stats = LiveWordsStats()
    w0 = time.perf_counter()
    got = recognise_words(x, settings, stats=stats)
    wall = time.perf_counter() - w0
    hyp_items = [(w, t) for w in got for t in norm_words([w.text])]
    hyp = [t for _, t in hyp_items]
    dist, pairs = edit_ops(ref, hyp)
    lat = [w.t_emitted - w.end_s for w, _ in hyp_items]
    ref_lat = [hyp_items[j][0].t_emitted - ref_items[i][1] for i, j in pairs]
    return {"config": name, "take": Path(wav).stem, "duration_s": len(x) / 16000,
            "ref_words": len(ref), "hyp_words": len(hyp), "errors": dist,
            "latency_s": lat, "ref_latency_s": ref_lat, "cpu_s": stats.cpu_s, "wall_s": wall,
            "utterances": stats.utterances, "hyp": " ".join(hyp)}


def summarise(rows: list[dict]) -> dict:
    lat = np.asarray([v for r in rows for v in r["latency_s"]] or [np.nan])
    rlat = np.asarray([v for r in rows for v in r["ref_latency_s"]] or [np.nan])
    dur = sum(r["duration_s"] for r in rows)
    return {"wer": sum(r["errors"] for r in rows) / max(sum(r["ref_words"] for r in rows), 1),
            "ref_words": sum(r["ref_words"] for r in rows),
            "hyp_words": sum(r["hyp_words"] for r in rows),
            "lat_med_ms": 1000 * float(np.median(lat)),
            "lat_p90_ms": 1000 * float(np.percentile(lat, 90)),
            "lat_max_ms": 1000 * float(np.max(lat)),
            "ref_lat_med_ms": 1000 * float(np.median(rlat)),
            "ref_lat_p90_ms": 1000 * float(np.percentile(rlat, 90)),
            "rtf_cpu": sum(r["cpu_s"] for r in rows) / dur,
            "rtf_wall": sum(r["wall_s"] for r in rows) / dur,
            "utterances": sum(r["utterances"] for r in rows), "audio_s": dur}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pairs", nargs="+", help="WAV TEXTGRID [WAV TEXTGRID ...]")
    ap.add_argument("--config", action="append", default=None,
                    help="[NAME:]key=value,... (repeatable; default: the compared settings)")
    ap.add_argument("--seconds", type=float, default=None, help="only the first S s of each")
    ap.add_argument("--json", type=Path, default=None, help="write every figure here")
    ap.add_argument("--jobs", type=int, default=1, help="processes (default 1)")
    a = ap.parse_args(argv)
    if len(a.pairs) % 2:
        ap.error("give WAV TEXTGRID pairs")
    pairs = list(zip(a.pairs[0::2], a.pairs[1::2], strict=True))
    configs = a.config or list(DEFAULT_CONFIGS)
    for c in configs:
        parse_config(c)
    jobs = [(c, w, g, a.seconds) for c in configs for w, g in pairs]
    if a.jobs > 1:
        with ProcessPoolExecutor(a.jobs) as ex:
            rows = list(ex.map(run_one, jobs))
    else:
        rows = [run_one(j) for j in jobs]
    names = [parse_config(c)[0] for c in configs]
    table = {n: summarise([r for r in rows if r["config"] == n]) for n in names}
    print("command: " + " ".join(shlex.quote(s) for s in [".venv/bin/python",
                                                          "tools/live_words_eval.py",
                                                          *(sys.argv[1:] if argv is None
                                                            else argv)]))
    first = next(iter(table.values()))
    print(f"\n{len(pairs)} take(s), {first['audio_s']:.1f} s of audio, "
          f"{first['ref_words']} reference words\n")
    print("| setting | WER | words out | latency median (ms) | p90 (ms) | max (ms) "
          "| vs ref end median / p90 (ms) | RTF (CPU) | RTF (wall) | utterances |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, s in table.items():
        print(f"| {n} | {s['wer']:.3f} | {s['hyp_words']} | {s['lat_med_ms']:.0f} | "
              f"{s['lat_p90_ms']:.0f} | {s['lat_max_ms']:.0f} | {s['ref_lat_med_ms']:.0f} / "
              f"{s['ref_lat_p90_ms']:.0f} | {s['rtf_cpu']:.3f} | {s['rtf_wall']:.3f} | "
              f"{s['utterances']} |")
    if a.json is not None:
        a.json.write_text(json.dumps({"summary": table, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
