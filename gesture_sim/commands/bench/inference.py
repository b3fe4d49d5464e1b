"""``gesture-sim bench inference``: cost of one inference step (CRF, DCNF, Levine 2009 filters).

Times, on one core after a warm-up, (a) the CRF forward step alone (memberships of the window
given), (b) the full run-time step of :class:`~gesture_sim.inference.model.GestureFilter`
(held syllable features, cluster memberships, CRF step) on a synthetic syllable stream (one
syllable about every 0.2 s), (c) the Levine 2009 baseline's step and, when the model has a
DCNF (Chiu 2014), (d) its forward step alone (network + pair update, input given) and (e) its
full run-time step. Uses ``--model`` or the default model; without one, a random model of the
given size (with a DCNF).
"""

from __future__ import annotations

import argparse
import time

from gesture_sim import DEFAULT_LIBRARY_DIR
from gesture_sim.commands import print_json

#: The shipped default model.
DEFAULT_MODEL = DEFAULT_LIBRARY_DIR / "model"


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "inference", help="time per inference step (CRF filter, baseline), microseconds",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    parser.add_argument("--model", metavar="FOLDER",
                        help=f"model folder (default: {DEFAULT_MODEL} if present, else random)")
    parser.add_argument("--random", action="store_true", help="use a random model")
    parser.add_argument("--states", type=int, default=8, help="random model: states")
    parser.add_argument("--clusters", type=int, default=8, help="random model: clusters")
    parser.add_argument("--window", type=int, default=4, help="random model: window")
    parser.add_argument("--steps", type=int, default=20000, help="timed steps per measurement")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=run)


def random_model(n_states: int, n_clusters: int, window: int, seed: int = 0,
                 with_dcnf: bool = False, hidden: tuple[int, ...] = (32, 16)):
    """A GestureModel with random (valid) parameters, for timing and tests.

    ``with_dcnf`` adds a second-order DCNF of the given hidden sizes over the same window.
    """
    import numpy as np

    from gesture_sim.contracts import Syllable
    from gesture_sim.inference.clusters import ProsodyClusters
    from gesture_sim.inference.crf import RemappedCRF
    from gesture_sim.inference.features import StepSettings
    from gesture_sim.inference.hmm import KinematicHMM
    from gesture_sim.inference.levine09 import N_SYMBOLS, Discretiser, Levine09Model
    from gesture_sim.inference.model import GestureModel
    from gesture_sim.inference.normalize import SpeakerNormalizer

    rng = np.random.default_rng(seed)
    s, k = n_states, n_clusters
    trans = rng.dirichlet(np.ones(s), size=s)
    hmm = KinematicHMM(np.full(s, 1.0 / s), trans, rng.normal(size=(s, 6)),
                       np.repeat(np.eye(6)[None] * 0.3, s, axis=0))
    clusters = ProsodyClusters(np.full(k, 1.0 / k), rng.normal(size=(k, 3)),
                               np.repeat(np.eye(3)[None] * 0.5, k, axis=0))
    crf = RemappedCRF(rng.normal(size=(s, s)), rng.normal(size=(s, window, k)))
    l09_trans = rng.dirichlet(np.ones(2 * s), size=2 * s)
    l09_trans[s:, s:] = 0.0
    l09_trans /= l09_trans.sum(axis=1, keepdims=True)
    baseline = Levine09Model(
        l09_trans, rng.dirichlet(np.ones(N_SYMBOLS), size=2 * s), np.tile([1.0, 2.0], (s, 1)),
        np.full(s, 0.6), Discretiser.fit_stats([Syllable(0, 0.2, 0.25, 150.0, 70.0, True)] * 3),
        0.5)
    dcnf = None
    if with_dcnf:
        from gesture_sim.inference.dcnf import N_BASE, DCNFSettings, init_dcnf

        d = N_BASE + k
        dcnf = init_dcnf(d, s, DCNFSettings(window=window, hidden=hidden, seed=seed),
                         np.zeros(d), np.ones(d))
        dcnf = dcnf.with_flat(rng.normal(0.0, 0.5, size=dcnf.flat().size))
    return GestureModel(hmm, clusters, crf, StepSettings(), SpeakerNormalizer().to_dict(),
                        {"names": list("TDVACH"), "B": [1.0] * 6, "W": [1.0] * 6},
                        "random", baseline=baseline, dcnf=dcnf)


def _syllable_stream(n_steps: int, rate: float):
    import numpy as np

    from gesture_sim.contracts import Syllable

    rng = np.random.default_rng(1)
    per_step: list[list] = [[] for _ in range(n_steps)]
    t = 0.1
    while True:
        length = rng.uniform(0.1, 0.3)
        emitted = t + length + 0.05
        step = int(np.ceil(emitted * rate))
        if step >= n_steps:
            break
        voiced = rng.random() < 0.8
        per_step[step].append(Syllable(t, t + length, emitted,
                                       float(rng.uniform(90, 250)) if voiced else None,
                                       float(rng.normal(70, 6)), voiced))
        t += length + rng.uniform(0.0, 0.4)
    return per_step


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from gesture_sim.inference.model import GestureModel

    folder = None if args.random else (args.model or (DEFAULT_MODEL if (
        DEFAULT_MODEL / "model.json").is_file() else None))
    if folder is not None:
        model = GestureModel.load(folder)
        source = str(folder)
    else:
        model = random_model(args.states, args.clusters, args.window, with_dcnf=True)
        source = "random"
    try:
        import os

        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    except (AttributeError, OSError):
        pass
    n = args.steps
    rate = model.settings.rate_hz
    rng = np.random.default_rng(0)
    windows = rng.dirichlet(np.ones(model.clusters.n_clusters), size=(n, model.crf.window))
    stream = _syllable_stream(n, rate)
    results = {}

    def timed(name: str, fn) -> None:
        fn(min(n, 500))                          # warm-up
        t0 = time.perf_counter()
        fn(n)
        results[name] = (time.perf_counter() - t0) / n * 1e6

    def crf_only(m: int) -> None:
        f = model.crf.new_filter(model.pad_membership)
        for i in range(m):
            f.step(windows[i])

    def full(m: int) -> None:
        f = model.new_filter()
        for i in range(m):
            f.step(i / rate, stream[i])

    timed("crf_step_us", crf_only)
    timed("crf_full_step_us", full)
    if model.baseline is not None:
        def baseline(m: int) -> None:
            f = model.new_filter("levine09")
            for i in range(m):
                f.step(i / rate, stream[i])

        timed("levine09_step_us", baseline)
    if model.dcnf is not None:
        d_inputs = rng.normal(size=(n, model.dcnf.n_inputs))

        def dcnf_only(m: int) -> None:
            f = model.dcnf.new_filter(model.dcnf_pad)
            for i in range(m):
                f.step(d_inputs[i])

        def dcnf_full(m: int) -> None:
            f = model.new_filter("dcnf")
            for i in range(m):
                f.step(i / rate, stream[i])

        timed("dcnf_step_us", dcnf_only)
        timed("dcnf_full_step_us", dcnf_full)
    out = {"model": source, "states": model.n_states, "clusters": model.clusters.n_clusters,
           "window": model.crf.window, "rate_hz": rate, "steps": n,
           "dcnf": model.dcnf.meta() if model.dcnf is not None else None,
           **{k: round(v, 2) for k, v in results.items()},
           "budget_us_per_step": round(1e6 / rate, 1)}
    if args.json:
        print_json(out)
        return 0
    print(f"inference step cost ({source}: S={out['states']}, K={out['clusters']}, "
          f"W={out['window']}, {n} steps, one core)")
    for k, v in results.items():
        print(f"  {k[:-3]:<18} {v:8.1f} us")
    print(f"  (one control step at {rate:g} Hz lasts {out['budget_us_per_step']:.0f} us)")
    return 0
