#!/usr/bin/env python3
"""The listener motion graph's excerpts (gesture_sim.signals.listener_graph) as a figure.

Usage (from the repository root):

    .venv/bin/python tools/listener_frames.py OUT.png [--library DIR] [--no-render]
        [--json OUT.json] [--write-cache]

Extracts the rest, nod and posture excerpts of a motion library (default: the shipped
``motion_library/default``) with the default settings and draws:

* top row, one panel per kind: every excerpt's head pitch ``neck_flex + head_flex`` (deg, > 0
  down) relative to its first frame against time (s); nods with their lowest head marked, and
  for posture shifts also the lean (lower-spine flexion) and the head tilt
  (``neck_bend + head_bend``), dashed and dotted;
* bottom (unless ``--no-render``): a frame sheet rendered on the humanoid (MuJoCo, headless),
  a side view of the head and torso: for a few excerpts of each kind the first, middle or
  lowest, and last frame, posed as the listener plays them (its rest pose plus the excerpt's
  values on the listener's joints, relative to the clip's median pose).

Prints the counts per kind (and per source clip family) and the extraction time; ``--json``
writes them. ``--write-cache`` also stores the graph as ``listener_graph.npz`` in the library
folder, which :func:`~gesture_sim.signals.listener_graph.default_listener_graph` then reads
instead of extracting (it checks the library's fingerprint).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MUJOCO_GL", "egl")

from gesture_sim import DEFAULT_LIBRARY_DIR  # noqa: E402
from gesture_sim.motion.library import MotionLibrary  # noqa: E402
from gesture_sim.signals.listener_graph import (  # noqa: E402
    CACHE_FILE,
    GRAPH_JOINTS,
    KINDS,
    ListenerGraph,
)

G = {n: i for i, n in enumerate(GRAPH_JOINTS)}
COLOURS = {"rest": "tab:green", "nod": "tab:blue", "posture": "tab:orange"}


def family(clip: str) -> str:
    """A clip's source family: the BEAT2 take or the Bandai Namco motion name."""
    if "scott" in clip:
        return "beat2_scott"
    parts = clip.split("_")
    return parts[1] if len(parts) > 1 else clip


def pitch(frames: np.ndarray) -> np.ndarray:
    return np.degrees(frames[:, G["neck_flex"]] + frames[:, G["head_flex"]])


def render_sheet(graph: ListenerGraph, per_kind: int = 4, size: tuple[int, int] = (200, 220)
                 ) -> tuple[list[np.ndarray], list[str]]:
    """Side views of the head and torso at the first, key and last frame of ``per_kind``
    excerpts of each kind (spread over the list)."""
    import mujoco

    from gesture_sim.sim import humanoid as hm

    model = hm.load_model(scene=True)
    data = mujoco.MjData(model)
    w, h = size
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, w)
    model.vis.global_.offheight = max(model.vis.global_.offheight, h)
    base = hm.qpos_from_targets(model, np.zeros(len(hm.ACTUATED_JOINTS)))
    adr = hm.qpos_addresses(model)[hm.actuated_index(GRAPH_JOINTS)]
    head = model.body("head").id if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY,
                                                       "head") >= 0 else 0
    renderer = mujoco.Renderer(model, height=h, width=w)
    cam = mujoco.MjvCamera()
    cam.azimuth, cam.elevation, cam.distance = 90.0, -5.0, 0.6
    images, labels = [], []
    try:
        for kind in KINDS:
            idx = graph.of_kind(kind)
            pick = idx[np.linspace(0, len(idx) - 1, min(per_kind, len(idx))).astype(int)] \
                if len(idx) else []
            for k in pick:
                ex = graph.excerpts[int(k)]
                for tag, f in (("first", 0), ("key", ex.peak), ("last", ex.n_frames - 1)):
                    data.qpos[:] = base
                    data.qpos[adr] = ex.frames[f]
                    mujoco.mj_forward(model, data)
                    cam.lookat[:] = data.xpos[head] - np.array([0.0, 0.0, -0.08])
                    renderer.update_scene(data, camera=cam)
                    images.append(renderer.render().copy())
                    p = pitch(ex.frames[f:f + 1])[0] - pitch(ex.frames[:1])[0]
                    labels.append(f"{kind} #{int(k)} {tag}\n{family(ex.clip)} "
                                  f"{f / graph.fps:.2f}s {p:+.1f}deg")
    finally:
        renderer.close()
    return images, labels


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", help="the PNG to write")
    ap.add_argument("--library", default=str(DEFAULT_LIBRARY_DIR))
    ap.add_argument("--no-render", action="store_true", help="curves only, no frame sheet")
    ap.add_argument("--json", help="write the counts here")
    ap.add_argument("--write-cache", action="store_true",
                    help=f"store the graph as {CACHE_FILE} in the library folder")
    a = ap.parse_args(argv)

    lib = MotionLibrary.load(a.library)
    t0 = time.perf_counter()
    graph = ListenerGraph.from_library(lib)
    t_extract = time.perf_counter() - t0
    counts = graph.counts()
    fams = {k: dict(Counter(family(graph.excerpts[i].clip) for i in graph.of_kind(k)))
            for k in KINDS}
    edges = graph.edges()
    report = {"library": a.library, "fingerprint": lib.fingerprint, "counts": counts,
              "by_source": fams, "extract_s": round(t_extract, 4),
              "cut_points": int(edges.sum()),
              "durations_s": {k: [round((graph.excerpts[i].n_frames - 1) / graph.fps, 3)
                                  for i in graph.of_kind(k)] for k in KINDS}}
    print(f"excerpts {counts}  (extraction {t_extract * 1000:.0f} ms, "
          f"{int(edges.sum())} cut points within theta)")
    for k in KINDS:
        print(f"  {k:8s} {fams[k]}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    images, labels = ([], []) if a.no_render else render_sheet(graph)
    rows = 2 if images else 1
    fig = plt.figure(figsize=(15, 4.2 * rows + (2.5 if images else 0)))
    gs = fig.add_gridspec(rows, 3, height_ratios=[1, 1.6] if images else [1])
    for j, kind in enumerate(KINDS):
        ax = fig.add_subplot(gs[0, j])
        for i in graph.of_kind(kind):
            ex = graph.excerpts[i]
            tt = np.arange(ex.n_frames) / graph.fps
            p = pitch(ex.frames) - pitch(ex.frames[:1])[0]
            ax.plot(tt, p, color=COLOURS[kind], lw=1, alpha=0.7)
            if kind == "nod":
                ax.plot(tt[ex.peak], p[ex.peak], "k.", ms=4)
            if kind == "posture":
                f = ex.frames - ex.frames[:1]
                ax.plot(tt, np.degrees(f[:, G["lower_spine_flex"]]), color="tab:red", lw=0.8,
                        ls="--", alpha=0.6)
                ax.plot(tt, np.degrees(f[:, G["neck_bend"]] + f[:, G["head_bend"]]),
                        color="tab:purple", lw=0.8, ls=":", alpha=0.7)
        ax.axhline(0, color="0.6", lw=0.5)
        extra = " (pitch solid, lean dashed, tilt dotted)" if kind == "posture" else ""
        ax.set_title(f"{kind}: {counts[kind]} excerpts{extra}", fontsize=10)
        ax.set_xlabel("time from the excerpt's start (s)")
        ax.set_ylabel("head pitch from start (deg, + down)" if j == 0 else "deg")
    if images:
        from gesture_sim.motion.preview import contact_sheet

        sheet = contact_sheet(images, labels, columns=12)
        ax = fig.add_subplot(gs[1, :])
        ax.imshow(sheet)
        ax.set_axis_off()
        ax.set_title("frames as the listener plays them (side view; first / key / last)",
                     fontsize=10)
    fig.suptitle(f"listener motion graph of {Path(a.library).name}: real excerpts "
                 f"(fingerprint {lib.fingerprint})", fontsize=11)
    fig.tight_layout()
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, dpi=90)
    print(f"wrote {a.out}")
    if a.json:
        Path(a.json).write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    if a.write_cache:
        path = Path(a.library) / CACHE_FILE
        graph.save(path)
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
