"""Humanoid poses the export tests write out: shipped library clips and random poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.sim import humanoid as hm

LIBRARY = Path(__file__).resolve().parents[2] / "motion_library" / "default" / "library.npz"


def library_qpos(model, clip: int, n: int) -> np.ndarray:
    """``n`` frames (30 fps) of a shipped library clip as full qpos rows (root included)."""
    z = np.load(LIBRARY)
    a = int(z["clip_offsets"][clip])
    qpos = np.zeros((n, model.nq))
    qpos[:, 0:3] = z["root_pos"][a:a + n]
    qpos[:, 3:7] = z["root_quat"][a:a + n]
    qpos[:, hm.qpos_addresses(model, library_joints())] = z["qpos"][a:a + n]
    return qpos


def library_joints() -> list[str]:
    """The shipped library's joint columns (the humanoid may have joints added since)."""
    import json

    return json.loads((LIBRARY.parent / "manifest.json").read_text())["joint_names"]


def random_qpos(model, n: int, seed: int = 0) -> np.ndarray:
    """Poses anywhere in the joint ranges, any root orientation."""
    rng = np.random.default_rng(seed)
    qpos = np.zeros((n, model.nq))
    ranges = hm.joint_ranges(model)
    qpos[:, hm.qpos_addresses(model)] = rng.uniform(ranges[:, 0], ranges[:, 1], (n, len(ranges)))
    qpos[:, 0:3] = rng.normal(0.0, 0.3, (n, 3)) + [0, 0, 0.9]
    qpos[:, 3:7] = np.roll(Rotation.random(n, random_state=seed).as_quat(), 1, axis=1)
    return qpos


def heading_relative(root_pos: np.ndarray, root_quat: np.ndarray, points: np.ndarray
                     ) -> np.ndarray:
    """Points (T, K, 3) relative to the pelvis (``root_pos`` (T, 3), ``root_quat`` (T, 4) w x y
    z), in its heading frame (yaw removed)."""
    mats = Rotation.from_quat(np.roll(root_quat, -1, axis=1)).as_matrix()
    fwd = mats[:, :, 0].copy()
    fwd[:, 2] = 0.0
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    left = np.stack([-fwd[:, 1], fwd[:, 0], np.zeros(len(fwd))], axis=1)
    frames = np.stack([fwd, left, np.tile([0.0, 0.0, 1.0], (len(fwd), 1))], axis=1)
    return np.einsum("tab,tkb->tka", frames, points - root_pos[:, None])
