#!/usr/bin/env python3
"""Add the Levine 2009 head and lower-body sections to a trained inference model, keeping every
other array and key of the model files as they are.

Usage (from the repository root; DATA is the shared data folder with the BEAT2 pair of
docs/DESIGN.md §6; AUDIO must be the model's own training speech):

    .venv/bin/python tools/add_levine09_sections.py --audio DATA/beat2_scott/2_scott_0_1_1.wav \\
        [--model motion_library/default/model] [--library motion_library/default] \\
        [--clip 2_scott_0_1_1] [-o OUT] [--force]

The sections are segmented at their own speed minima from the library's clip of the training
take (``--clip``, default: the model's first training pair, which is a clip of the default
library), clustered, and counted on the syllables of AUDIO with the baseline's own discretiser
statistics (:mod:`gesture_sim.inference.levine09_sections`). The syllables are checked against
the model: their whole-set statistics must be the baseline's (else the audio or the prosody
tracker differs; ``--force`` accepts it). ``model.npz`` gains the ``l09_head_*`` and
``l09_lower_*`` arrays and ``model.json``'s ``baseline`` block a ``sections`` entry; nothing else
changes (checked after writing). Without ``-o`` the model folder is updated in place.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--audio", required=True, help="the model's training speech (WAV)")
    parser.add_argument("--model", default=str(ROOT / "motion_library" / "default" / "model"))
    parser.add_argument("--library", default=str(ROOT / "motion_library" / "default"))
    parser.add_argument("--clip", default=None, help="library clip of the training take")
    parser.add_argument("-o", "--output", default=None, help="output folder (default: --model)")
    parser.add_argument("--force", action="store_true",
                        help="accept syllables whose statistics differ from the model's")
    args = parser.parse_args(argv)

    from gesture_sim.audio.prosody import analyze_file
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.errors import GestureSimError
    from gesture_sim.fileio import atomic_outputs, jsonable
    from gesture_sim.inference.levine09 import Discretiser
    from gesture_sim.inference.levine09_sections import train_sections
    from gesture_sim.inference.model import MODEL_JSON, MODEL_NPZ, GestureModel
    from gesture_sim.motion.library import MotionLibrary

    src = Path(args.model)
    try:
        model = GestureModel.load(src)
        if model.baseline is None:
            raise GestureSimError("the model has no Levine 2009 baseline")
        library = MotionLibrary.load(args.library)
        name = args.clip or Path(model.summary["pairs"][0]).stem
        clips = [c for c in library.clips if c.name == name]
        if not clips:
            raise GestureSimError(f"the library has no clip {name!r}")
        clip = clips[0]
        analysis = analyze_file(args.audio)
        syllables = list(analysis.syllables)
        stats = Discretiser.fit_stats(syllables)
        same = all(np.allclose(stats[k], model.baseline.stats[k], rtol=1e-9, atol=1e-12)
                   for k in model.baseline.stats)
        if not same and not args.force:
            raise GestureSimError(
                f"the syllables of {args.audio} do not give the baseline's statistics "
                f"({stats} vs {model.baseline.stats}); --force to accept")
    except GestureSimError as exc:
        print(f"gesture-sim: error: {exc}", file=sys.stderr)
        return 2
    rate = model.settings.rate_hz
    audio_s = len(analysis.samples) / SAMPLE_RATE
    n_steps = int(np.floor(min(clip.n_frames / clip.fps, audio_s) * rate))
    sections = train_sections([syllables], [np.asarray(clip.qpos, dtype=float)],
                              tuple(library.joint_names), [clip.fps], rate, [n_steps / rate],
                              model.baseline.stats, model.baseline.silence_chunk_s)
    for sec in sections.values():
        sec.info |= {"clip": clip.name, "library_fingerprint": str(library.fingerprint),
                     "syllables": len(syllables), "statistics_match": bool(same)}

    meta = json.loads((src / MODEL_JSON).read_text(encoding="utf-8"))
    with np.load(src / MODEL_NPZ, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    new = {}
    for name_, sec in sections.items():
        new |= sec.to_arrays(f"l09_{name_}_")
    # Replace earlier sections (a rerun), never any other array.
    old_sections = set(meta["baseline"].get("sections") or {})
    keep = {k: v for k, v in arrays.items()
            if not any(k.startswith(f"l09_{s}_") for s in old_sections)}
    clash = set(keep) & set(new)
    if clash:
        print(f"gesture-sim: error: arrays {sorted(clash)} exist already", file=sys.stderr)
        return 2
    before_meta = json.loads(json.dumps(meta))
    meta["baseline"]["sections"] = {n: s.meta() for n, s in sections.items()}
    out = Path(args.output or args.model)
    if out.resolve() != src.resolve():
        out.mkdir(parents=True, exist_ok=True)
        for f in src.iterdir():
            if f.is_file() and f.name not in (MODEL_JSON, MODEL_NPZ):
                shutil.copy2(f, out / f.name)
    with atomic_outputs(out / MODEL_NPZ, out / MODEL_JSON) as (npz_tmp, json_tmp):
        with open(npz_tmp, "wb") as fh:
            np.savez(fh, **(keep | new))
        json_tmp.write_text(json.dumps(jsonable(meta, finite=False), indent=1),
                            encoding="utf-8")

    # Check: every other array and key is as it was; the model loads with its sections.
    with np.load(out / MODEL_NPZ, allow_pickle=False) as npz:
        for k, v in keep.items():
            w = npz[k]
            assert w.dtype == v.dtype and w.shape == v.shape and w.tobytes() == v.tobytes(), k
    after = json.loads((out / MODEL_JSON).read_text(encoding="utf-8"))
    for k, v in before_meta.items():
        if k != "baseline":
            assert after[k] == v, k
    for k, v in before_meta["baseline"].items():
        if k != "sections":
            assert after["baseline"][k] == v, k
    loaded = GestureModel.load(out)
    assert set(loaded.baseline.sections) == set(sections)
    print(json.dumps({n: s.info for n, s in sections.items()}, indent=1,
                     default=lambda x: None if isinstance(x, float) and math.isnan(x) else x))
    return 0


if __name__ == "__main__":
    sys.exit(main())
