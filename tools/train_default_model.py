#!/usr/bin/env python3
"""Train the default inference model shipped in ``motion_library/default/model``.

Usage (from the repository root; DATA is the shared data folder with the BEAT2 pair of
docs/DESIGN.md §6):

    .venv/bin/python tools/train_default_model.py \\
        --pair DATA/beat2_scott/2_scott_0_1_1.npz \\
               DATA/beat2_scott/2_scott_0_1_1.wav \\
        [--library motion_library/default] [-o motion_library/default/model] [--states N]

The kinematic parameters are normalised with the default library's B_X / W_X so the model's
state Gaussians live in the library's parameter space (the control layer compares them with
the library's segments). Writes the model and a ``README.md`` stating the source and licence.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pair", nargs=2, action="append", required=True,
                        metavar=("MOTION", "AUDIO"))
    parser.add_argument("--library", default=str(ROOT / "motion_library" / "default"))
    parser.add_argument("-o", "--output",
                        default=str(ROOT / "motion_library" / "default" / "model"))
    parser.add_argument("--states", type=int, default=None)
    parser.add_argument("--clusters", type=int, default=8)
    parser.add_argument("--window", type=int, default=4)
    args = parser.parse_args(argv)

    from gesture_sim.commands.train import library_normalisation, load_pairs
    from gesture_sim.fileio import atomic_write_text
    from gesture_sim.inference.train import TrainSettings, train_model

    norm, lib_fp = library_normalisation(args.library)
    takes = load_pairs(args.pair)
    model = train_model(takes, TrainSettings(n_states=args.states, n_clusters=args.clusters,
                                             window=args.window),
                        param_normalisation=norm, library_fingerprint=lib_fp,
                        on_stage=lambda s: print(f"  {s}", file=sys.stderr))
    model.save(args.output)
    s = model.summary
    sources = "\n".join(f"- `{Path(m).name}` + `{Path(a).name}`" for m, a in args.pair)
    measured = measured_sections(Path(args.output) / "README.md")
    atomic_write_text(Path(args.output) / "README.md", f"""# The default inference model

Remapped CRF (Levine et al. 2010) over {s['states']} hidden kinematic states, {s['clusters']}
prosody clusters, input window {s['window']} steps at {model.settings.rate_hz:g} Hz, and the
Levine et al. 2009 baseline over the same states. Trained by
`tools/train_default_model.py` on {s['seconds_of_data']:.1f} s of motion + speech
({s['segments']} segments, {s['syllables']} syllables) from:

{sources}

Kinematic parameters normalised with the default library's B_X / W_X (library fingerprint
`{lib_fp}`). Training-data fingerprint `{model.fingerprint}`.

Held-out HMM log-likelihood per step by number of states (last 25 % held out):
`{json.dumps(s['held_out_loglik_per_step'])}`.

{measured}## Source and licence

Derived from BEAT2 speaker 2 "scott", take `2_scott_0_1_1` (motion SMPL-X + speech) — Liu et
al., "BEAT", ECCV 2022; Liu et al., "EMAGE", CVPR 2024; files from `ycyentropy/GestureLSM`
(`demo/examples/`). **CC BY-NC 4.0, research/education only**; do not redistribute outside the
project. The model holds statistics of that data (Gaussian means/covariances, CRF weights,
speaker normalisation), not the recordings.
""")
    print(json.dumps({k: s[k] for k in ("steps", "states", "clusters", "window",
                                        "held_out_loglik_per_step", "training_seconds")},
                     indent=1))
    return 0


def measured_sections(readme: Path) -> str:
    """The hand-written sections of an existing model README (every ``## `` section between
    the generated head and "## Source and licence": what the data can teach, what was measured
    against ``random_sync``), kept across a retrain; '' when there is none."""
    if not readme.is_file():
        return ""
    text = readme.read_text(encoding="utf-8")
    start = text.find("\n## What ")
    end = text.find("\n## Source and licence")
    return text[start + 1:end + 1] if 0 <= start < end else ""


if __name__ == "__main__":
    sys.exit(main())
