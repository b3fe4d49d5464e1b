#!/usr/bin/env python3
"""A text-to-speech voice known ahead, planned vs causal (issue 51): espeak-ng says a few
sentences; the project's aligner (PocketSphinx) gives their timed words and phones, as a TTS
engine would hand them over before playback; the planned method gets them through
``GesturePipeline.expect_speech`` and the causal controller hears the audio only.

    PYTHONPATH=. .venv/bin/python tools/planned_tts.py [--seeds 3] [--json OUT.json]

Per method and seed, kinematic (the targets' own strokes, the timing layer's stroke log):
voice onset -> first stroke (s, over each phrase after a pause of 0.6 s or more), and the
stroke-to-stress error: for each stressed syllable (the first vowel of each content word,
:func:`gesture_sim.audio.known.stress_from_words`), the distance (s) to the nearest stroke
(median, and the share within 0.2 s), with the same share for the strokes shifted in time
(chance).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SENTENCES = (
    "I would like to tell you about the small town where I grew up.",
    "It was a wonderful place, full of music and stories.",
    "Everybody knew everybody else by name, and nobody ever locked a door.",
    "On summer evenings we walked down to the river and watched the boats.",
)


def _voice():
    from gesture_sim.audio.phones import align_transcript
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.testing.dialogue import say

    parts, words, phones, t = [np.zeros(int(0.5 * SAMPLE_RATE), np.float32)], [], [], 0.5
    for s in SENTENCES:
        x = say(s) * 0.5
        tr = align_transcript(x, SAMPLE_RATE, s)
        words += [(t + w.start_s, t + w.end_s, w.text) for w in tr.words]
        phones += [(t + p.start_s, t + p.end_s, p.label) for p in tr.phones if p.label != "SIL"]
        parts += [x, np.zeros(int(0.9 * SAMPLE_RATE), np.float32)]
        t += (len(x) + len(parts[-1])) / SAMPLE_RATE
    return np.concatenate(parts), words, phones


def _figures(strokes: np.ndarray, stress: np.ndarray, onsets: list[float], dur: float) -> dict:
    strokes = np.sort(strokes)
    err = np.abs(stress[:, None] - strokes[None, :]).min(axis=1) if strokes.size else \
        np.full(len(stress), np.inf)
    shifts = np.linspace(1.0, dur - 1.0, 50)
    chance = np.mean([np.mean(np.abs(stress[:, None] - ((strokes + d) % dur)[None, :])
                              .min(axis=1) <= 0.2) for d in shifts])
    first = [float(strokes[strokes >= on - 0.3][0] - on) for on in onsets
             if np.any(strokes >= on - 0.3)]
    return {"onset_to_first_stroke_s": float(np.median(first)),
            "onset_to_first_stroke_each_s": first,
            "stress_error_median_s": float(np.median(err)),
            "stress_within_0.2": float(np.mean(err <= 0.2)),
            "stress_within_0.2_chance": float(chance),
            "strokes_per_s": float(len(strokes) / dur)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--write", type=Path, default=None, metavar="DIR",
                    help="also write the voice (tts.wav) and its timed words (tts_words.txt, "
                         "'start end word' lines) for render --transcript")
    args = ap.parse_args(argv)

    from gesture_sim.audio.known import stress_from_words
    from gesture_sim.audio.sources import iter_blocks
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.loading import load_stack
    from gesture_sim.pipeline import GesturePipeline

    y, words, phones = _voice()
    dur = len(y) / SAMPLE_RATE
    if args.write is not None:
        from gesture_sim.testing.dialogue import _write_wav as write_wav

        args.write.mkdir(parents=True, exist_ok=True)
        write_wav(args.write / "tts.wav", y[:, None])
        (args.write / "tts_words.txt").write_text(
            "".join(f"{a:.3f} {b:.3f} {w}\n" for a, b, w in words))
    stress = stress_from_words(words, phones)
    onsets = [words[0][0]] + [b[0] for a, b in zip(words[:-1], words[1:], strict=True)
                              if b[0] - a[1] >= 0.6]
    stack = load_stack(None, None, policy=True)
    out: dict = {"duration_s": dur, "n_stress": int(len(stress)), "runs": {}}
    for method in ("planned", "controller"):
        for seed in range(args.seeds):
            pipe = GesturePipeline(stack.library, stack.model, stack.policy, method=method,
                                   seed=seed, physics=False,
                                   control_library=stack.control_library)
            pipe.reset()
            if method == "planned":
                pipe.expect_speech(y, words=words, phones=phones)
            for block in iter_blocks(y, 160):
                pipe.push_audio(block)
            pipe.finish()
            f = _figures(np.asarray(pipe.player.log.strokes), stress, onsets, dur)
            if method == "planned":
                f["planning_s"] = pipe.costs["planning"].seconds
                f.update(pipe.motion.timing)
            out["runs"][f"{method}/{seed}"] = f
            print(method, seed, {k: v for k, v in f.items() if not k.endswith("each_s")},
                  flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
