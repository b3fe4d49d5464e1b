"""Frame accuracy of the prosody tracker's speech / not-speech decision, per voice-activity engine.

Truth: a 10 ms frame is speech when it lies inside a word interval of the take's TextGrid
(``words`` tier). Each take is scored clean and in noise mixtures, each with ``--lead`` seconds
of the same noise *before* the take (the case where a relative silence rule has nothing to be
relative to) and a faint click in that lead:

* ``room@L``: room tone taken from the take's own pauses (the frames outside words, looped),
  brought to L dBFS RMS (``--levels``: −30, −45, −60);
* ``line@L``: line noise — white noise band-passed to 300–3400 Hz plus 60 Hz mains hum with its
  harmonics — at L dBFS;
* ``room/snrS``, ``line/snrS``: the same noises at S dB below the take's active speech RMS
  (``--snrs``: 20, 10).

Per engine (``off`` = the energy rule alone, ``silero``, ``webrtc`` when installed) it prints the
frame accuracy, speech recall (word frames not silent), the false-speech share of the non-word
frames, the non-silent share of the lead, syllables emitted in the lead, and the onset delay
against the energy rule on the clean take (median over pause→speech onsets of the first
non-silent frame, ms).

    .venv/bin/python tools/vad_accuracy.py DATA/2_scott_0_{1_1,2_2,3_3,4_4}.wav \
        --textgrid-dir DATA/textgrids [--engines off silero webrtc] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gesture_sim.audio.prosody import ProsodyConfig, analyze_samples  # noqa: E402
from gesture_sim.audio.sources import load_audio  # noqa: E402
from gesture_sim.audio.vad import VadConfig  # noqa: E402
from gesture_sim.contracts import SAMPLE_RATE  # noqa: E402
from gesture_sim.testing.noise import (  # noqa: E402
    at_level,
    click,
    hum,
    line_noise,
    rms_db,
    room_tone,
    word_frames,
)

SR = SAMPLE_RATE


def onsets(nonsilent: np.ndarray) -> np.ndarray:
    """Frame indices where a run of at least 20 silent frames gives way to speech."""
    idx = []
    run = 0
    for k, v in enumerate(nonsilent):
        if not v:
            run += 1
        else:
            if run >= 20:
                idx.append(k)
            run = 0
    return np.array(idx, int)


def score(x: np.ndarray, truth: np.ndarray, lead_frames: int, cfg: ProsodyConfig) -> dict:
    a = analyze_samples(x.astype(np.float32), config=cfg)
    ns = ~a.frames.silent[: len(truth)]
    truth = truth[: len(ns)]
    lead_end_s = lead_frames * 0.01
    return {
        "accuracy": float(np.mean(ns == truth)),
        "recall": float(ns[truth].mean()),
        "false_speech": float(ns[~truth].mean()),
        "lead_nonsilent": float(ns[:lead_frames].mean()) if lead_frames else 0.0,
        "lead_syllables": int(sum(s.t_start < lead_end_s for s in a.syllables)),
        "_nonsilent": ns,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("wavs", nargs="+", type=Path)
    ap.add_argument("--textgrid-dir", type=Path, required=True)
    ap.add_argument("--engines", nargs="+", default=["off", "silero", "webrtc"])
    ap.add_argument("--levels", type=float, nargs="+", default=[-30.0, -45.0, -60.0])
    ap.add_argument("--snrs", type=float, nargs="+", default=[20.0, 10.0])
    ap.add_argument("--lead", type=float, default=6.0, help="seconds of noise before the take")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()

    rows = []
    for wav in args.wavs:
        x, _ = load_audio(wav)
        x = x.astype(np.float64)
        tg = args.textgrid_dir / (wav.stem + ".TextGrid")
        n_frames = -(-len(x) // (SR // 100))
        words = word_frames(tg, n_frames)
        speech_db = rms_db(x[np.repeat(words, SR // 100)[: len(x)]])
        rng = np.random.default_rng(args.seed)
        lead = int(args.lead * SR)
        n = lead + len(x)
        room, line = room_tone(x, words, n), line_noise(n, rng) + 0.5 * hum(n)
        conds: list[tuple[str, np.ndarray | None]] = [("clean", None)]
        for lv in args.levels:
            conds += [(f"room@{lv:g}", at_level(room, lv)), (f"line@{lv:g}", at_level(line, lv))]
        for snr in args.snrs:
            conds += [(f"room/snr{snr:g}", at_level(room, speech_db - snr)),
                      (f"line/snr{snr:g}", at_level(line, speech_db - snr))]
        clean_off = None
        for name, noise in conds:
            if noise is None:
                y, lead_frames, offset = x, 0, 0.0
            else:
                y = np.concatenate([np.zeros(lead), x]) + noise + click(n, int(lead * 0.4))
                lead_frames, offset = int(args.lead * 100), args.lead
            truth = word_frames(tg, -(-len(y) // (SR // 100)), offset)
            for eng in args.engines:
                cfg = replace(ProsodyConfig(), vad=VadConfig(engine=eng))
                try:
                    r = score(y, truth, lead_frames, cfg)
                except Exception as exc:  # noqa: BLE001 - an engine not installed
                    print(f"{eng}: {exc}", file=sys.stderr)
                    continue
                ns = r.pop("_nonsilent")
                if name == "clean":
                    if eng == "off":
                        clean_off = ns
                        r["onset_delay_ms"] = 0.0
                    else:
                        ref = onsets(clean_off)
                        mine = onsets(ns)
                        d = [int(mine[mine >= k][0] - k) * 10 for k in ref
                             if (mine >= k).any() and mine[mine >= k][0] - k < 30]
                        r["onset_delay_ms"] = float(np.median(d)) if d else float("nan")
                rows.append({"take": wav.stem, "condition": name, "engine": eng, **r})
                print(f"{wav.stem:16} {name:13} {eng:7} acc {r['accuracy']:.3f} "
                      f"recall {r['recall']:.3f} false {r['false_speech']:.3f} "
                      f"lead {r['lead_nonsilent']:.3f} lead_syl {r['lead_syllables']:3d}"
                      + (f" onset +{r['onset_delay_ms']:.0f} ms" if "onset_delay_ms" in r
                         else ""), flush=True)
    # summary: mean over takes per (condition, engine)
    print("\nmean over takes")
    keys = sorted({(r["condition"], r["engine"]) for r in rows},
                  key=lambda k: ([r["condition"] for r in rows].index(k[0]), k[1]))
    summary = []
    for cond, eng in keys:
        sel = [r for r in rows if r["condition"] == cond and r["engine"] == eng]
        m = {f: float(np.mean([r[f] for r in sel]))
             for f in ("accuracy", "recall", "false_speech", "lead_nonsilent", "lead_syllables")}
        summary.append({"condition": cond, "engine": eng, **m})
        print(f"{cond:13} {eng:7} acc {m['accuracy']:.3f} recall {m['recall']:.3f} "
              f"false {m['false_speech']:.3f} lead {m['lead_nonsilent']:.3f} "
              f"lead_syl {m['lead_syllables']:.1f}")
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, "summary": summary}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
