#!/usr/bin/env python3
"""Listener figures: backchannel rates and timing for interest 0 / 0.5 / 1 and both listener
models (Okwechime 2011 ch. 4-5; issue 34).

Usage (from the repository root):

    .venv/bin/python tools/listener_figures.py [--dialogues 3] [--seeds 5]
        [--real SPEECH.wav] [--json OUT.json]

Sources:

* **the two-voice test dialogue** (:func:`gesture_sim.testing.dialogue.make_dialogue`, seeds
  0..``dialogues``-1; espeak-ng + sox): both persons listen to each other, a person speaks while
  any of its own prosody frames of the last 0.3 s is not silent (the conversation tests'
  rule). Known answers: the pauses after statements (*inviting*), after questions, and the
  gaps between turns.
* **real speech** (``--real``, default a 64 s BEAT2 take of one real speaker; the repository has
  no real two-speaker recording): the listener hears that speaker and never speaks. Pauses are
  the speaker's silent stretches of at least 0.25 s (its prosody frames' ``silent`` flags;
  speech = first to last sound less the pauses); there is no known
  inviting/non-inviting split, so only "in a pause" vs "mid-speech" is reported.

Models: ``rule`` (the prosodic rule, :class:`~gesture_sim.signals.listener.ListenerSignals`;
``today`` = no interest, the rule unchanged) and ``okwechime`` (the audio-driven listener,
:class:`~gesture_sim.signals.listener_audio.AudioListener`, fallback mapping, codebook on the
shipped speech). Interest tables: Table 5.4 around the rule's base rates
(:class:`~gesture_sim.signals.sdm.ListenerTendencies`).

Measures per listener, pooled over dialogues, both persons and ``seeds`` listener seeds:
backchannels, nods (kinds with a nod) and "mm" backchannels (the thesis's voiced [V]; here a
silent head dip) per minute of partner
speech; the share of backchannels decided (``t_emitted``) in a partner's inviting pause
(from its start to 0.3 s after its end), at the end of a partner's turn (a turn gap, or the
dialogue's last utterance to the end; the turn's last utterance is a statement: the rule may
answer it), in a pause after a question (not
inviting), and elsewhere (mid-speech or while the listener itself speaks).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gesture_sim.audio.sources import load_audio  # noqa: E402
from gesture_sim.contracts import SAMPLE_RATE  # noqa: E402
from gesture_sim.signals.listener import make_listener  # noqa: E402
from gesture_sim.testing.frames import tracked_frames  # noqa: E402

DT = 1 / 30
CONFIGS: tuple[tuple[str, float | None], ...] = (
    ("rule", None), ("rule", 0.0), ("rule", 0.5), ("rule", 1.0),
    ("okwechime", 0.0), ("okwechime", 0.5), ("okwechime", 1.0),
)


def simulate(listeners: list, audio: list[np.ndarray | None], frames: list[tuple | None],
             dur: float) -> None:
    """Step ``listeners`` (one per person, None: that person does not listen) at 30 Hz;
    listener ``p`` hears person ``1 - p``'s frames and audio (``audio[q]``/``frames[q]``:
    person q's voice, None: q is silent and never speaks)."""
    n = len(listeners)
    sent_f = [0] * n
    sent_a = [0] * n
    for k in range(int(dur / DT)):
        t = k * DT
        for q in range(n):
            p = 1 - q
            if frames[q] is not None and listeners[p] is not None:
                fr = frames[q]
                m = int(np.searchsorted(fr[3], t + 1e-9, side="right"))
                if m > sent_f[q]:
                    listeners[p].push_frames(*(a[sent_f[q]:m] for a in fr))
                    sent_f[q] = m
            if audio[q] is not None and listeners[p] is not None and hasattr(
                    listeners[p], "push_audio"):
                m = min(int(round(t * SAMPLE_RATE)), len(audio[q]))
                if m > sent_a[q]:
                    listeners[p].push_audio(audio[q][sent_a[q]:m])
                    sent_a[q] = m
        for p in range(n):
            if listeners[p] is None:
                continue
            own = False
            fr = frames[p]
            if fr is not None:
                m = int(np.searchsorted(fr[3], t + 1e-9, side="right"))
                own = bool(((fr[0][:m] >= t - 0.3) & ~fr[2][:m]).any())
            listeners[p].step(t, own)


def _in(t: float, spans: list[tuple[float, float]], after: float = 0.3) -> bool:
    return any(a <= t <= b + after for a, b in spans)


def tally(acc: dict, bcs: list, speech_min: float, inviting: list, gaps: list,
          questions: list) -> None:
    """Add one listener's backchannels to ``acc``."""
    acc["speech_min"] += speech_min
    for b in bcs:
        acc["bc"] += 1
        acc["nod"] += "nod" in b.kind
        acc["mm"] += "mm" in b.kind
        if _in(b.t_emitted, inviting):
            acc["inviting"] += 1
        elif _in(b.t_emitted, gaps):
            acc["gap"] += 1
        elif _in(b.t_emitted, questions):
            acc["question"] += 1
        else:
            acc["elsewhere"] += 1


def _new() -> dict:
    return {"speech_min": 0.0, "bc": 0, "nod": 0, "mm": 0, "inviting": 0, "gap": 0,
            "question": 0, "elsewhere": 0}


def dialogue_rows(n_dialogues: int, seeds: int) -> dict:
    from gesture_sim.testing import dialogue

    out = {cfg: _new() for cfg in CONFIGS}
    for ds in range(n_dialogues):
        d = dialogue.make_dialogue(ds)
        audio = [d.channels[:, p].astype(float) for p in (0, 1)]
        frames = [tracked_frames(d.channels[:, p]) for p in (0, 1)]
        for model, interest in CONFIGS:
            for s in range(seeds):
                lis = [make_listener(model, seed=100 * ds + 10 * s + p, interest=interest)
                       for p in (0, 1)]
                simulate(lis, audio, frames, d.duration)
                for p in (0, 1):
                    q = 1 - p
                    inv = [(a, b) for who, a, b in d.inviting_pauses if who == q]
                    gap = [(a, b) for who, a, b in d.turn_gaps if who == q]
                    last = d.turns[-1]
                    if last.person == q:              # the dialogue's last turn end
                        gap.append((last.t_end, d.duration))
                    que = [(a, b) for who, a, b in d.other_pauses if who == q]
                    tally(out[(model, interest)], lis[p].backchannels, d.speech_s(q) / 60.0,
                          inv, gap, que)
    return out


def real_rows(path: Path, seeds: int) -> dict:
    x, _ = load_audio(path)
    fr = tracked_frames(x)
    times, silent = fr[0], fr[2]
    sound = np.flatnonzero(~silent)
    pauses: list[tuple[float, float]] = []
    for a, b in zip(sound[:-1], sound[1:], strict=True):
        if (b - a - 1) * 0.01 >= 0.25 - 1e-9:        # silent frames a+1 .. b-1
            pauses.append((times[a] + 0.005, times[b] - 0.005))
    # speech: from the first to the last non-silent frame, less the pauses (gaps < 0.25 s,
    # unvoiced consonants included, count as speech)
    span = (times[sound[-1]] - times[sound[0]] + 0.01) if len(sound) else 0.0
    speech_min = (span - sum(b - a for a, b in pauses)) / 60.0
    out = {cfg: _new() for cfg in CONFIGS}
    for model, interest in CONFIGS:
        for s in range(seeds):
            lis = make_listener(model, seed=1000 + s, interest=interest)
            simulate([None, lis], [x.astype(float), None], [fr, None], len(x) / SAMPLE_RATE)
            tally(out[(model, interest)], lis.backchannels, speech_min, pauses, [], [])
    out["_pauses"] = len(pauses)
    out["_speech_min"] = speech_min
    return out


def table(rows: dict, title: str, split: bool) -> str:
    head = ("| model | interest | backchannels/min | nods/min | 'mm'/min | at inviting pauses"
            + (" | at turn ends | after questions" if split else "") + " | elsewhere |")
    lines = [f"**{title}**", "", head, "|" + "---|" * (head.count("|") - 1)]
    for (model, interest) in CONFIGS:
        a = rows[(model, interest)]
        m = max(a["speech_min"], 1e-9)
        n = max(a["bc"], 1)
        cells = [model, "today (none)" if interest is None else f"{interest:.1f}",
                 f"{a['bc'] / m:.1f}", f"{a['nod'] / m:.1f}", f"{a['mm'] / m:.1f}",
                 f"{a['inviting'] / n:.0%}"]
        if split:
            cells += [f"{a['gap'] / n:.0%}", f"{a['question'] / n:.0%}"]
        cells.append(f"{a['elsewhere'] / n:.0%}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dialogues", type=int, default=3, help="dialogue seeds (default 3)")
    ap.add_argument("--seeds", type=int, default=5, help="listener seeds per case (default 5)")
    ap.add_argument("--real", type=Path, default=None,
                    help="also a real speech recording as the partner (e.g. a BEAT2 take)")
    ap.add_argument("--json", type=Path, default=None, help="write the counts as JSON")
    args = ap.parse_args(argv)
    result: dict[str, dict] = {}
    if args.dialogues > 0:
        rows = dialogue_rows(args.dialogues, args.seeds)
        mins = rows[CONFIGS[0]]["speech_min"] / args.seeds
        print(table(rows, f"Two-voice test dialogue ({args.dialogues} dialogues x 2 listeners x "
                    f"{args.seeds} seeds; {mins:.1f} min of partner speech per seed)", True))
        print()
        result["dialogue"] = {f"{m}:{i}": v for (m, i), v in rows.items()}
    if args.real is not None and args.real.is_file():
        rows = real_rows(args.real, args.seeds)
        print(table(rows, f"Real speech: {args.real.name} ({rows['_speech_min']:.2f} min of "
                    f"speech, {rows['_pauses']} pauses >= 0.25 s; {args.seeds} seeds); "
                    "'at inviting pauses' = in any pause", False))
        result["real"] = {(f"{k[0]}:{k[1]}" if isinstance(k, tuple) else k): v
                          for k, v in rows.items()}
    elif args.real is not None:
        print(f"(no real recording at {args.real})")
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
