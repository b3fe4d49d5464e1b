#!/usr/bin/env python3
"""The face's figures on real speech: lip sync per phone source, and the head's nod rate
against a real speaker's motion capture (issue 30's acceptance figures).

For each take (``NAME.wav`` with ``NAME.TextGrid``, words and phones tiers) and each phone
source the pipeline runs with physics (controller, seed 0) and the simulated lips are judged
against the TextGrid's phones:

* ``textgrid``: the TextGrid's own phones;
* ``aligned``: the TextGrid's word sequence as a transcript, force-aligned to the audio by
  PocketSphinx (:func:`gesture_sim.audio.phones.align_transcript`);
* ``recognised``: phones from the audio alone (:class:`gesture_sim.audio.phones.PhoneRecogniser`,
  the whole file, used as known in advance: the recogniser's own latency is reported by
  ``tools/phone_sources.py``);
* ``loudness``: no phones (the degraded mode: the jaw opens with the loudness).

Figures: the share of the TextGrid's /p b m/ segments during which the simulated lips close
(the lip gap, from the jaw, lip and tuck joints, reaches ``CLOSED_MM``), the share of its open
vowels (/aa ae ah ao aw ay/) during which the mouth opens by ``OPEN_MM``, and the head's nods a
minute (:func:`gesture_sim.metrics.face.nod_times`), RUTH's nod batons and brow raises a
minute, and the accent-to-head-speed-peak lag. With ``--smplx`` the real take's nod rate by the
same detector is printed beside them.

Usage::

    .venv/bin/python tools/face_figures.py --takes DIR [--names 2_scott_0_1_1 ...] \\
        [--sources textgrid aligned recognised loudness] [--smplx TAKE.npz] [--json OUT]

``DIR`` holds ``NAME.wav`` and ``textgrids/NAME.TextGrid`` (BEAT2's layout).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from gesture_sim.signals.face_rig import LIP_RADIUS_M  # noqa: E402

SOURCES = ("textgrid", "aligned", "recognised", "loudness")
CLOSED_MM = 1.5
OPEN_MM = 5.0
BILABIAL = {"P", "B", "M"}
OPEN_VOWELS = {"AA", "AE", "AH", "AO", "AW", "AY"}


def lip_gap_m(q: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """The lips' vertical gap (m) from the simulated joints: the jaw opens it by
    ``LIP_RADIUS_M * sin(jaw)``, the lower lip's raise and the upper lip's lowering close it."""
    col = {n: i for i, n in enumerate(names)}
    jaw = q[:, col["jaw_open"]]
    return (LIP_RADIUS_M * np.sin(jaw) - q[:, col["lower_lip_raise"]]
            + q[:, col["upper_lip_raise"]])


def share_during(t: np.ndarray, ok: np.ndarray, spans: list[tuple[float, float]]) -> float:
    """The share of ``spans`` during which ``ok`` holds at some step."""
    hits = [bool(ok[(t >= a) & (t <= b)].any()) for a, b in spans]
    return float(np.mean(hits)) if hits else float("nan")


def phones_for(source: str, wav: Path, grid: Path, samples: np.ndarray):
    from gesture_sim.audio.phones import (
        PhoneRecogniser,
        align_transcript,
        phones_from_textgrid,
        words_from_textgrid,
    )

    if source == "textgrid":
        return phones_from_textgrid(grid)
    if source == "aligned":
        text = " ".join(w.text for w in words_from_textgrid(grid))
        return list(align_transcript(samples, 16000, text).phones)
    if source == "recognised":
        rec = PhoneRecogniser()
        out = [e.phone for e in rec.push(samples)] + [e.phone for e in rec.finish()]
        return out
    return None


def run_take(name: str, wav: Path, grid: Path, source: str) -> dict:
    from gesture_sim.audio.phones import phones_from_textgrid
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.feed import run_file
    from gesture_sim.metrics.face import trace_figures
    from gesture_sim.pipeline import GesturePipeline
    from gesture_sim.sim import humanoid as hm

    y = load_audio(wav)
    samples = np.asarray(y[0] if isinstance(y, tuple) else y, dtype=float)
    t0 = time.perf_counter()
    phones = phones_for(source, wav, grid, samples)
    t_phones = time.perf_counter() - t0
    pipe = GesturePipeline.create(seed=0, phones=phones)
    res = run_file(pipe, y=samples, sr=16000)
    tr = pipe.trace()
    t = tr.time - tr.time[0]
    gap = lip_gap_m(tr.q, hm.ACTUATED_JOINTS)
    ref = phones_from_textgrid(grid)
    acc = [a.t for a in pipe.log.accents]
    face = trace_figures(tr, pipe.sim.model, pipe.log.signals, acc, res.duration)
    return {
        "take": name, "source": source, "seconds": round(res.duration, 2),
        "phones": None if phones is None else len(phones), "phones_s": round(t_phones, 2),
        "bilabial_closed_share": share_during(
            t, gap <= CLOSED_MM / 1e3, [(p.start_s, p.end_s) for p in ref if p.label in BILABIAL]),
        "open_vowel_open_share": share_during(
            t, gap >= OPEN_MM / 1e3, [(p.start_s, p.end_s) for p in ref if p.label in OPEN_VOWELS]),
        "head_nods_per_min": round(face["head_nods_per_min"], 1),
        "nod_batons_per_min": round(face["nods_per_min"], 1),
        "brow_raises_per_min": round(face["brow_raises_per_min"], 1),
        "accent_to_head_peak_median_s": face["accent_to_head_peak_s"]["median"],
    }


def real_head_coupling(poses: np.ndarray, fps: float, wav: Path) -> dict:
    """The eval's head-peak coupling (``metrics.inputs.head_timing``) of a real take: its
    SMPL-X head's angular speed relative to the chest against the accents the detector finds
    in its audio, and the same with the accents shifted by 2-20 s (chance, 20 shifts)."""
    from scipy.spatial.transform import Rotation

    from gesture_sim.audio.sources import load_audio
    from gesture_sim.audio.speech import SpeechState
    from gesture_sim.contracts import AudioBlock
    from gesture_sim.metrics.inputs import head_timing
    from gesture_sim.motion.smplx import SMPLX_JOINTS

    n, h = SMPLX_JOINTS.index("neck"), SMPLX_JOINTS.index("head")
    rel = Rotation.from_rotvec(poses[:, 3 * n: 3 * n + 3]) * \
        Rotation.from_rotvec(poses[:, 3 * h: 3 * h + 3])
    speed = (rel[:-1].inv() * rel[1:]).magnitude() * fps
    t = (np.arange(len(speed)) + 0.5) / fps
    y = load_audio(wav)
    x = np.asarray(y[0] if isinstance(y, tuple) else y, dtype=np.float32)
    speech = SpeechState()
    acc = []
    for i in range(0, len(x), 160):
        new = speech.push(AudioBlock(samples=x[i:i + 160], t_start=i / 16000))
        acc += [a.t for a in new.accents]
    acc = np.array(acc + [a.t for a in speech.flush().accents])
    real = head_timing(acc, t, speed, float(t[-1]))
    rng = np.random.default_rng(0)
    chance = [head_timing(np.sort((acc + s) % t[-1]), t, speed, float(t[-1]))["head_accent_hits"]
              for s in rng.uniform(2.0, 20.0, 20)]
    return {"head_accent_hits": round(real["head_accent_hits"], 3),
            "head_accent_hits_chance": round(float(np.mean(chance)), 3),
            "head_accent_hits_chance_sd": round(float(np.std(chance)), 3),
            "head_peaks_per_s": round(real["head_peaks_per_s"], 2)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--takes", type=Path, required=True,
                    help="folder with NAME.wav and textgrids/NAME.TextGrid")
    ap.add_argument("--names", nargs="+", default=None, help="takes (default: every TextGrid)")
    ap.add_argument("--sources", nargs="+", choices=SOURCES, default=list(SOURCES))
    ap.add_argument("--smplx", type=Path, default=None,
                    help="a take's SMPL-X npz: its real nod rate by the same detector")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = ap.parse_args(argv)
    names = args.names or sorted(p.stem for p in (args.takes / "textgrids").glob("*.TextGrid"))
    rows = []
    for name in names:
        for source in args.sources:
            row = run_take(name, args.takes / f"{name}.wav",
                           args.takes / "textgrids" / f"{name}.TextGrid", source)
            rows.append(row)
            print(json.dumps(row), flush=True)
    out = {"rows": rows}
    if args.smplx is not None:
        from gesture_sim.metrics.face import nod_times, smplx_head_pitch

        z = np.load(args.smplx)
        fps = float(z["mocap_frame_rate"])
        pitch = smplx_head_pitch(z["poses"])
        t = np.arange(len(pitch)) / fps
        out["real"] = {"take": args.smplx.stem, "head_nods_per_min": round(
            len(nod_times(t, pitch)) / (t[-1] / 60.0), 1)}
        wav = args.smplx.with_suffix(".wav")
        if wav.is_file():
            out["real"].update(real_head_coupling(z["poses"], fps, wav))
        print(json.dumps(out["real"]))
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
