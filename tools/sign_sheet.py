"""Contact sheet of a motion library's gestural signs (Chiu 2014), with per-sign counts and the
agreement of the two labelling passes (docs/SIGNS.md).

    python tools/sign_sheet.py motion_library/default -o docs/figures/signs.png --json out.json

One row per sign, up to ``--per-sign`` segments in it (co-speech segments first, spread over
the library), each drawn as two small views of the body frame from forward kinematics: front
(y across, character's left on the right, z up) and side (x forward to the right, z up). The
left hand's path is blue, the right hand's red, light to dark over time; a dot marks the start,
a triangle the apex (the highest frame) with the palm normal there as an arrow; grey marks are
the shoulders, the chest point and the head. The title gives the segment, its kind, its length,
the pass-1 rule's sign and the pass-2 (prototype) sign.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _segment_kinds(lib) -> list[str]:
    from gesture_sim.commands.library import segment_kinds

    return [str(k) for k in segment_kinds(lib)[0]]


def summary(lib, kinds: list[str], pass1: list[str], pass2: list[str]) -> dict:
    """Per-sign counts per segment kind and the two-pass agreement (all, and co-speech)."""
    from gesture_sim.motion import signs as sg

    out: dict = {"signs": list(sg.SIGNS), "counts": {}, "agreement": {},
                 "settings": sg.settings_dict()}
    for kind in ("cospeech", "emblem", "adaptor", "acting", "all"):
        idx = [i for i, k in enumerate(kinds) if kind == "all" or k == kind]
        if not idx:
            continue
        out["counts"][kind] = {"pass1": sg.sign_counts([pass1[i] for i in idx]),
                               "pass2": sg.sign_counts([pass2[i] for i in idx])}
        out["agreement"][kind] = sg.cohen_kappa([pass1[i] for i in idx],
                                                [pass2[i] for i in idx])
    co = [i for i, k in enumerate(kinds) if k == "cospeech"]
    out["confusion_cospeech"] = {
        a: {b: n for b in sg.SIGNS
            if (n := sum(1 for i in co if pass1[i] == a and pass2[i] == b))}
        for a in sg.SIGNS if any(pass1[i] == a for i in co)}
    return out


def _draw(ax_front, ax_side, form, title: str) -> None:
    t = form.n_frames
    colours = ({0: "tab:blue", 1: "tab:red"})
    for h in range(2):
        p = form.hand[:, h]
        alpha = np.linspace(0.25, 1.0, max(t - 1, 1))
        for k in range(t - 1):
            ax_front.plot(p[k:k + 2, 1], p[k:k + 2, 2], color=colours[h], alpha=alpha[k], lw=1.4)
            ax_side.plot(p[k:k + 2, 0], p[k:k + 2, 2], color=colours[h], alpha=alpha[k], lw=1.4)
        ax_front.plot(p[0, 1], p[0, 2], "o", color=colours[h], ms=3)
        ax_side.plot(p[0, 0], p[0, 2], "o", color=colours[h], ms=3)
        a = int(np.argmax(p[:, 2]))
        n = form.palm[a, h] * 0.12
        ax_front.plot(p[a, 1], p[a, 2], "^", color=colours[h], ms=4)
        ax_side.plot(p[a, 0], p[a, 2], "^", color=colours[h], ms=4)
        ax_front.annotate("", (p[a, 1] + n[1], p[a, 2] + n[2]), (p[a, 1], p[a, 2]),
                          arrowprops={"arrowstyle": "->", "color": "k", "lw": 0.8})
        ax_side.annotate("", (p[a, 0] + n[0], p[a, 2] + n[2]), (p[a, 0], p[a, 2]),
                         arrowprops={"arrowstyle": "->", "color": "k", "lw": 0.8})
        s = form.shoulder[0, h]
        ax_front.plot(s[1], s[2], "s", color="0.6", ms=3)
        ax_side.plot(s[0], s[2], "s", color="0.6", ms=3)
    c = form.chest[0]
    head = form.shoulder[0].mean(axis=0) + np.array([0.0, 0.0, 0.22])
    for ax, (u, w) in ((ax_front, (1, 2)), (ax_side, (0, 2))):
        ax.plot(c[u], c[w], "x", color="0.5", ms=4)
        ax.add_patch(__import__("matplotlib.patches", fromlist=["Circle"]).Circle(
            (head[u], head[w]), 0.09, fill=False, color="0.6", lw=0.8))
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    ax_front.set_xlim(-0.85, 0.85)
    ax_side.set_xlim(-0.4, 1.0)
    for ax in (ax_front, ax_side):
        ax.set_ylim(-0.45, 1.2)
    ax_front.set_title(title, fontsize=6, loc="left")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("library", help="motion library folder")
    ap.add_argument("-o", "--output", required=True, help="PNG to write")
    ap.add_argument("--per-sign", type=int, default=4, help="segments drawn per sign (4)")
    ap.add_argument("--kinds", default="cospeech,emblem,acting,adaptor",
                    help="segment kinds drawn, in order of preference")
    ap.add_argument("--json", help="also write the counts and agreement to this JSON file")
    ap.add_argument("--dpi", type=int, default=90)
    args = ap.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gesture_sim.motion import signs as sg
    from gesture_sim.motion.library import MotionLibrary

    lib = MotionLibrary.load(args.library)
    kinds = _segment_kinds(lib)
    forms = [sg.segment_form(lib, s.index) for s in lib.segments]
    pass1 = [sg.label_form(f)[0] for f in forms]
    pass2 = sg.prototype_library(lib)
    out = summary(lib, kinds, pass1, pass2)
    want = [k.strip() for k in args.kinds.split(",") if k.strip()]
    rows = [s for s in sg.SIGNS if any(pass1[i] == s and kinds[i] in want
                                       for i in range(len(pass1)))]
    cols = max(args.per_sign, 1)
    fig, axes = plt.subplots(max(len(rows), 1), 2 * cols,
                             figsize=(2.3 * cols * 2 * 0.62, 1.55 * max(len(rows), 1)),
                             squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    drawn: dict[str, list[int]] = {}
    for r, sign in enumerate(rows):
        chosen: list[int] = []
        for kind in want:
            idx = [i for i in range(len(pass1)) if pass1[i] == sign and kinds[i] == kind]
            room = cols - len(chosen)
            if room <= 0:
                break
            if len(idx) > room:
                idx = [idx[int(k)] for k in np.linspace(0, len(idx) - 1, room)]
            chosen += idx
        drawn[sign] = chosen
        for c, i in enumerate(chosen):
            seg = lib.segments[i]
            a, b = axes[r, 2 * c], axes[r, 2 * c + 1]
            a.axis("on")
            b.axis("on")
            title = (f"{sign} | #{i} {kinds[i]} {seg.length / lib.fps:.2f}s\n"
                     f"{lib.clips[seg.clip].name[-22:]} p2={pass2[i]}")
            _draw(a, b, forms[i], title)
        axes[r, 0].set_ylabel(sign, fontsize=8)
    fig.suptitle(f"{args.library}: pass-1 signs (front | side views; blue left, red right "
                 f"hand; arrow = palm normal at the apex)", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output, dpi=args.dpi)
    out["drawn"] = drawn
    out["library"] = args.library
    out["fingerprint"] = lib.fingerprint
    text = json.dumps(out, indent=1)
    if args.json:
        Path(args.json).write_text(text + "\n", encoding="utf-8")
    co = out["counts"].get("cospeech", {}).get("pass1", {})
    print("co-speech pass-1 counts: " + ", ".join(f"{k} {v}" for k, v in co.items() if v))
    for kind, ag in out["agreement"].items():
        print(f"{kind}: {ag['n']} segments, agreement {ag['agreement']}, kappa {ag['kappa']}")
    print(f"-> {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
