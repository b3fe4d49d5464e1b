"""``gesture-sim eval inference``: the paper's Figure 4 on held-out data.

Trains the prosody clusters and the kinematic HMM on the training part, then for each input
window W the remapped CRF and a remapped generative HMM over the same windowed inputs, and
prints their log-likelihood per time step on the test part (see
:mod:`gesture_sim.inference.evaluate`); ``--dcnf`` adds the DCNF of Chiu 2014. With ``--pair``
only, the last 30 % of each pair is
held out; with ``--test-pair``, the pairs given there are the test set.
"""

from __future__ import annotations

import argparse

from gesture_sim.commands import print_json


def register(modes: argparse._SubParsersAction) -> None:
    from gesture_sim.commands.train import add_pair_arguments

    parser = modes.add_parser(
        "inference", help="held-out likelihood per step, remapped CRF vs HMM, windows 1-5",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    add_pair_arguments(parser)
    parser.add_argument("--test-pair", nargs=2, action="append", metavar=("MOTION", "AUDIO"),
                        help="score on this pair instead of holding out the last 30 %%")
    parser.add_argument("--states", type=int, metavar="N",
                        help="hidden states (default: chosen by held-out HMM likelihood)")
    parser.add_argument("--clusters", type=int, default=8, metavar="K")
    parser.add_argument("--windows", type=int, nargs="+", default=[1, 2, 3, 4, 5], metavar="W",
                        help="input windows to score (default 1 2 3 4 5; 0 = no prosody "
                        "input, transitions only: the floor prosody must beat)")
    parser.add_argument("--held-out", type=float, default=0.3, metavar="FRACTION",
                        help="held-out share of each pair without --test-pair (default 0.3)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dcnf", action="store_true",
                        help="add the DCNF (Chiu 2014) row: sigmoid network + 2nd-order chain")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from gesture_sim.commands.train import check_pair_durations, load_pairs
    from gesture_sim.errors import GestureSimError
    from gesture_sim.inference.clusters import fit_clusters
    from gesture_sim.inference.dcnf import DCNFSettings
    from gesture_sim.inference.evaluate import figure4
    from gesture_sim.inference.features import StepSettings
    from gesture_sim.inference.hmm import choose_n_states, fit_hmm
    from gesture_sim.inference.normalize import SpeakerNormalizer
    from gesture_sim.inference.train import prepare_takes, split_held_out
    from gesture_sim.motion.kinematics import fit_normalisation
    from gesture_sim.progress import progress

    if not 0.05 <= args.held_out <= 0.9:
        raise GestureSimError(f"--held-out must be in 0.05..0.9, got {args.held_out}")
    if any(w < 0 or w > 16 for w in args.windows):
        raise GestureSimError("--windows must be between 0 and 16")
    steps = StepSettings()
    show = not args.json
    train_takes = load_pairs(args.pair, enabled=show)
    check_pair_durations(train_takes, args.pair)
    test_takes = load_pairs(args.test_pair, enabled=show) if args.test_pair else []
    if test_takes:
        check_pair_durations(test_takes, args.test_pair)
    cut_s = None
    if not test_takes:
        cut_s = [t.duration_s * (1.0 - args.held_out) for t in train_takes]
        seed_syllables = [s for t, c in zip(train_takes, cut_s, strict=True)
                          for s in t.syllables if s.t_emitted < c]
    else:
        seed_syllables = [s for t in train_takes for s in t.syllables]
    if len(seed_syllables) < 20:
        used = sum(cut_s) if cut_s is not None else sum(t.duration_s for t in train_takes)
        raise GestureSimError(
            f"the training part of --pair has {len(seed_syllables)} syllables of speech in "
            f"{used:.1f} s (motion and speech overlap, less the held-out share); at least 20 "
            "are needed: give longer pairs")
    seed = SpeakerNormalizer.from_syllables(seed_syllables).to_dict()
    norm = fit_normalisation(np.concatenate([t.motion.raw_params for t in train_takes]))
    prepared = prepare_takes(train_takes, steps, seed, norm)
    if test_takes:
        train = [(p.x, p.y) for p in prepared]
        test = [(p.x, p.y) for p in prepare_takes(test_takes, steps, seed, norm)]
    else:
        xs_tr, xs_te = split_held_out([p.x for p in prepared], args.held_out)
        ys_tr, ys_te = split_held_out([p.y for p in prepared], args.held_out)
        train, test = list(zip(xs_tr, ys_tr, strict=True)), list(zip(xs_te, ys_te, strict=True))
    clusters = fit_clusters(np.concatenate([x for x, _ in train]), args.clusters, seed=args.seed)
    ys = [y for _, y in train]
    curve = {}
    if args.states is None:
        inner_tr, inner_ho = split_held_out(ys, 0.25)
        n_states, curve = choose_n_states(inner_tr, inner_ho, (3, 4, 5, 6, 8, 10), n_restarts=2,
                                          seed=args.seed)
    else:
        n_states = args.states
    hmm, _ = fit_hmm(ys, n_states, seed=args.seed)
    bar = progress(total=len(args.windows), desc="windows", enabled=show, unit="window")
    rows = figure4(hmm, clusters, clusters.membership(steps.silence()), train, test,
                   windows=args.windows, on_window=lambda _w: bar.update(1),
                   dcnf=DCNFSettings(seed=args.seed) if args.dcnf else None, steps=steps)
    bar.close()
    n_train = sum(len(y) for y in ys)
    n_test = sum(len(y) for _, y in test)
    result = {
        "states": n_states, "clusters": args.clusters, "train_steps": n_train,
        "test_steps": n_test, "uniform_loglik_per_step": float(-np.log(n_states)),
        "protocol": "test pairs" if test_takes else f"last {args.held_out:.0%} held out",
        "state_curve": {str(k): (v if np.isfinite(v) else None) for k, v in curve.items()},
        "rows": [r.to_dict() for r in rows],
    }
    if args.json:
        print_json(result)
        return 0
    print(f"held-out likelihood per time step ({result['protocol']}; {n_train} training "
          f"steps, {n_test} test steps; S={n_states}, K={args.clusters}; "
          f"uniform guess = {np.exp(result['uniform_loglik_per_step']):.3f})")
    extra = f"  {'DCNF log':>9} {'DCNF lik':>8}" if args.dcnf else ""
    print(f"{'window':>6}  {'CRF log':>9} {'CRF lik':>8}  {'HMM log':>9} {'HMM lik':>8}{extra}")
    for r in rows:
        extra = (f"  {r.dcnf_loglik:9.3f} {np.exp(r.dcnf_loglik):8.3f}"
                 if r.dcnf_loglik is not None else "")
        print(f"{r.window:>6}  {r.crf_loglik:9.3f} {np.exp(r.crf_loglik):8.3f}  "
              f"{r.hmm_loglik:9.3f} {np.exp(r.hmm_loglik):8.3f}{extra}")
    return 0
