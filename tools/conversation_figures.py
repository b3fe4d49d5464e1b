"""Figures of the two-person scene on the scripted espeak-ng dialogue (BENCHMARKS.md,
"Conversation"): how often and when the listener backchannels, relative to the partner's pauses,
and (with physics) how still the hands are in the partner's turns and how the bodies stand.

    python tools/conversation_figures.py --seeds 0 1 2 [--physics] [--json out.json]

Each seed draws a dialogue (pause lengths) and the people's seeds (seed, seed + 1). A
backchannel answers a pause when its nod peaks 0.2-1.5 s after the pause began.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from gesture_sim.app.conversation import conversation_summary
from gesture_sim.conversation import Conversation, conversation_channels, run_conversation
from gesture_sim.loading import load_stack
from gesture_sim.testing.dialogue import make_dialogue

WINDOW = (0.2, 1.5)


def _answered(pauses, people) -> tuple[int, list[float]]:
    hits, delays = 0, []
    for speaker, t0, _t1 in pauses:
        d = [b["t_peak"] - t0 for b in people[1 - speaker]["backchannels"]
             if WINDOW[0] <= b["t_peak"] - t0 <= WINDOW[1]]
        if d:
            hits += 1
            delays.append(min(d))
    return hits, delays


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--physics", action="store_true", help="also simulate the two bodies")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    stack = load_stack(None, None, policy=True)
    rows = []
    for seed in args.seeds:
        d = make_dialogue(seed=seed)
        voices, turns = conversation_channels(channels=d.channels)
        conv = Conversation(stack.library, stack.model, stack.policy, seeds=(seed, seed + 1),
                            physics=args.physics, control_library=stack.control_library)
        s = conversation_summary(run_conversation(conv, voices, turns))
        people = s["people"]
        inv, inv_delays = _answered(d.inviting_pauses, people)
        q, _ = _answered(d.other_pauses, people)
        gaps, _ = _answered(d.turn_gaps, people)
        bcs = [b for p in people for b in p["backchannels"]]
        partner_s = sum(d.speech_s(p) for p in range(2))
        row = {"seed": seed, "inviting": [inv, len(d.inviting_pauses)],
               "questions": [q, len(d.other_pauses)], "turn_gaps": [gaps, len(d.turn_gaps)],
               "delays_s": inv_delays, "backchannels": len(bcs),
               "per_min_partner_speech": 60.0 * len(bcs) / partner_s,
               "while_speaking": sum(p["backchannels_while_speaking"] for p in people),
               "with_brow": sum(b["kind"] == "nod+brow" for b in bcs)}
        if args.physics:
            row["hands_in_partner_turns"] = [p["hands_in_partner_turns"] for p in people]
            row["physics"] = [p["physics"] for p in people]
        rows.append(row)
        print(json.dumps(row, default=float))
    delays = np.concatenate([r["delays_s"] for r in rows]) if rows else np.zeros(0)
    total = {
        "inviting_answered": sum(r["inviting"][0] for r in rows) / max(
            sum(r["inviting"][1] for r in rows), 1),
        "questions_answered": sum(r["questions"][0] for r in rows) / max(
            sum(r["questions"][1] for r in rows), 1),
        "turn_gaps_answered": sum(r["turn_gaps"][0] for r in rows) / max(
            sum(r["turn_gaps"][1] for r in rows), 1),
        "delay_median_s": float(np.median(delays)) if len(delays) else None,
        "delay_range_s": [float(delays.min()), float(delays.max())] if len(delays) else None,
        "per_min_partner_speech": float(np.mean([r["per_min_partner_speech"] for r in rows])),
        "while_speaking": sum(r["while_speaking"] for r in rows),
    }
    print(json.dumps(total, default=float))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"seeds": rows, "total": total}, f, indent=1, default=float)


if __name__ == "__main__":
    main()
