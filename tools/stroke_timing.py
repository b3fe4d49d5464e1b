#!/usr/bin/env python3
"""Measure the real motion's timing on a take with its motion capture (issue 51, step 1).

    PYTHONPATH=. .venv/bin/python tools/stroke_timing.py TAKE.wav TAKE.npz TAKE.TextGrid \\
        [--json OUT.json]

Prints, as JSON: the signed time from each stressed vowel centre (the TextGrid's primary-stress
ARPAbet vowels) and each accent (the project's accent detector over the file) to the nearest
hand-speed peak of the take's own motion (> 0: the stroke apex comes after), with the quantiles
of those offsets; the stroke phases (dip -> peak, peak -> dip), the holds during speech and the
apex speeds (:mod:`gesture_sim.metrics.stroke_timing`). The planner's lead and the nudge's
bounds (:mod:`gesture_sim.control.planner`) come from these figures.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("audio", type=Path)
    ap.add_argument("motion", type=Path)
    ap.add_argument("textgrid", type=Path)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    from gesture_sim.app.evaluation import EVAL_FPS, Evaluator
    from gesture_sim.audio.accents import analyze_accents
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.audio.textgrid import read_textgrid, stressed_vowels
    from gesture_sim.metrics import motion as mm
    from gesture_sim.metrics.points import HAND_POINTS, POINT_NAMES
    from gesture_sim.metrics.stroke_timing import _quantiles, stroke_offsets, stroke_phases

    ev = Evaluator(physics=False)
    q = ev.retarget_reference(args.motion)
    pos = ev.fk.standing(q)
    hands = [POINT_NAMES.index(j) for j in HAND_POINTS]
    speed = mm.joint_speeds(pos, EVAL_FPS)[:, hands].mean(axis=1)
    peaks = mm.speed_peaks(speed, EVAL_FPS)
    samples, _ = load_audio(args.audio)
    an = analyze_accents(samples)
    accents = np.array([a.t for a in an.accents])
    stress = np.array([(a + b) / 2 for a, b in stressed_vowels(read_textgrid(args.textgrid))])
    # speaking per motion frame, from the detector's per-frame voice activity
    t_m = np.arange(len(speed)) / EVAL_FPS
    speaking = np.interp(t_m, an.times, an.speaking.astype(float)) > 0.5
    out = {
        "duration_s": len(speed) / EVAL_FPS,
        "n_peaks": int(len(peaks)),
        "stress_per_s": float(len(stress) / (len(speed) / EVAL_FPS)),
        "accents_per_s": float(len(accents) / (len(speed) / EVAL_FPS)),
        "stress_to_peak_s": _quantiles(stroke_offsets(stress, peaks, 0.3)),
        "accent_to_peak_s": _quantiles(stroke_offsets(accents, peaks, 0.3)),
        "phases": stroke_phases(speed, EVAL_FPS, speaking=speaking).summary(),
    }
    text = json.dumps(out, indent=1)
    print(text)
    if args.json is not None:
        args.json.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
