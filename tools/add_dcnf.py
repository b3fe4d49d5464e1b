#!/usr/bin/env python3
"""Add a DCNF (Chiu 2014) to a trained inference model, keeping everything else as it is.

Usage (from the repository root; DATA is the shared data folder with the BEAT2 pair of
docs/DESIGN.md §6; the pairs must be the model's own training data, checked by fingerprint):

    .venv/bin/python tools/add_dcnf.py \\
        --pair DATA/beat2_scott/2_scott_0_1_1.npz DATA/beat2_scott/pcm16/2_scott_0_1_1.wav \\
        [--model motion_library/default/model] [-o OUT] [--window 4] [--seed 0]

The DCNF is trained against the model's own kinematic HMM posterior on the model's own
per-step inputs (same normaliser seed, clusters and parameter normalisation), so the HMM, the
CRF, the baseline and the controller policy built on them stay valid; the model file is
rewritten at format 1.1 with the ``dcnf`` block. Without ``-o`` the model folder is updated in
place; with ``-o`` the other files of the folder (policy, README) are copied along.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pair", nargs=2, action="append", required=True,
                        metavar=("MOTION", "AUDIO"))
    parser.add_argument("--model", default=str(ROOT / "motion_library" / "default" / "model"))
    parser.add_argument("-o", "--output", default=None, help="output folder (default: --model)")
    parser.add_argument("--window", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--force", action="store_true",
                        help="accept pairs whose per-step data differ from the model's (e.g. "
                        "after a change of the prosody tracker); recorded in the summary")
    args = parser.parse_args(argv)

    from gesture_sim.commands.train import load_pairs
    from gesture_sim.errors import GestureSimError
    from gesture_sim.inference.dcnf import DCNFSettings
    from gesture_sim.inference.model import MODEL_VERSION, GestureModel
    from gesture_sim.inference.train import data_fingerprint, fit_dcnf_to_hmm, prepare_takes

    try:
        model = GestureModel.load(args.model)
        takes = load_pairs(args.pair)
        prepared = prepare_takes(takes, model.settings, model.normalizer_seed,
                                 model.param_normalisation)
        fingerprint = data_fingerprint(prepared, model.settings)
        if fingerprint != model.fingerprint and not args.force:
            raise GestureSimError(
                "these pairs are not the model's training data (fingerprint differs; "
                "--force to accept)")
    except GestureSimError as exc:
        print(f"gesture-sim: error: {exc}", file=sys.stderr)
        return 2
    settings = replace(DCNFSettings(), window=args.window, seed=args.seed)
    print(f"  DCNF (W={settings.window}, layers {list(settings.hidden)}, order "
          f"{settings.order})", file=sys.stderr)
    dcnf, info = fit_dcnf_to_hmm(model.hmm, model.clusters, prepared, model.settings, settings)
    model.dcnf = dcnf
    model.version = MODEL_VERSION
    model.summary["dcnf"] = {"iterations": info.iterations,
                             "objective_per_step": info.objective_per_step,
                             "valid_loglik_per_step": info.valid_loglik_per_step,
                             "seconds": info.seconds, "settings": dcnf.meta(),
                             "data_fingerprint": fingerprint,
                             "syllables": sum(len(t.syllables) for t in takes)}
    out = Path(args.output or args.model)
    if out.resolve() != Path(args.model).resolve():
        out.mkdir(parents=True, exist_ok=True)
        for f in Path(args.model).iterdir():
            if f.is_file() and f.name not in ("model.json", "model.npz"):
                shutil.copy2(f, out / f.name)
    model.save(out)
    print(json.dumps(model.summary["dcnf"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
