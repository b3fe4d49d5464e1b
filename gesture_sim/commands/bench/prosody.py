"""``gesture-sim bench prosody``: real-time factor and latency of the causal prosody tracker.

Feeds each WAV through :class:`~gesture_sim.audio.prosody.ProsodyTracker` in 10 ms blocks, on
one core, after one warm-up run, two ways in the same run: as a live microphone (nothing known
ahead) and as a file (the whole audio known ahead: :meth:`ProsodyTracker.expect`, each frame
analysed once; the same frames and syllables). Reports the real-time factor of each (audio
seconds per compute second, best of ``--repeat`` runs; file decoding excluded), the file's cost
as a share of the live one's, and the prosody latency ``t_emitted - t_end`` of every syllable
(median and 95th percentile, pooled; the same either way).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from gesture_sim import REPO_DIR
from gesture_sim.commands import print_json

#: Shipped fixtures the benchmark uses by default (relative to the repository root).
DEFAULT_DIR = REPO_DIR / "tests" / "data" / "audio"


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "prosody", help="prosody tracker speed (x real time, one core) and latency",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    parser.add_argument("files", nargs="*", metavar="WAV",
                        help=f"audio files (default: the WAVs in {DEFAULT_DIR})")
    parser.add_argument("--block-size", type=int, default=160, metavar="N",
                        help="samples per pushed block (default 160 = 10 ms)")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per file (best kept)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=run)


def _one_core() -> set[int] | None:
    """Pin this process to one CPU where the OS allows it (Linux); return the old set."""
    try:
        old = set(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {min(old)})
        return old
    except (AttributeError, OSError):
        return None


def run(args: argparse.Namespace) -> int:
    from gesture_sim.errors import GestureSimError

    files = [Path(f) for f in args.files] or sorted(DEFAULT_DIR.glob("*.wav"))
    if not files:
        raise GestureSimError(f"no WAV files given and none found in {DEFAULT_DIR}")
    old_affinity = _one_core()
    try:
        summary = _measure(files, args.block_size, args.repeat)
    finally:
        if old_affinity:
            os.sched_setaffinity(0, old_affinity)
    if args.json:
        print_json(summary)
        return 0
    rows = summary["per_file"]
    print(f"{'file':<34}{'dur s':>7}{'x RT live':>10}{'x RT file':>10}{'syl':>6}"
          f"{'lat med ms':>12}{'lat p95 ms':>12}")
    for r in rows:
        print(f"{r['file']:<34}{r['duration_s']:>7.2f}{r['rtf']:>10.1f}{r['rtf_file']:>10.1f}"
              f"{r['syllables']:>6}{r['latency_median_ms']!s:>12}{r['latency_p95_ms']!s:>12}")
    print(f"\nreal-time factor (one core, {args.block_size}-sample blocks): live "
          f"{summary['realtime_factor']:.1f}x, file {summary['realtime_factor_file']:.1f}x "
          f"(the file costs {summary['file_to_live_cost']:.2f} of live)")
    print(f"latency (syllable end -> emission): median {summary['latency_median_ms']} ms, "
          f"p95 {summary['latency_p95_ms']} ms, max {summary['latency_max_ms']} ms "
          f"over {summary['syllables']} syllables")
    return 0


def _measure(files: list[Path], block_size: int, repeat: int) -> dict:
    """Time the tracker on each file; pooled latency statistics."""
    import time

    import numpy as np

    from gesture_sim.audio.prosody import analyze_samples
    from gesture_sim.audio.sources import load_audio
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.progress import progress

    rows, latencies = [], []
    total_audio = total_live = total_file = 0.0
    for path in progress(files, desc="bench prosody", unit="file"):
        x, _ = load_audio(path)
        dur = len(x) / SAMPLE_RATE
        for ahead in (False, True):
            analyze_samples(x[:SAMPLE_RATE], block_size, ahead=ahead)  # warm-up (imports)
        best = {False: float("inf"), True: float("inf")}
        result = None
        for _ in range(max(1, repeat)):
            for ahead in (False, True):                # alternating: the same minutes
                t0 = time.perf_counter()
                result = analyze_samples(x, block_size, ahead=ahead)
                best[ahead] = min(best[ahead], time.perf_counter() - t0)
        assert result is not None
        lat = [s.t_emitted - s.t_end for s in result.syllables]
        latencies.extend(lat)
        total_audio += dur
        total_live += best[False]
        total_file += best[True]
        rows.append({
            "file": path.name, "duration_s": round(dur, 3), "compute_s": round(best[False], 4),
            "rtf": round(dur / best[False], 1), "compute_s_file": round(best[True], 4),
            "rtf_file": round(dur / best[True], 1), "syllables": len(result.syllables),
            "latency_median_ms": round(1000 * float(np.median(lat)), 1) if lat else None,
            "latency_p95_ms": round(1000 * float(np.percentile(lat, 95)), 1) if lat else None,
        })
    lat_a = np.array(latencies)
    summary = {
        "block_size": block_size,
        "files": len(rows), "audio_s": round(total_audio, 3),
        "realtime_factor": round(total_audio / total_live, 1),
        "realtime_factor_file": round(total_audio / total_file, 1),
        "file_to_live_cost": round(total_file / total_live, 3),
        "syllables": int(len(lat_a)),
        "latency_median_ms": round(1000 * float(np.median(lat_a)), 1) if len(lat_a) else None,
        "latency_p95_ms": round(1000 * float(np.percentile(lat_a, 95)), 1) if len(lat_a) else None,
        "latency_max_ms": round(1000 * float(lat_a.max()), 1) if len(lat_a) else None,
        "note": "latency = t_emitted - t_end (algorithmic; a live source adds <= one block)",
        "per_file": rows,
    }
    return summary
