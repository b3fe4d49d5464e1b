#!/usr/bin/env python3
"""Train the gesture-controller policy shipped in ``motion_library/default/model/policy.npz``.

Usage (from the repository root):

    .venv/bin/python tools/train_default_policy.py \\
        [--library motion_library/default] [--model motion_library/default/model] [-o PATH]

Loads the motion library and its inference model, solves the controller MDP with the default
tones (calm / neutral / energetic), every tag of the library as a semantic label and the
product's settings (:func:`gesture_sim.loading.policy_settings`), and saves
the policy where :func:`gesture_sim.loading.load_policy` reads it (``<model>/policy.npz`` for
the model's own library, ``<library>/policies/`` for another library: see
:func:`gesture_sim.loading.policy_path`).
Prints the training figures (solve and table seconds, candidates before/after pruning, file
size) as JSON on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--library", default=str(ROOT / "motion_library" / "default"))
    parser.add_argument("--model", default=None,
                        help="inference model folder (default: <library>/model)")
    parser.add_argument("-o", "--output", default=None,
                        help="policy file (default: where the loader reads it: "
                             "<model>/policy.npz for the model's own library, else "
                             "<library>/policies/)")
    args = parser.parse_args(argv)

    from gesture_sim.control.policy import Policy
    from gesture_sim.errors import GestureSimError
    from gesture_sim.loading import (
        is_own_library,
        load_stack,
        policy_path,
        train_library_policy,
    )

    try:
        stack = load_stack(args.library, args.model, policy=False)   # checks the pair fits
        model_dir, library, model = stack.model_dir, stack.control_library, stack.state_model
        t0 = time.perf_counter()
        policy = train_library_policy(library, model, show_progress=True)
        train_s = time.perf_counter() - t0
        out = Path(args.output) if args.output else policy_path(
            model_dir, model, library_dir=stack.library_dir,
            own_library=is_own_library(stack.model, stack.library))
        policy.save(out)
        Policy.load(out, library.fingerprint, model.fingerprint)       # reads back, same pair
    except GestureSimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    m = policy.meta
    print(json.dumps({
        "policy": str(out), "file_mb": os.path.getsize(out) / 1e6, "train_s": train_s,
        "solve_s": m["solve_seconds"], "table_s": m["table_seconds"],
        "segments": m["n_segments"], "states": m["n_states"], "tones": list(policy.tones),
        "labels": list(policy.labels[1:]), "entries_before_pruning": m["entries_before_pruning"],
        "entries_after_pruning": m["entries_after_pruning"], "value_rows": m["value_rows"],
        "pruned_fraction": m["pruned_fraction"], "error_bound": m["error_bound"],
    }, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
