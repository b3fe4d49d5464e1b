#!/usr/bin/env python3
"""Does the inference layer's belief change what the planner chooses? (issue 51)

    PYTHONPATH=. .venv/bin/python tools/planner_prior.py AUDIO.wav [--textgrid T.TextGrid]

Plans the file twice, with the belief prior (the ``planned`` defaults) and without
(``prior_weight=0``), and prints the share of the planned time in which a different segment
plays, the share of items shared, and the planning wall time split.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("audio", type=Path)
    ap.add_argument("--textgrid", type=Path, default=None)
    args = ap.parse_args(argv)

    from gesture_sim.audio.sources import load_audio
    from gesture_sim.feed import _text_ahead
    from gesture_sim.loading import load_stack
    from gesture_sim.pipeline import GesturePipeline

    stack = load_stack(None, None, policy=True)
    y, _ = load_audio(args.audio)
    plans, timing = {}, {}
    for name, w in (("prior", None), ("no_prior", 0.0)):
        pipe = GesturePipeline(stack.library, stack.model, stack.policy, method="planned",
                               physics=False, control_library=stack.control_library)
        if w is not None:
            pipe.motion.settings = replace(pipe.motion.settings, prior_weight=w)
        pipe.reset()
        if args.textgrid is not None:
            pipe.know_ahead(**_text_ahead(None, args.textgrid, None))
        import tracemalloc

        tracemalloc.start()
        pipe.expect_audio(y)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        plans[name], timing[name] = pipe.motion.plan, dict(pipe.motion.timing)
        timing[name]["peak_python_mb"] = peak / 2**20
    t = np.arange(0.0, len(y) / 16000.0, 1.0 / 30)
    seg = {}
    for name, plan in plans.items():
        seg[name] = np.array([plan.items[i].segment if i >= 0 else -1
                              for i in (plan.at(x)[0] for x in t)])
    both = (seg["prior"] >= 0) & (seg["no_prior"] >= 0)
    a = {(it.segment, round(it.t_start, 2)) for it in plans["prior"].items}
    b = {(it.segment, round(it.t_start, 2)) for it in plans["no_prior"].items}
    out = {"time_with_another_segment": float(np.mean(seg["prior"][both]
                                                      != seg["no_prior"][both])),
           "items_shared": len(a & b) / max(len(a | b), 1),
           "distinct": {k: len({it.segment for it in p.items}) for k, p in plans.items()},
           "timing_s": timing, "duration_s": len(y) / 16000.0}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
