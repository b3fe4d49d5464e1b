"""Measure the laugh detector (:mod:`gesture_sim.audio.laughter`): false alarms on real speech,
hits on synthetic laughter and misses on synthetic non-laughter.

* **Real speech** (every WAV given, or every ``*.wav`` in a folder given): laughs detected per
  minute and the share of frames marked laugh. Every such file is taken to contain no
  laughter (check that yourself: the project's speech files have none), so each detection is a
  false alarm.
* **Synthetic sets** (``--synthetic``; needs ``espeak-ng`` and ``sox``): made in a temporary
  folder (or ``--keep DIR``). Laughter: espeak-ng "ha ha ha ha", "hahaha", "he he he he" ... in
  four voices, two speeds and two pitches, and sox call trains (tremolo-modulated vowels, /h/ +
  vowel calls, breathy noise bursts at 4-6 Hz). Non-laughter: espeak-ng "ha" once, "ha ha",
  "hello how are you", counting, sentences; and both voices of the project's espeak test
  dialogue (:mod:`gesture_sim.testing.dialogue`, seeds 0-5). A laughter file is a hit when a
  laugh is detected overlapping its sound; a non-laughter file is a false alarm when any laugh is
  detected.

No real laughter recording is available to this project: the hit rate is on synthetic laughter
only.

    .venv/bin/python tools/laughter_eval.py tests/data/pipeline/beat2_scott_0_2_2.wav \\
        tests/data/audio [MORE_WAVS_OR_FOLDERS ...] --synthetic [--json out.json]

(the figures in docs/OKWECHIME.md also took the BEAT2, JFK and CMU Arctic folders of the
project's data collection as further arguments)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gesture_sim.audio.laughter import detect_laughter  # noqa: E402
from gesture_sim.audio.sources import load_audio  # noqa: E402

VOICES = ("en", "en+f3", "en+m3", "en-us+f2")
SPEEDS = (175, 230)          # words per minute
PITCHES = (40, 80)           # espeak-ng 0..99
LAUGH_TEXTS = ("ha ha ha ha", "ha ha ha", "ha ha ha ha ha", "ha-ha-ha", "ha-ha-ha-ha",
               "he he he he", "ho ho ho ho", "hahaha")
OTHER_TEXTS = ("ha", "ha ha", "hello how are you", "one two three four",
               "one two three four five six seven eight", "the quick brown fox jumps over the "
               "lazy dog", "I think that is a very good idea", "yes", "well, I do not know")


def _run(cmd: list[str]) -> None:
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def espeak(path: Path, text: str, voice: str = "en", speed: int = 175, pitch: int = 50) -> Path:
    """espeak-ng ``text`` -> a 16 kHz mono WAV at ``path`` (with 0.3 s of silence around)."""
    raw = path.with_suffix(".raw.wav")
    _run(["espeak-ng", "-v", voice, "-s", str(speed), "-p", str(pitch), "-w", str(raw), text])
    _run(["sox", str(raw), "-r", "16000", "-c", "1", str(path), "pad", "0.3", "0.3"])
    raw.unlink()
    return path


def sox_tremolo(path: Path, f0: float, rate: float, dur: float, depth: float = 95.0) -> Path:
    """A sawtooth "vowel" (F0 ``f0`` Hz, low-passed at 1.5 kHz, two formant boosts)
    amplitude-modulated at ``rate`` Hz (sox ``tremolo``)."""
    _run(["sox", "-n", "-r", "16000", "-c", "1", str(path), "synth", f"{dur}", "sawtooth",
          f"{f0}", "lowpass", "1500", "equalizer", "700", "2q", "8", "equalizer", "1200",
          "2q", "6", "tremolo", f"{rate}", f"{depth}", "gain", "-n", "-6", "pad", "0.3",
          "0.3"])
    return path


def sox_calls(path: Path, rate: float, n: int, f0: float, breathy: bool) -> Path:
    """``n`` calls at ``rate`` Hz: each an /h/ (0.03 s of high-passed noise) then a vowel
    (sawtooth, F0 falling from ``f0`` by 15 %), or with ``breathy`` only a noise burst."""
    period = 1.0 / rate
    call = path.with_suffix(".call.wav")
    if breathy:
        _run(["sox", "-n", "-r", "16000", "-c", "1", str(call), "synth", "0.11", "pinknoise",
              "highpass", "500", "fade", "q", "0.02", "0.11", "0.05", "gain", "-n", "-8"])
        length = 0.11
    else:
        h = path.with_suffix(".h.wav")
        v = path.with_suffix(".v.wav")
        _run(["sox", "-n", "-r", "16000", "-c", "1", str(h), "synth", "0.03", "whitenoise",
              "highpass", "1500", "gain", "-n", "-28"])
        _run(["sox", "-n", "-r", "16000", "-c", "1", str(v), "synth", "0.1", "sawtooth",
              f"{f0}-{0.85 * f0}", "lowpass", "2000", "fade", "q", "0.015", "0.1", "0.04",
              "gain", "-n", "-6"])
        _run(["sox", str(h), str(v), str(call)])
        h.unlink()
        v.unlink()
        length = 0.13
    gap = max(period - length, 0.0)
    _run(["sox", str(call), str(path), "pad", "0", f"{gap:.4f}", "repeat", str(n - 1), "pad",
          "0.3", "0.3"])
    call.unlink()
    return path


def make_synthetic(folder: Path) -> tuple[list[Path], list[Path]]:
    """Write the synthetic laughter and non-laughter sets under ``folder``; returns their
    paths (laughter, non-laughter)."""
    la, no = folder / "laughter", folder / "other"
    la.mkdir(parents=True, exist_ok=True)
    no.mkdir(parents=True, exist_ok=True)
    laughs: list[Path] = []
    others: list[Path] = []
    for text in LAUGH_TEXTS:
        for v in VOICES:
            for s in SPEEDS:
                for p in PITCHES:
                    slug = text.replace(" ", ".")
                    name = f"espeak_{slug}_{v.replace('+', '-')}_{s}_{p}.wav"
                    laughs.append(espeak(la / name, text, v, s, p))
    for f0 in (140, 230, 320):
        for rate in (4.0, 5.0, 6.0):
            for dur in (0.8, 1.3):
                laughs.append(sox_tremolo(la / f"tremolo_{f0}_{rate}_{dur}.wav", f0, rate, dur))
    for rate in (4.0, 5.0, 6.0):
        for n in (3, 5):
            laughs.append(sox_calls(la / f"noise_{rate}_{n}.wav", rate, n, 0.0, True))
            for f0 in (180, 300):
                laughs.append(sox_calls(la / f"hcalls_{rate}_{n}_{f0}.wav", rate, n, f0, False))
    for text in OTHER_TEXTS:
        for v in VOICES:
            for s in (175, 260):
                slug = "".join(ch if ch.isalnum() else "." for ch in text)
                name = f"espeak_{slug}_{v.replace('+', '-')}_{s}.wav"
                others.append(espeak(no / name, text, v, s, 50))
    return laughs, others


def _wavs(paths: list[str]) -> list[Path]:
    out: list[Path] = []
    for p in map(Path, paths):
        out.extend(sorted(p.glob("*.wav")) if p.is_dir() else [p])
    return out


def score_real(paths: list[Path]) -> list[dict]:
    """Per real speech file: duration, laughs (false alarms), per minute, laugh frame share."""
    rows = []
    for p in paths:
        x, _ = load_audio(p)
        digest = hashlib.sha1(np.asarray(x, np.float32).tobytes()).hexdigest()
        _, flags, laughs = detect_laughter(x)
        dur = len(x) / 16000.0
        rows.append({"file": str(p), "sha1": digest, "duration_s": round(dur, 2),
                     "false_alarms": len(laughs),
                     "per_minute": round(len(laughs) / max(dur / 60.0, 1e-9), 3),
                     "frame_share": round(float(flags.mean()) if len(flags) else 0.0, 5),
                     "spans": [(round(lg.start, 2), round(lg.end, 2)) for lg in laughs]})
    return rows


def _sound_span(x: np.ndarray) -> tuple[float, float]:
    env = np.abs(x)
    idx = np.flatnonzero(env > 0.02 * env.max()) if env.max() > 0 else np.array([0])
    return idx[0] / 16000.0, idx[-1] / 16000.0


def score_synthetic(laughs: list[Path], others: list[Path]) -> dict:
    hit_rows, fa_rows = [], []
    for p in laughs:
        x, _ = load_audio(p)
        a, b = _sound_span(x)
        _, _, found = detect_laughter(x)
        hit = any(lg.end > a and lg.start < b for lg in found)
        hit_rows.append({"file": p.name, "hit": hit, "sound": (round(a, 2), round(b, 2)),
                         "spans": [(round(lg.start, 2), round(lg.end, 2)) for lg in found]})
    for p in others:
        x, _ = load_audio(p)
        _, _, found = detect_laughter(x)
        fa_rows.append({"file": p.name, "false_alarm": bool(found),
                        "spans": [(round(lg.start, 2), round(lg.end, 2)) for lg in found]})
    groups: dict[str, list[bool]] = {}
    for r in hit_rows:
        parts = r["file"].split("_")
        key = "_".join(parts[:2]) if parts[0] == "espeak" else parts[0]
        groups.setdefault(key, []).append(r["hit"])
    dlg = []
    try:
        from gesture_sim.testing.dialogue import make_dialogue

        for seed in range(6):
            ch = make_dialogue(seed=seed).channels
            for i in range(ch.shape[1]):
                found = detect_laughter(np.asarray(ch[:, i], float))[2]
                dlg.append((len(ch) / 16000.0, len(found)))
    except Exception as exc:  # noqa: BLE001 - the dialogue is optional here
        print(f"(no test dialogue: {exc})", file=sys.stderr)
    d_min = sum(a for a, _ in dlg) / 60.0
    return {
        "dialogue_speech": {"channels": len(dlg), "minutes": round(d_min, 2),
                            "false_alarms": sum(b for _, b in dlg),
                            "per_minute": round(sum(b for _, b in dlg) / max(d_min, 1e-9), 3)},
        "laughter_files": len(hit_rows),
        "hit_rate": round(float(np.mean([r["hit"] for r in hit_rows])), 3),
        "hit_rate_by_kind": {k: round(float(np.mean(v)), 3) for k, v in groups.items()},
        "other_files": len(fa_rows),
        "false_alarm_rate": round(float(np.mean([r["false_alarm"] for r in fa_rows])), 3),
        "laughter": hit_rows, "other": fa_rows,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="*", help="real speech WAVs or folders of them (no laughter)")
    ap.add_argument("--synthetic", action="store_true",
                    help="also make and score the espeak-ng / sox sets")
    ap.add_argument("--keep", type=Path, help="write the synthetic sets here (kept)")
    ap.add_argument("--json", type=Path, help="write every figure here")
    a = ap.parse_args(argv)
    out: dict = {"note": "no real laughter recording was available: hits are on synthetic "
                         "laughter only; real speech files are assumed laughter-free"}
    real = score_real(_wavs(a.paths))
    if real:
        out["real_speech"] = real
        tot_s = sum(r["duration_s"] for r in real)
        tot_fa = sum(r["false_alarms"] for r in real)
        uniq = {r["sha1"]: r for r in real}.values()        # the same take given twice: once
        u_s = sum(r["duration_s"] for r in uniq)
        u_fa = sum(r["false_alarms"] for r in uniq)
        out["real_total"] = {"files": len(real), "minutes": round(tot_s / 60.0, 2),
                             "false_alarms": tot_fa,
                             "per_minute": round(tot_fa / max(tot_s / 60.0, 1e-9), 3),
                             "unique_files": len(uniq), "unique_minutes": round(u_s / 60.0, 2),
                             "unique_false_alarms": u_fa,
                             "unique_per_minute": round(u_fa / max(u_s / 60.0, 1e-9), 3)}
        for r in real:
            print(f"{r['file']}: {r['duration_s']:.1f} s, {r['false_alarms']} false alarm(s), "
                  f"{r['per_minute']:.2f}/min {r['spans']}")
        t = out["real_total"]
        print(f"real speech: {t['files']} files, {t['minutes']} min, {t['false_alarms']} false "
              f"alarms = {t['per_minute']:.2f}/min; distinct audio: {t['unique_files']} files, "
              f"{t['unique_minutes']} min, {t['unique_false_alarms']} = "
              f"{t['unique_per_minute']:.2f}/min")
    if a.synthetic:
        if not (shutil.which("espeak-ng") and shutil.which("sox")):
            print("espeak-ng and sox are needed for --synthetic", file=sys.stderr)
            return 2
        tmp = None
        folder = a.keep
        if folder is None:
            tmp = tempfile.TemporaryDirectory()
            folder = Path(tmp.name)
        try:
            syn = score_synthetic(*make_synthetic(folder))
        finally:
            if tmp is not None:
                tmp.cleanup()
        out["synthetic"] = syn
        print(f"synthetic laughter: {syn['laughter_files']} files, hit rate {syn['hit_rate']} "
              f"{syn['hit_rate_by_kind']}")
        print(f"synthetic non-laughter: {syn['other_files']} files, false-alarm rate "
              f"{syn['false_alarm_rate']}")
        dd = syn["dialogue_speech"]
        print(f"espeak test dialogue (gesture_sim.testing.dialogue, seeds 0-5): "
              f"{dd['channels']} voices, {dd['minutes']} min, {dd['false_alarms']} false alarms "
              f"= {dd['per_minute']:.2f}/min")
        for r in syn["laughter"]:
            if not r["hit"]:
                print(f"  miss {r['file']} {r['spans']}")
        for r in syn["other"]:
            if r["false_alarm"]:
                print(f"  false alarm {r['file']} {r['spans']}")
    if a.json:
        a.json.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
