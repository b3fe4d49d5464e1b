"""``gesture-sim library graph LIBRARY [-o FILE] [--plot PNG]``: build MIMiC's motion graph.

Registered under ``library`` by :func:`register_graph` (called from
:mod:`gesture_sim.commands.library`). The graph (:mod:`gesture_sim.control.mimic`) is written
next to the library (``LIBRARY/mimic_graph.npz``) unless ``-o`` says otherwise; ``--plot``
draws the cut points and medoids in the first two principal components with the strongest
transitions, beside the Markov matrix.
"""

from __future__ import annotations

import argparse

from gesture_sim.commands import print_json


def register_graph(lsub: argparse._SubParsersAction) -> None:
    """Add the ``graph`` action to the ``library`` subparsers."""
    g = lsub.add_parser(
        "graph", help="build the MIMiC motion graph of a library",
        description="Cut points, k-medoid clusters, Markov matrix and pose/velocity density "
                    "of a library (Okwechime 2011), saved next to the library.")
    g.add_argument("folder", metavar="LIBRARY", help="library folder")
    g.add_argument("-o", "--output", metavar="FILE",
                   help="graph file to write (default: LIBRARY/mimic_graph.npz)")
    g.add_argument("--plot", metavar="PNG", help="also draw the graph into this PNG")
    g.add_argument("--clusters", type=int, default=None,
                   help="number of k-medoid clusters N_c (default: subsequences / 3.5)")
    g.add_argument("--alpha", type=float, default=None,
                   help="kernel width factor (default: chosen by cross-validation; thesis 0.25)")
    g.add_argument("--seed", type=int, default=0, help="k-medoids seed (default 0)")
    g.add_argument("--json", action="store_true", help="print the summary as JSON")
    g.set_defaults(func=run_graph)


def run_graph(args: argparse.Namespace) -> int:
    from pathlib import Path

    from gesture_sim import validation as v

    folder = v.input_folder("LIBRARY", args.folder, "library folder")
    if args.clusters is not None:
        v.integer("--clusters", args.clusters, 2, 10000)
    if args.alpha is not None:
        v.number("--alpha", args.alpha, 0.0, 100.0, lo_open=True)
    v.seed("--seed", args.seed)
    from gesture_sim.control.mimic import GRAPH_FILE

    out = Path(args.output) if args.output else Path(folder) / GRAPH_FILE
    out_path, plot_path = v.check_outputs(
        [v.Output("-o/--output", out, (".npz",)),
         v.Output("--plot", args.plot, v.PNG_EXTENSIONS) if args.plot else None],
        inputs=[folder / name for name in ("library.npz", "manifest.json", "model")])

    from gesture_sim.control.inputs import ControlLibrary
    from gesture_sim.control.mimic import build_graph
    from gesture_sim.motion.library import MotionLibrary

    lib = ControlLibrary.from_motion_library(MotionLibrary.load(folder))
    graph = build_graph(lib, n_clusters=args.clusters,
                        alpha="cv" if args.alpha is None else args.alpha, seed=args.seed)
    from gesture_sim.fileio import atomic_outputs

    # the graph and its figure are published together: a failed or interrupted figure leaves
    # the previous graph file as it was
    with atomic_outputs(out_path, plot_path) as (tmp_graph, tmp_plot):
        graph.save(tmp_graph)
        if tmp_plot is not None:
            plot_graph(graph, tmp_plot)
    m = graph.meta
    summary = {"graph": str(out_path), "library_fingerprint": m["library_fingerprint"],
               "graph_fingerprint": m["graph_fingerprint"], "clusters": m["n_clusters"],
               "subsequences": m["n_subsequences"], "cut_points": m["n_cut_points"],
               "pca_dims": m["pca_dims"], "pca_energy": round(m["pca_energy"], 4),
               "alpha": m["alpha"], "kernels": m["kernels"], "build_s": round(m["build_s"], 3),
               "plot": str(plot_path) if plot_path else None}
    if args.json:
        print_json(summary)
        return 0
    print(f"{summary['subsequences']} subsequences, {summary['clusters']} clusters, "
          f"{summary['pca_dims']} PCA dims ({100 * m['pca_energy']:.1f} % energy), kernel width "
          f"alpha {m['alpha']:g}, built in {m['build_s']:.2f} s -> {out_path} "
          f"(fingerprint {m['graph_fingerprint']})")
    if plot_path is not None:
        print(f"figure -> {plot_path}")
    return 0


def plot_graph(graph, path, top: int = 40) -> None:
    """Draw ``graph``: cut points and medoids in PC1/PC2 with the ``top`` strongest observed
    transitions (width ∝ probability), and the Markov matrix."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from gesture_sim.fileio import atomic_path

    pool = np.nonzero(graph.pool)[0]
    pts = graph.start_pose[pool, :2]
    cl = graph.start_cluster[pool]
    med = graph.medoids[:, :2]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 5.6))
    cmap = plt.get_cmap("tab20")
    ax.scatter(pts[:, 0], pts[:, 1], c=[cmap(c % 20) for c in cl], s=18, alpha=0.7)
    p = graph.markov
    observed = np.argwhere(graph.counts > 0)
    order = observed[np.argsort(-p[observed[:, 0], observed[:, 1]])][:top]
    for i, j in order:
        if i == j:
            ax.scatter(*med[i], s=300 * p[i, j], facecolors="none", edgecolors="0.3")
            continue
        ax.annotate("", xy=med[j], xytext=med[i],
                    arrowprops={"arrowstyle": "-|>", "lw": 0.5 + 4 * p[i, j], "color": "0.3",
                                "alpha": 0.8, "shrinkA": 6, "shrinkB": 6})
    ax.scatter(med[:, 0], med[:, 1], c=[cmap(c % 20) for c in range(len(med))], s=90,
               marker="s", edgecolors="k", zorder=3)
    for c, (x, y) in enumerate(med):
        ax.annotate(str(c), (x, y), textcoords="offset points", xytext=(5, 5), fontsize=8)
    ax.set_xlabel("PC 1")
    ax.set_ylabel("PC 2")
    ax.set_title(f"cut points (dots) and medoids (squares); {len(order)} strongest transitions")
    im = bx.imshow(p, cmap="viridis", vmin=0, vmax=1)
    bx.set_xlabel("next cluster")
    bx.set_ylabel("cluster")
    bx.set_title("Markov matrix P(next | current), smoothed")
    fig.colorbar(im, ax=bx, fraction=0.046)
    m = graph.meta
    fig.suptitle(f"MIMiC graph: {m['n_subsequences']} subsequences, {m['n_clusters']} clusters, "
                 f"{m['pca_dims']} PCA dims, alpha {m['alpha']:g}")
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
