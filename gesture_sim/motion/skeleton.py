"""The common skeleton-motion structure produced by every motion reader (BVH, SMPL-X).

Coordinates are those of the source file (BVH files are usually Y-up) but lengths are in metres:
readers convert units. Retargeting (:mod:`gesture_sim.motion.retarget`) handles the axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class SkeletonMotion:
    """A skeleton and its motion, with forward kinematics already done.

    Attributes:
        names: joint names, length J. End Sites of a BVH appear as leaf joints named
            ``<parent>_End`` (their local rotation is the identity).
        parents: (J,) int, index of each joint's parent, -1 for the root; parents precede children.
        offsets: (J, 3) float, rest offset of each joint from its parent (m, parent frame).
        local_rotations: (T, J, 3, 3) float, rotation of each joint relative to its parent frame.
        positions: (T, J, 3) float, global joint positions (m).
        rotations: (T, J, 3, 3) float, global joint orientations (rotation matrices).
        fps: frames per second.
        source: path or description of where the motion came from.
        unit_scale: the factor that converted the file's length unit to metres.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    local_rotations: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray
    fps: float
    source: str = ""
    unit_scale: float = 1.0

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.positions.shape[0])

    @property
    def duration(self) -> float:
        """Length of the motion (s)."""
        return self.n_frames / self.fps

    def index(self, name: str) -> int:
        """Index of the joint called ``name`` (KeyError if absent)."""
        return self.names.index(name)


def forward_kinematics(
    parents: np.ndarray, translations: np.ndarray, local_rotations: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Global positions and rotations of a joint tree, vectorised over frames.

    Args:
        parents: (J,) parent indices, -1 for a root; every parent precedes its children.
        translations: (T, J, 3) translation of each joint in its parent's frame (m); for a root,
            its global position.
        local_rotations: (T, J, 3, 3) rotation of each joint relative to its parent.

    Returns:
        positions (T, J, 3) and rotations (T, J, 3, 3), global.
    """
    n_frames, n_joints = translations.shape[:2]
    positions = np.empty((n_frames, n_joints, 3))
    rotations = np.empty((n_frames, n_joints, 3, 3))
    for j in range(n_joints):
        p = parents[j]
        if p < 0:
            positions[:, j] = translations[:, j]
            rotations[:, j] = local_rotations[:, j]
        else:
            positions[:, j] = positions[:, p] + np.einsum(
                "tab,tb->ta", rotations[:, p], translations[:, j])
            rotations[:, j] = rotations[:, p] @ local_rotations[:, j]
    return positions, rotations


def resample(motion: SkeletonMotion, fps: float) -> SkeletonMotion:
    """The motion resampled to ``fps`` (Hz) over the same time span.

    Positions are interpolated linearly; rotations (local and global) by normalised linear
    interpolation of quaternions (sign-aligned), which at mocap rates equals slerp closely.
    """
    if abs(motion.fps - fps) < 1e-9 * fps:
        return motion
    from scipy.spatial.transform import Rotation

    n_src = motion.n_frames
    n_dst = max(1, int(np.floor((n_src - 1) * fps / motion.fps + 1e-9)) + 1)
    t = np.arange(n_dst) * motion.fps / fps                  # fractional source frame index
    i0 = np.clip(np.floor(t).astype(int), 0, n_src - 1)
    i1 = np.minimum(i0 + 1, n_src - 1)
    w = (t - i0)[:, None, None]

    def lerp(x: np.ndarray) -> np.ndarray:
        return x[i0] * (1 - w) + x[i1] * w

    def rot_lerp(mats: np.ndarray) -> np.ndarray:
        n_j = mats.shape[1]
        q = Rotation.from_matrix(mats.reshape(-1, 3, 3)).as_quat().reshape(n_src, n_j, 4)
        q0, q1 = q[i0], q[i1]
        q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
        qi = q0 * (1 - w) + q1 * w
        qi /= np.linalg.norm(qi, axis=-1, keepdims=True)
        return Rotation.from_quat(qi.reshape(-1, 4)).as_matrix().reshape(n_dst, n_j, 3, 3)

    return SkeletonMotion(
        names=motion.names, parents=motion.parents, offsets=motion.offsets,
        local_rotations=rot_lerp(motion.local_rotations), positions=lerp(motion.positions),
        rotations=rot_lerp(motion.rotations), fps=float(fps), source=motion.source,
        unit_scale=motion.unit_scale,
    )
