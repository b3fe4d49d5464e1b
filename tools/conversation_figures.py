"""Figures of the two-person scene on the scripted espeak-ng dialogue (BENCHMARKS.md,
"Conversation"): how often and when the listener backchannels, relative to the partner's pauses,
and (with physics) how still the hands are in the partner's turns and how the bodies stand.

    python tools/conversation_figures.py --seeds 0 1 2 [--physics] [--json out.json]

Each seed draws a dialogue (pause lengths) and the people's seeds (seed, seed + 1). A
backchannel answers a pause when its nod peaks 0.2-1.5 s after the pause began.

    python tools/conversation_figures.py --face-sheet OUT.png [--seconds 9] [--interest 1]

instead draws the listener's face (``docs/figures/listener_face.png``): the dialogue of seed
``--seeds[0]`` (its first ``--seconds``), both people simulated (physics, the human look),
person 1 (red) listening to person 0's first turn, seen by the ``face_1`` camera at the
listener's backchannel peaks and in between; the top row without the listening posture (the
head as the clip holds it, the eyes looking up at the partner), the bottom row with it
(:mod:`gesture_sim.signals.listener`, *Posture*). Each frame is labelled with the listener's
simulated head pitch (spine + neck + head flexion, deg, + down) and eye pitch in the orbit.
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


PITCH = ("lower_spine_flex", "upper_spine_flex", "neck_flex", "head_flex")


def _face_run(stack, channels: np.ndarray, seed: int, interest: float, posture: bool):
    """Both people on ``channels`` with physics; ``posture``: the listeners' posture on/off.
    Returns (conversation, run, summary)."""
    voices, turns = conversation_channels(channels=channels)
    conv = Conversation(stack.library, stack.model, stack.policy, seeds=(seed, seed + 1),
                        physics=True, control_library=stack.control_library,
                        interests=(interest, interest))
    for person in conv.people:
        person._layer("listener").listener.posture = posture
    run = run_conversation(conv, voices, turns)
    return conv, run, conversation_summary(run)


def face_sheet(out: str, seed: int, seconds: float, interest: float,
               size: tuple[int, int] = (320, 300)) -> dict:
    """The listener's face sheet (module docstring); returns the figures per row."""
    import os

    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco
    from PIL import Image

    from gesture_sim.motion.preview import contact_sheet
    from gesture_sim.sim import humanoid as hm
    from gesture_sim.sim.scene import conversation_model, scene_qpos

    stack = load_stack(None, None, policy=True)
    d = make_dialogue(seed=seed)
    ch = d.channels[: int(seconds * 16000)]
    first = [u for u in d.turns[: next((i for i, u in enumerate(d.turns) if u.person != 0),
                                       len(d.turns))]]
    turn = type(first[0])(person=0, t_start=first[0].t_start, t_end=first[-1].t_end)
    w, h = size
    images, labels, rows = [], [], {}
    times = None
    for posture in (False, True):
        conv, run, s = _face_run(stack, ch, seed, interest, posture)
        tr = conv.traces()[1]
        col = [hm.ACTUATED_JOINTS.index(n) for n in PITCH]
        eye = hm.ACTUATED_JOINTS.index("left_eye_pitch")
        pitch = np.degrees(tr.q[:, col].sum(axis=1))
        eyes = np.degrees(tr.q[:, eye])
        t = tr.time - tr.time[0]
        if times is None:      # the same decisions with and without the posture
            bcs = [b for b in s["people"][1]["backchannels"] if b["t_peak"] < seconds - 0.5]
            times = [(turn.t_start + 1.9, "listening")]
            times += [(b["t_peak"], b["kind"].replace("+", " + ")) for b in bcs[:2]]
            if bcs:
                times.append((bcs[0]["t_peak"] + 0.6, "after the nod"))
            times = sorted(times[:4])
        during = (t >= turn.t_start) & (t <= min(turn.t_end, seconds))
        rows["posture" if posture else "before"] = {
            "head_pitch_deg_mean": round(float(pitch[during].mean()), 1),
            "eye_pitch_deg_mean": round(float(eyes[during].mean()), 1)}
        model = conversation_model(conv.distance, look="human")
        qpos = scene_qpos(conv.scene.model, conv.traces())
        data = mujoco.MjData(model)
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, w)
        model.vis.global_.offheight = max(model.vis.global_.offheight, h)
        renderer = mujoco.Renderer(model, height=h, width=w)
        try:
            for tt, what in times:
                i = int(np.argmin(np.abs(t - tt)))
                data.qpos[:] = qpos[min(i, len(qpos) - 1)]
                mujoco.mj_forward(model, data)
                renderer.update_scene(data, camera="face_1")
                images.append(renderer.render().copy())
                tag = "listening posture" if posture else "before (no posture)"
                labels.append(f"{tag}: {tt:.2f} s {what}\n"
                              f"head {pitch[i]:+.1f} deg, eyes {eyes[i]:+.1f} deg (+ down)")
        finally:
            renderer.close()
    sheet = contact_sheet(images, labels, columns=len(times))
    Image.fromarray(sheet).save(out)
    return {"out": out, "seed": seed, "seconds": seconds, "interest": interest,
            "turn": [turn.t_start, turn.t_end], "frames": times, **rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--physics", action="store_true", help="also simulate the two bodies")
    ap.add_argument("--json", default=None)
    ap.add_argument("--face-sheet", default=None, metavar="OUT.png",
                    help="draw the listener's face sheet instead (module docstring)")
    ap.add_argument("--seconds", type=float, default=9.0,
                    help="--face-sheet: the dialogue's first seconds")
    ap.add_argument("--interest", type=float, default=1.0, help="--face-sheet: both listeners")
    args = ap.parse_args()
    if args.face_sheet:
        res = face_sheet(args.face_sheet, args.seeds[0], args.seconds, args.interest)
        print(json.dumps(res, default=float))
        if args.json:
            with open(args.json, "w") as f:
                json.dump(res, f, indent=1, default=float)
        return
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
