"""``gesture-sim bench onset``: voice onset after a pause -> first visible stroke, and its parts.

Real speech (the repository's recordings, or the FILEs given), each after ``--pause`` seconds of
silence, one stream per seed, played through the pipeline with physics exactly as ``live
--audio`` plays it (the same control step; offline the tracker's per-frame work is prepared
ahead with the same results at the same times). At each reference voice onset after a pause of
at least ``--min-pause`` (found offline on the samples: :func:`gesture_sim.metrics.onset.
voice_onsets`) where the body is at rest, the latency to the body's first hand-speed peak is
split into its parts:

* ``detector``: onset -> the centre of the first 10 ms frame the speech state counts as speaking
  (the voice-activity detector's windows and the energy rule);
* ``emission``: that frame's centre -> when the tracker emits it (its batch's look-ahead);
* ``control_step``: emission -> the first control step that leaves rest (30 Hz steps);
* ``stroke_rise``: leaving rest -> the timing layer's stroke peak in the targets;
* ``pd_response``: the targets' stroke peak -> the body's first hand-speed peak (the PD
  control and the body's inertia; negative when the body's speed peaks before the targets'
  stroke mark).

The figure of issue 55 is the median of ``total`` over every onset and seed (goal 150 ms).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from gesture_sim.commands import print_json

#: The parts of the latency, in order (ms each; they sum to ``total``).
PARTS = ("detector", "emission", "control_step", "stroke_rise", "pd_response")


def _default_files() -> list[Path]:
    """The repository's real speech recordings (tests/data), where present."""
    root = Path(__file__).resolve().parents[3] / "tests" / "data"
    names = ("audio/jfk.wav", "audio/arctic_a0007.wav", "audio/beat2_scott_0_2_2_excerpt.wav",
             "eval/2_scott_0_1_1_first10s.wav", "inference/beat2_scott_0_3_3_first20s.wav")
    return [root / n for n in names if (root / n).is_file()]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("onset", help="voice onset after a pause -> first visible stroke (ms), "
                       "and its parts", description=__doc__.split("\n\n")[1])
    p.add_argument("files", nargs="*", metavar="FILE",
                   help="speech recordings (default: the repository's real speech files)")
    p.add_argument("--seeds", type=int, default=3, help="seeds 0 .. N-1 (default 3)")
    p.add_argument("--pause", type=float, default=2.0,
                   help="silence before each file (s; default 2)")
    p.add_argument("--min-pause", type=float, default=1.0,
                   help="an onset counts after at least this much silence (s; default 1)")
    p.add_argument("--onset-entry", type=float, default=None, metavar="S",
                   help="also run the timing layer entering the segment at most S s (at its "
                        "fastest rate) before its first stroke when it leaves rest "
                        "(SyncSettings.onset_entry_s), reported beside the defaults")
    p.add_argument("--onset-blend", type=float, default=None, metavar="S",
                   help="... with the ramp from rest over S s (SyncSettings.onset_blend_s)")
    p.add_argument("--onset-rate-at-once", action="store_true",
                   help="... with the playback rate leaving rest at once "
                        "(SyncSettings.onset_rate_at_once)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def _speaking_frames(pipe: Any) -> list[tuple[float, float, bool]]:
    """Record (frame centre t, t_known, speaking) of every frame the accent detector steps
    (an instance wrapper on its ``_step``; the bench's instrument, not the pipeline's)."""
    det = pipe.speech.detector
    rows: list[tuple[float, float, bool]] = []
    inner = det._step

    def step(t, i_db, f0, silent, t_known, acc, bnd):
        inner(t, i_db, f0, silent, t_known, acc, bnd)
        rows.append((float(t), float(t_known), bool(det.speaking)))

    det._step = step
    return rows


def measure(files: list[Path], seeds: int, pause_s: float, min_pause_s: float,
            sync: Any = None) -> dict[str, Any]:
    """Run the stream once per seed; the per-onset latencies (ms) and their medians.
    ``sync``: the timing layer's :class:`~gesture_sim.control.synchrony.SyncSettings`
    (None: the pipeline's own)."""
    import numpy as np

    from gesture_sim.audio.sources import load_audio
    from gesture_sim.feed import run_file
    from gesture_sim.metrics import motion as mm
    from gesture_sim.metrics.onset import first_at_or_after, voice_onsets
    from gesture_sim.metrics.points import EVAL_FPS, POINT_NAMES, PointFK, trace_positions
    from gesture_sim.pipeline import GesturePipeline

    sr = 16_000
    parts, names = [], []
    for f in files:
        x, _ = load_audio(f)
        parts += [np.zeros(int(round(pause_s * sr)), dtype=np.float32), x]
        names.append(Path(f).name)
    y = np.concatenate(parts)
    bounds = np.cumsum([0] + [len(p) for p in parts]) / sr
    onsets = voice_onsets(y, sr, min_pause_s=min_pause_s)
    fk = PointFK()
    hands = [POINT_NAMES.index("left_hand"), POINT_NAMES.index("right_hand")]
    rows: list[dict[str, Any]] = []
    skipped = 0
    for seed in range(seeds):
        pipe = GesturePipeline.create(seed=seed, sync=sync)
        frames = _speaking_frames(pipe)
        run_file(pipe, y=y, sr=sr)
        log = pipe.log
        steps = np.asarray(log.step_times)
        modes = np.asarray(log.modes)
        pos = trace_positions(pipe.trace(), fk)
        speed = mm.joint_speeds(pos, EVAL_FPS)[:, hands].mean(axis=1)
        peaks = mm.speed_peaks(speed, EVAL_FPS)
        fr = np.array([(t, tk) for t, tk, _ in frames])
        speaking = np.array([s for _, _, s in frames])
        for o in onsets:
            before = np.nonzero(steps < o - 1e-9)[0]
            if not len(before) or modes[before[-1]] != "rest":
                skipped += 1
                continue
            # the first frame counted as speaking from just before the onset on
            cand = np.nonzero((fr[:, 0] >= o - 0.1) & speaking)[0]
            leave = np.nonzero((steps >= o - 1e-9) & (modes != "rest"))[0]
            if not len(cand) or not len(leave):
                skipped += 1
                continue
            t_frame, t_known = fr[cand[0]]
            t_leave = float(steps[leave[0]])
            t_stroke = first_at_or_after(np.asarray(log.strokes), t_leave, 1.5)
            t_body = first_at_or_after(peaks, o, 1.5)
            if not (np.isfinite(t_stroke) and np.isfinite(t_body)):
                skipped += 1
                continue
            which = int(np.searchsorted(bounds, o, side="right") - 1) // 2
            ms = {"detector": t_frame - o, "emission": t_known - t_frame,
                  "control_step": t_leave - t_known, "stroke_rise": t_stroke - t_leave,
                  "pd_response": t_body - t_stroke, "total": t_body - o}
            rows.append({"seed": seed, "file": names[min(which, len(names) - 1)],
                         "onset_s": round(float(o), 3),
                         **{k: round(1e3 * float(v), 1) for k, v in ms.items()}})
    keys = (*PARTS, "total")
    med = {k: round(float(np.median([r[k] for r in rows])), 1) if rows else None for k in keys}
    per_seed = {}
    for seed in range(seeds):
        mine = [r["total"] for r in rows if r["seed"] == seed]
        per_seed[str(seed)] = round(float(np.median(mine)), 1) if mine else None
    return {"files": names, "pause_s": pause_s, "min_pause_s": min_pause_s, "seeds": seeds,
            "onsets": int(len(onsets)), "measured": len(rows), "skipped_not_at_rest": skipped,
            "median_ms": med, "total_median_by_seed_ms": per_seed,
            "total_mean_ms": round(float(np.mean([r["total"] for r in rows])), 1) if rows
            else None, "goal_ms": 150.0, "rows": rows}


def run(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v

    v.integer("--seeds", args.seeds, 1, 20)
    v.number("--pause", args.pause, 0.0, 30.0, lo_open=True, hint=" seconds")
    v.number("--min-pause", args.min_pause, 0.0, 30.0, lo_open=True, hint=" seconds")
    for f in args.files:
        v.input_file("FILE", f, "audio file")
    files = [Path(f) for f in args.files] or _default_files()
    if not files:
        from gesture_sim.errors import GestureSimError

        raise GestureSimError("no speech files: give FILE arguments")
    for name in ("onset_entry", "onset_blend"):
        if getattr(args, name) is not None:
            v.number("--" + name.replace("_", "-"), getattr(args, name), 0.0, 2.0,
                     hint=" seconds")
    variant = _variant(args)
    out = measure(files, args.seeds, args.pause, args.min_pause)
    if variant is not None:
        out = {"defaults": out, "variant": {
            "settings": {k: getattr(variant, k) for k in
                         ("onset_entry_s", "onset_blend_s", "onset_rate_at_once")},
            **measure(files, args.seeds, args.pause, args.min_pause, sync=variant)}}
    if args.json:
        print_json(out)
        return 0
    if variant is not None:
        for name in ("defaults", "variant"):
            print(f"{name}:")
            _print(out[name])
        return 0
    _print(out)
    return 0


def _variant(args: argparse.Namespace) -> Any:
    """The timing layer's settings with the onset options given (None: none given)."""
    if args.onset_entry is None and args.onset_blend is None and not args.onset_rate_at_once:
        return None
    from gesture_sim.control.ramp import DEFAULT_BLEND_FRAMES
    from gesture_sim.control.synchrony import SyncSettings

    # the pipeline's own settings (methods._player: blend_s from its 15-step ramp at 30 Hz)
    return SyncSettings(blend_s=DEFAULT_BLEND_FRAMES / 30.0, onset_entry_s=args.onset_entry,
                        onset_blend_s=args.onset_blend,
                        onset_rate_at_once=bool(args.onset_rate_at_once))


def _print(out: dict[str, Any]) -> None:
    med = out["median_ms"]
    print(f"voice onset after a pause -> first visible stroke: {out['measured']} onsets "
          f"({out['onsets']} per seed, {out['skipped_not_at_rest']} skipped: not at rest), "
          f"{out['seeds']} seeds, {len(out['files'])} files")
    for k in (*PARTS, "total"):
        print(f"  {k:<13} {med[k]:>7.1f} ms (median)")
    print(f"  total by seed: {out['total_median_by_seed_ms']}; goal {out['goal_ms']:.0f} ms")
