"""Copy the Unitree G1 and H1 MuJoCo models into ``assets/robots/``, meshes simplified for size.

Source: a copy of Unitree's ``unitree_mujoco`` robot folders (BSD 3-Clause), given as ``--src``.
The MJCF files are copied unchanged; every binary STL mesh they load is simplified by vertex
clustering (vertices snapped to a cubic grid and merged, degenerate triangles dropped), the grid
cell of each mesh grown until it has at most ``--max-faces`` triangles. MuJoCo collides a mesh
through its convex hull, which the clustering moves by at most half a grid cell (the cell is
reported per mesh). Run once, by hand::

    python tools/ship_robots.py --src UNITREE_ROBOTS_DIR --dst assets/robots
"""

from __future__ import annotations

import argparse
import shutil
import struct
from pathlib import Path

import numpy as np

ROBOTS = {"unitree_g1": ("g1_29dof.xml", "scene_29dof.xml", "g1_joint_index_dds.md"),
          "unitree_h1": ("h1.xml", "scene.xml")}


def read_stl(path: Path) -> np.ndarray:
    """Triangles of a binary STL, (F, 3, 3) float32 (m)."""
    raw = path.read_bytes()
    n = struct.unpack("<I", raw[80:84])[0]
    rec = np.frombuffer(raw[84:84 + 50 * n], dtype=np.dtype(
        [("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    return rec["v"].astype(np.float64)


def write_stl(path: Path, tris: np.ndarray) -> None:
    """Write (F, 3, 3) triangles as a binary STL with their face normals."""
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    nrm = np.cross(e1, e2)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    rec = np.zeros(len(tris), dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)),
                                              ("a", "<u2")]))
    rec["n"], rec["v"] = nrm, tris
    path.write_bytes(b"simplified by gesture_sim tools/ship_robots.py".ljust(80, b" ")
                     + struct.pack("<I", len(tris)) + rec.tobytes())


def cluster(tris: np.ndarray, cell: float) -> np.ndarray:
    """Vertex clustering: snap to a ``cell`` (m) grid, each cluster at its vertices' mean."""
    v = tris.reshape(-1, 3)
    key = np.floor(v / cell).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    cnt = np.bincount(inv)
    mean = np.stack([np.bincount(inv, weights=v[:, k]) / cnt for k in range(3)], axis=1)
    f = inv.reshape(-1, 3)
    ok = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    f = np.unique(np.sort(f[ok], axis=1), axis=0, return_index=True)[1]
    kept = inv.reshape(-1, 3)[ok][np.sort(f)]
    return mean[kept]


def simplify(tris: np.ndarray, max_faces: int) -> tuple[np.ndarray, float]:
    """The finest clustering (cell grown by 15 % steps from 1 mm) with at most ``max_faces``."""
    if len(tris) <= max_faces:
        return tris, 0.0
    cell = 0.001
    while True:
        out = cluster(tris, cell)
        if len(out) <= max_faces:
            return out, cell
        cell *= 1.15


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--src", type=Path, required=True)
    ap.add_argument("--dst", type=Path, required=True)
    ap.add_argument("--max-faces", type=int, default=1500)
    args = ap.parse_args()
    args.dst.mkdir(parents=True, exist_ok=True)
    shutil.copy2(args.src / "LICENSE.unitree_mujoco", args.dst / "LICENSE.unitree_mujoco")
    for robot, files in ROBOTS.items():
        src, dst = args.src / robot, args.dst / robot
        dst.mkdir(parents=True, exist_ok=True)
        for f in files:
            shutil.copy2(src / f, dst / f)
        for mesh_dir in ("meshes", "assets"):
            if not (src / mesh_dir).is_dir():
                continue
            (dst / mesh_dir).mkdir(exist_ok=True)
            for stl in sorted((src / mesh_dir).glob("*.STL")):
                tris = read_stl(stl)
                out, cell = simplify(tris, args.max_faces)
                write_stl(dst / mesh_dir / stl.name, out)
                print(f"{robot}/{mesh_dir}/{stl.name}: {len(tris)} -> {len(out)} faces, "
                      f"cell {1000 * cell:.1f} mm")


if __name__ == "__main__":
    main()
