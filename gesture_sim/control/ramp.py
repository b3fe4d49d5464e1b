"""The one switch ramp: a jump of the joint targets blended in over a few control steps.

A clip switch jumps the targets; the body would realise the jump at its torque limits (a snap).
:class:`SwitchRamp` blends from the last target to the new stream with a smoothstep over ``n``
control steps (the "short target ramp" docs/DESIGN.md allows; its length is a setting and its
effect is measured in docs/history.md). Used by the timing layer
(:class:`~gesture_sim.control.synchrony.SyncPlayer`) and by the methods with their own timing.

A ``path`` (Chiu 2014's GPDM transitions, :class:`~gesture_sim.motion.gpdm.GPDMPath`) replaces
the straight line in joint space: frame k of the ramp is ``P_k + w_k (q_k − q_1)``, ``P`` the
path's n poses from the last target to the new stream's first value ``q_1`` and ``q_k − q_1``
the new stream's own motion since then. With the straight line ``P_k = q_from + w_k (q_1 −
q_from)`` this is the ramp itself.

The pose blended from is not held still: it carries on with the velocity the targets had at
the switch, decaying (:func:`carried`; Holden's "dead blending", 2023). A held start would stop
the outgoing motion dead in one step and start the new one from rest; carried on, the targets'
velocity is continuous through the switch and the blend's weight only has to move between two
moving poses.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

#: Control steps (at 30 Hz) a switch is blended over by default: 0.5 s, as long as a gesture's
#: preparation; with the carried start it brings the jerk to real motion's level with the
#: coupling kept above random selection's (docs/history.md, "switch ramp").
DEFAULT_BLEND_FRAMES = 15

#: The time constant (s) with which the pose a switch ramp blends from carries on moving
#: (:func:`carried`): about one stroke phase's tail; 0.067–0.15 s measured alike (docs/history.md,
#: "switch ramp").
DEFAULT_CARRY_S = 0.1

#: A transition path: ``path(q_from, q_to, n)`` -> (n, D) poses strictly between the two.
TransitionPath = Callable[[np.ndarray, np.ndarray, int], np.ndarray]


def smoothstep(x: float) -> float:
    """3x² − 2x³ of x clipped to [0, 1]."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def carried(q_from: np.ndarray, v: np.ndarray | None, k: int, tau: float,
            bounds: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The pose ``q_from`` carried on ``k`` steps by the velocity ``v`` (per step) decaying
    with time constant ``tau`` (steps): ``q_from + v τ (1 − e^(−k/τ))``; ``q_from`` itself
    when there is no velocity or ``tau`` ≤ 0. Its velocity at the start is ``v``, and it comes
    to rest ``v τ`` beyond ``q_from``. ``bounds`` (lo, hi): it stays within them, or within
    ``q_from`` where that lies beyond them."""
    if v is None or tau <= 0.0:
        return q_from
    q = q_from + v * (-tau * math.expm1(-k / tau))
    if bounds is not None:
        q = np.clip(q, np.minimum(bounds[0], q_from), np.maximum(bounds[1], q_from))
    return q


class SwitchRamp:
    """Blend a jump in over ``n`` control steps (0: no ramp, the raw jump).

    After :meth:`start` with the last target (and the last step's change of the target), the
    next ``n`` calls return ``c_k + w_k (q - c_k)`` with ``w_k = smoothstep(k / (n + 1))``,
    k = 1 … n, where ``c_k`` is the last target carried on by its velocity (:func:`carried`,
    time constant ``carry_tau`` steps; 0: held still, the ramp before stop 44; within
    ``bounds``, :func:`carried`); later calls return ``q`` itself. Vectors are (n_joints,),
    rad or m.
    """

    def __init__(self, n: int, carry_tau: float = 0.0, path: TransitionPath | None = None,
                 bounds: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        self.n = max(int(n), 0)
        self.carry_tau = float(carry_tau)
        self.bounds = bounds
        self.path = path
        self._path: np.ndarray | None = None
        self._from: np.ndarray | None = None
        self._v: np.ndarray | None = None
        self._k = 0
        self._n = self.n            # this ramp's steps (``start(..., n=)``)
        self._q1: np.ndarray | None = None

    @property
    def active(self) -> bool:
        """A ramp is under way."""
        return self._from is not None

    def reset(self) -> None:
        """No ramp under way."""
        self._from, self._v, self._k = None, None, 0

    def start(self, q_from: np.ndarray | None, v_from: np.ndarray | None = None,
              n: int | None = None) -> None:
        """Ramp from ``q_from`` (the last target sent; None: nothing to ramp from), moving at
        ``v_from`` (its change over the last step; None: still), over ``n`` steps (None: the
        ramp's own ``n``)."""
        n_now = self.n if n is None else max(int(n), 0)
        if n_now > 0 and q_from is not None:
            self._n = n_now
            self._from, self._k = np.array(q_from, dtype=float), 0
            self._v = None if v_from is None else np.array(v_from, dtype=float)
            self._q1 = self._path = None

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """The ramped target for this step's stream value ``q``."""
        if self._from is None:
            return q
        self._k += 1
        c = carried(self._from, self._v, self._k, self.carry_tau, self.bounds)
        w = smoothstep(self._k / (self._n + 1))
        if self.path is not None:
            if self._path is None:
                self._q1 = np.array(q, dtype=float)
                self._path = np.asarray(self.path(self._from, self._q1, self._n), dtype=float)
            out = self._path[self._k - 1] + w * (q - self._q1)
        else:
            out = c + w * (q - c)
        if self._k >= self._n:
            self._from = self._v = None
        return out
