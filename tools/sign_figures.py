"""Figures of the sign predictor (Chiu 2014; docs/SIGNS.md §4): held-out sign prediction on the
labelled take, and the semantic check on the other takes.

    python tools/sign_figures.py --library motion_library/default \\
        --labelled 2_scott_0_1_1.wav 2_scott_0_1_1.TextGrid \\
        --take 2_scott_0_2_2.wav 2_scott_0_2_2.TextGrid --take ... --folds 4 --json out.json

1. **Held-out prediction.** Only the labelled take has signs (the library's segments of it), so
   the frames are cross-validated by ``--folds`` contiguous time blocks: each block is held
   out in turn, a model is trained on the rest (vocabulary from the training blocks only) and
   decodes the block (Viterbi, offline; and the causal filter's argmax). Frame accuracy and
   per-sign F1 (macro over the signs present in the reference) for: the full model, the
   prosody-only model, the words-only model (words + POS + lexicon), and the majority baseline
   (the training blocks' most frequent sign).
2. **Semantic check.** On each other take (a TextGrid, no sign labels), a model trained on the
   whole labelled take decodes the take; for each lexicon cue (a word or phrase of the
   dictionary, :mod:`gesture_sim.signals.sign_lexicon`) the check is whether its sign occurs
   in the predicted frames from the cue's start to 1 s after its end. Reported against random
   sign sequences (a Markov chain with the labelled take's smoothed transitions, 200 draws)
   and against the same model without the dictionary prior (``lexicon_weight = 0``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def f1_scores(ref: np.ndarray, hyp: np.ndarray, n: int) -> dict[int, float]:
    """Per-class F1 over the classes present in ``ref``."""
    out = {}
    for c in np.unique(ref):
        tp = float(np.sum((ref == c) & (hyp == c)))
        fp = float(np.sum((ref != c) & (hyp == c)))
        fn = float(np.sum((ref == c) & (hyp != c)))
        out[int(c)] = 2 * tp / (2 * tp + fp + fn) if tp > 0 else 0.0
    return out


def cross_validate(take, folds: int, variants: dict, base) -> dict:
    from gesture_sim.inference import sign_model as sm

    n = int(math.ceil(take.duration_s / base.frame_s - 1e-9))
    y = sm.frame_labels(take.spans, n, base.frame_s, None)
    edges = np.linspace(0, n, folds + 1).round().astype(int)
    preds: dict[str, np.ndarray] = {k: np.full(n, -1) for k in [*variants, "majority"]}
    causal: dict[str, np.ndarray] = {k: np.full(n, -1) for k in variants}
    for f in range(folds):
        lo, hi = edges[f], edges[f + 1]
        train_mask = np.ones(n, bool)
        train_mask[lo:hi] = False
        ytr = np.where(train_mask, y, -1)
        # vocabulary from the training blocks' words only
        tw = [w for w in take.words if not (lo <= int((w[0] + w[1]) / 2 // base.frame_s) < hi)]
        for name, cfg in variants.items():
            vocab = sm.build_vocabulary([tw], cfg.min_count, cfg.max_vocab)
            layout = sm.layout_for(cfg, vocab)
            x = sm.frame_inputs(layout, take.duration_s, take.syllables, take.words)[:n]
            model = sm.fit_sign_model([x], [ytr], layout, cfg)
            preds[name][lo:hi] = model.decode(x[lo:hi])
            causal[name][lo:hi] = model.causal_marginals(x[lo:hi]).argmax(axis=1)
        ok = ytr[ytr >= 0]
        preds["majority"][lo:hi] = np.bincount(ok, minlength=sm.N_SIGNS).argmax()
    rows = {}
    for name, p in preds.items():
        f1 = f1_scores(y, p, sm.N_SIGNS)
        rows[name] = {"accuracy": float(np.mean(p == y)),
                      "macro_f1": float(np.mean(list(f1.values()))),
                      "f1": {sm.SIGNS[c]: round(v, 3) for c, v in f1.items()}}
        if name in causal:
            rows[name]["causal_accuracy"] = float(np.mean(causal[name] == y))
            cf = f1_scores(y, causal[name], sm.N_SIGNS)
            rows[name]["causal_macro_f1"] = float(np.mean(list(cf.values())))
    counts = np.bincount(y[y >= 0], minlength=sm.N_SIGNS)
    return {"frames": int(n), "folds": folds, "fold_edges": edges.tolist(),
            "label_counts": {sm.SIGNS[i]: int(c) for i, c in enumerate(counts) if c},
            "variants": rows}


def hits(cues, pred: np.ndarray, frame_s: float, within_s: float = 1.0) -> np.ndarray:
    """(n_cues,) whether each cue's sign is among the predicted frames from its start to
    ``within_s`` after its end."""
    from gesture_sim.inference.sign_model import SIGN_INDEX

    out = []
    for a, b, s in cues:
        k0 = int(a // frame_s)
        k1 = min(int((b + within_s) // frame_s), len(pred) - 1)
        out.append(bool(np.any(pred[k0:k1 + 1] == SIGN_INDEX[s])))
    return np.array(out, dtype=bool)


def semantic_check(model, model_nolex, takes, labels: np.ndarray, draws: int = 200,
                   seed: int = 0) -> dict:
    from gesture_sim.inference import sign_model as sm

    s = sm.N_SIGNS
    cnt = np.ones((s, s)) * 0.1
    np.add.at(cnt, (labels[:-1], labels[1:]), 1.0)
    trans = cnt / cnt.sum(axis=1, keepdims=True)
    marg = np.bincount(labels, minlength=s) + 0.1
    marg = marg / marg.sum()
    rng = np.random.default_rng(seed)
    out = {}
    tot = {"cues": 0, "model": 0, "model_causal": 0, "no_dictionary_prior": 0,
           "random": 0.0}
    for t in takes:
        lay = model.layout
        x = sm.frame_inputs(lay, t.duration_s, t.syllables, t.words)
        _, cues = sm.word_annotations(t.words)
        p = model.decode(x)
        pc = model.causal_marginals(x).argmax(axis=1)
        xn = sm.frame_inputs(model_nolex.layout, t.duration_s, t.syllables, t.words)
        pn = model_nolex.decode(xn)
        rnd = []
        for _ in range(draws):
            r = np.empty(len(p), dtype=int)
            r[0] = rng.choice(s, p=marg)
            for k in range(1, len(p)):
                r[k] = rng.choice(s, p=trans[r[k - 1]])
            rnd.append(hits(cues, r, lay.frame_s).mean() if cues else 0.0)
        h, hc, hn = (hits(cues, q, lay.frame_s) for q in (p, pc, pn))
        by_sign: dict[str, list[int]] = {}
        for (_, _, sg), ok in zip(cues, h, strict=True):
            by_sign.setdefault(sg, [0, 0])
            by_sign[sg][0] += int(ok)
            by_sign[sg][1] += 1
        out[t.name] = {"cues": len(cues), "model": float(h.mean()) if cues else None,
                       "model_causal": float(hc.mean()) if cues else None,
                       "no_dictionary_prior": float(hn.mean()) if cues else None,
                       "random_mean": float(np.mean(rnd)), "random_sd": float(np.std(rnd)),
                       "by_sign": {k: f"{a}/{b}" for k, (a, b) in sorted(by_sign.items())},
                       "predicted_counts": {sm.SIGNS[i]: int(c) for i, c in
                                            enumerate(np.bincount(p, minlength=s)) if c}}
        tot["cues"] += len(cues)
        tot["model"] += int(h.sum())
        tot["model_causal"] += int(hc.sum())
        tot["no_dictionary_prior"] += int(hn.sum())
        tot["random"] += float(np.mean(rnd)) * len(cues)
    n = max(tot["cues"], 1)
    out["all"] = {"cues": tot["cues"], "model": tot["model"] / n,
                  "model_causal": tot["model_causal"] / n,
                  "no_dictionary_prior": tot["no_dictionary_prior"] / n,
                  "random_mean": tot["random"] / n}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--library", type=Path, required=True)
    ap.add_argument("--labelled", nargs=2, type=Path, required=True, metavar=("WAV", "TG"))
    ap.add_argument("--take", nargs=2, type=Path, action="append", default=[],
                    metavar=("WAV", "TG"))
    ap.add_argument("--folds", type=int, default=4)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    from train_sign_model import take_from_library

    from gesture_sim.audio.phones import words_from_textgrid
    from gesture_sim.audio.prosody import analyze_file
    from gesture_sim.inference import sign_model as sm
    from gesture_sim.motion.library import MotionLibrary

    lib = MotionLibrary.load(args.library)
    take = take_from_library(args.labelled[0], args.labelled[1], lib)
    base = sm.SignModelSettings()
    variants = {
        "full": base,
        "prosody_only": replace(base, words=False, pos=False, lexicon=False),
        "words_only": replace(base, prosody=False),
        "full_no_dictionary_prior": replace(base, lexicon_weight=0.0),
        "full_hidden16": replace(base, hidden=(16,)),
        "full_order2": replace(base, order=2),
    }
    report = {"labelled_take": take.name, "settings": base.to_dict(),
              "cross_validation": cross_validate(take, args.folds, variants, base)}
    others = []
    for wav, tg in args.take:
        an = analyze_file(wav)
        words = [(w.start_s, w.end_s, w.text) for w in words_from_textgrid(tg)]
        others.append(sm.LabelledTake(Path(wav).stem, len(an.samples) / 16000.0,
                                      an.syllables, words, []))
    if others:
        model = sm.train_on_takes([take], base)
        nolex = sm.train_on_takes([take], replace(base, lexicon_weight=0.0))
        n = int(math.ceil(take.duration_s / base.frame_s - 1e-9))
        labels = sm.frame_labels(take.spans, n, base.frame_s, None)
        report["semantic_check"] = semantic_check(model, nolex, others, labels[labels >= 0])
    text = json.dumps(report, indent=1)
    print(text)
    if args.json is not None:
        args.json.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
