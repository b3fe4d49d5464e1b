"""The one switch ramp: a jump of the joint targets blended in over a few control steps.

A clip switch jumps the targets; the body would realise the jump at its torque limits (a snap).
:class:`SwitchRamp` blends from the last target to the new stream with a smoothstep over ``n``
control steps (the "short target ramp" docs/DESIGN.md allows; its length is a setting and its
effect is measured in BENCHMARKS.md). Used by the timing layer
(:class:`~gesture_sim.control.synchrony.SyncPlayer`) and by the methods with their own timing.
"""

from __future__ import annotations

import numpy as np


def smoothstep(x: float) -> float:
    """3x² − 2x³ of x clipped to [0, 1]."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


class SwitchRamp:
    """Blend a jump in over ``n`` control steps (0: no ramp, the raw jump).

    After :meth:`start` with the last target, the next ``n`` calls return
    ``q_from + w_k (q - q_from)`` with ``w_k = smoothstep(k / (n + 1))``, k = 1 … n; later calls
    return ``q`` itself. Vectors are (n_joints,), rad or m.
    """

    def __init__(self, n: int) -> None:
        self.n = max(int(n), 0)
        self._from: np.ndarray | None = None
        self._k = 0

    def reset(self) -> None:
        """No ramp under way."""
        self._from, self._k = None, 0

    def start(self, q_from: np.ndarray | None) -> None:
        """Ramp from ``q_from`` (the last target sent; None: nothing to ramp from)."""
        if self.n > 0 and q_from is not None:
            self._from, self._k = np.array(q_from, dtype=float), 0

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """The ramped target for this step's stream value ``q``."""
        if self._from is None:
            return q
        self._k += 1
        out = self._from + smoothstep(self._k / (self.n + 1)) * (q - self._from)
        if self._k >= self.n:
            self._from = None
        return out
