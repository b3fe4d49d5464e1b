"""Additive target layers: named joint offsets summed onto the body's target before the tracker.

One mechanism for every channel that rides on top of the chosen clip (the face and head signals
of :mod:`gesture_sim.signals.ruth`, and anything later): each layer is a set of offsets on named
actuated joints (rad for hinges, m for slides); :meth:`TargetLayers.apply` adds every layer to a
target vector q* (shape (n_act,), :data:`~gesture_sim.sim.humanoid.ACTUATED_JOINTS` order) and
clamps the joints the layers touch to their ranges, so that the same PD tracker and the same
torque limits realise them. Joints no layer touches are returned unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from gesture_sim.errors import GestureSimError
from gesture_sim.sim import humanoid as hm


@lru_cache(maxsize=1)
def _ranges() -> np.ndarray:
    """Joint ranges of :data:`~gesture_sim.sim.humanoid.ACTUATED_JOINTS`, (n_act, 2)."""
    return hm.joint_ranges(hm.load_model(scene=False))


class TargetLayers:
    """Named layers of joint offsets, summed and clamped onto a target vector.

    Args:
        ranges: (n_act, 2) joint limits (default: the humanoid's, from ``humanoid.xml``).
        margin: fraction of each touched joint's range kept free at both ends (a target exactly
            at a limit would press the joint into it).
    """

    def __init__(self, ranges: np.ndarray | None = None, margin: float = 0.01) -> None:
        self.ranges = np.asarray(_ranges() if ranges is None else ranges, dtype=float)
        if self.ranges.shape != (len(hm.ACTUATED_JOINTS), 2):
            raise GestureSimError(f"ranges must have shape ({len(hm.ACTUATED_JOINTS)}, 2)")
        span = self.ranges[:, 1] - self.ranges[:, 0]
        self._lo = self.ranges[:, 0] + margin * span
        self._hi = self.ranges[:, 1] - margin * span
        self._layers: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def define(self, name: str, joints: Sequence[str]) -> None:
        """Declare layer ``name`` acting on ``joints`` (actuated joint names); offsets start 0."""
        idx = hm.actuated_index(list(joints))
        self._layers[name] = (idx, np.zeros(len(idx)))

    def set(self, name: str, offsets: np.ndarray) -> None:
        """Set the offsets of layer ``name``, shape (len(joints),), rad or m."""
        if name not in self._layers:
            raise GestureSimError(f"unknown target layer {name!r}")
        idx, _ = self._layers[name]
        off = np.asarray(offsets, dtype=float).reshape(-1)
        if off.shape != idx.shape:
            raise GestureSimError(f"layer {name!r} takes {len(idx)} offsets, got {off.shape}")
        self._layers[name] = (idx, off.copy())

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._layers)

    def apply(self, q: np.ndarray) -> np.ndarray:
        """``q`` (n_act,) plus every layer, the touched joints clamped to range (a new array)."""
        out = np.array(q, dtype=float, copy=True)
        touched: list[np.ndarray] = []
        for idx, off in self._layers.values():
            np.add.at(out, idx, off)
            touched.append(idx)
        if touched:
            j = np.unique(np.concatenate(touched))
            out[j] = np.clip(out[j], self._lo[j], self._hi[j])
        return out
