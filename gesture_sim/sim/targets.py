"""Target streams: interpolation of a control-rate stream to the physics rate, and the shaper.

A target stream is q*(t) over :data:`gesture_sim.sim.humanoid.ACTUATED_JOINTS`, sampled at the
control rate (typically 30 Hz). Between samples q* is linear and qd* is the finite difference of
the two neighbouring samples (piecewise constant), as docs/DESIGN.md §1 step 5 asks.

:class:`TargetShaper` turns the possibly discontinuous stream (a clip switch jumps) into the
reference that the PD tracker follows: a second-order reference model driven by q* and qd*
with bounded velocity feed-forward and bounded acceleration. On smooth streams it reproduces
q*(t) without lag (qd* is fed forward); at a jump it produces the fast but finite-acceleration
transition a body can make, instead of an infinite-acceleration step.

:class:`RollingTargets` is the live form of a stream: each control step pushes its target, and
the physics samples between the last two (the same interpolation, one control period back).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gesture_sim.errors import GestureSimError


@dataclass
class TargetStream:
    """Joint targets sampled at a fixed rate.

    Attributes:
        q: shape (T, n_act), radians (hinges) or metres (slides).
        rate: samples per second (Hz); sample k is at time ``t0 + k / rate``.
        t0: time of the first sample (s).
    """

    q: np.ndarray
    rate: float = 30.0
    t0: float = 0.0

    def __post_init__(self) -> None:
        self.q = np.asarray(self.q, dtype=float)
        if self.q.ndim != 2 or self.q.shape[0] < 1:
            raise GestureSimError(
                f"target stream must have shape (T, n_joints), got {self.q.shape}")
        if not np.all(np.isfinite(self.q)):
            raise GestureSimError("target stream contains NaN or infinite values")
        if self.rate <= 0:
            raise GestureSimError(f"target rate must be positive, got {self.rate}")

    @property
    def duration(self) -> float:
        """Time covered by the samples (s): (T - 1) / rate."""
        return (self.q.shape[0] - 1) / self.rate

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """q*(t) (linear between samples) and qd*(t) (finite difference), each shape (n_act,).

        Before the first sample and after the last the stream holds still (qd* = 0).
        """
        x = (t - self.t0) * self.rate
        n = self.q.shape[0]
        if x <= 0.0 or n == 1:
            return self.q[0].copy(), np.zeros(self.q.shape[1])
        if x >= n - 1:
            return self.q[-1].copy(), np.zeros(self.q.shape[1])
        k = int(x)
        a = x - k
        dq = self.q[k + 1] - self.q[k]
        return self.q[k] + a * dq, dq * self.rate

    def resample(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vectorised :meth:`sample` at ``times`` (shape (N,)): q, qd of shape (N, n_act)."""
        times = np.asarray(times, dtype=float)
        n = self.q.shape[0]
        x = np.clip((times - self.t0) * self.rate, 0.0, n - 1)
        k = np.minimum(x.astype(int), max(n - 2, 0))
        a = (x - k)[:, None]
        if n == 1:
            return np.repeat(self.q, len(times), axis=0), np.zeros((len(times), self.q.shape[1]))
        dq = self.q[k + 1] - self.q[k]
        inside = ((times - self.t0) * self.rate > 0) & ((times - self.t0) * self.rate < n - 1)
        return self.q[k] + a * dq, dq * self.rate * inside[:, None]


class TargetShaper:
    """Second-order reference model between the target stream and the PD tracker.

    Per step of length ``dt`` (s), with r the reference and v its velocity (each (n_act,)):
    ``a = clip(w² (q* - r) + 2 w (clip(qd*, ±v_max) - v), ±a_max)``, then
    ``v += a dt; r += v dt`` (semi-implicit Euler). ``w`` (rad/s) sets how fast an offset closes
    (critically damped, time constant 1/w); ``v_max`` (rad/s) bounds the velocity feed-forward
    that a jump of q* would otherwise make huge; ``a_max`` (rad/s², per joint) bounds the
    reference acceleration. Slide joints use the same numbers in m, m/s, m/s².

    Two regimes (optional): with ``v_fast``/``a_fast`` set, a joint whose stream is *smooth*
    (the reference within ``gap`` of q* and |qd*| <= ``jump_speed``, default ``v_fast``) is
    shaped with the wide bounds
    ``v_fast``/``a_fast`` (real motion: fast but continuous), and only a joint realising a *jump*
    (a clip switch: q* far from the reference, or a one-interval speed above ``v_fast``) with
    the tight ``v_max``/``a_max``. Without them every joint uses ``v_max``/``a_max``.
    """

    def __init__(self, n: int, omega: float = 30.0, v_max: float | np.ndarray = 8.0,
                 a_max: float | np.ndarray = 150.0, v_fast: float | np.ndarray | None = None,
                 a_fast: float | np.ndarray | None = None, gap: float = 0.15,
                 jump_speed: float | None = None) -> None:
        self.omega = float(omega)
        self.v_max = np.broadcast_to(np.asarray(v_max, dtype=float), (n,)).copy()
        self.a_max = np.broadcast_to(np.asarray(a_max, dtype=float), (n,)).copy()
        self.v_fast = None if v_fast is None else np.broadcast_to(
            np.asarray(v_fast, dtype=float), (n,)).copy()
        self.a_fast = None if a_fast is None else np.broadcast_to(
            np.asarray(a_fast, dtype=float), (n,)).copy()
        self.gap = float(gap)
        self.jump_speed = jump_speed
        self.r = np.zeros(n)
        self.v = np.zeros(n)
        self.a = np.zeros(n)
        self._buf: np.ndarray | None = None

    def reset(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        """Start the reference at ``q`` (and velocity ``qd``, default 0)."""
        self.r = np.array(q, dtype=float)
        self.v = np.zeros_like(self.r) if qd is None else np.array(qd, dtype=float)
        self.a = np.zeros_like(self.r)

    def step(self, q_target: np.ndarray, qd_target: np.ndarray, dt: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance by ``dt`` seconds; returns the reference (r, v, a), each (n_act,).

        The returned arrays are the shaper's own buffers (updated in place by the next step).
        """
        w = self.omega
        buf = self._buf
        if buf is None or buf.shape != self.r.shape:
            buf = self._buf = np.empty_like(self.r)
        a = self.a if self.a.shape == self.r.shape else np.empty_like(self.r)
        v_max, a_max = self.v_max, self.a_max
        if self.v_fast is not None and self.a_fast is not None:
            vj = self.v_fast if self.jump_speed is None else self.jump_speed
            smooth = (np.abs(q_target - self.r) <= self.gap) & (np.abs(qd_target) <= vj)
            v_max = np.where(smooth, self.v_fast, v_max)
            a_max = np.where(smooth, self.a_fast, a_max)
        np.minimum(qd_target, v_max, out=buf)
        np.maximum(buf, -v_max, out=buf)                # clipped velocity feed-forward
        buf -= self.v
        buf *= 2.0 * w
        np.subtract(q_target, self.r, out=a)
        a *= w * w
        a += buf
        np.minimum(a, a_max, out=a)
        np.maximum(a, -a_max, out=a)
        np.multiply(a, dt, out=buf)
        self.v += buf
        np.multiply(self.v, dt, out=buf)
        self.r += buf
        self.a = a
        return self.r, self.v, self.a


class RollingTargets:
    """A live target stream: the control steps push their targets, the physics samples them.

    Each control step (period ``dt`` s) pushes its target q (n_act,) at stream time t
    (:meth:`push`). :meth:`sample` at time t returns, before the latest push time ``t_last``,
    the linear blend from the previous target (at ``t_last - dt``) to the latest, clamped to
    that interval, with qd* their difference over ``dt``; at or after ``t_last``, or while only
    one target has been pushed, the latest target held with qd* = 0.

    Args:
        dt: control period (s), > 0.
    """

    def __init__(self, dt: float) -> None:
        if not dt > 0.0:
            raise GestureSimError(f"control period must be positive, got {dt}")
        self.dt = float(dt)
        self.reset()

    def reset(self) -> None:
        """Forget every pushed target."""
        self._q_prev: np.ndarray | None = None
        self._q_last: np.ndarray | None = None
        self._t_last = 0.0
        self._dq: np.ndarray | None = None       # q_last - q_prev, per push
        self._qd: np.ndarray | None = None       # (q_last - q_prev) / dt, per push (read-only)
        self._zero: np.ndarray | None = None     # qd* while held (read-only)

    @property
    def ready(self) -> bool:
        """Whether a target has been pushed (:meth:`sample` works)."""
        return self._q_last is not None

    @property
    def last(self) -> np.ndarray | None:
        """The latest pushed target (n_act,), or None before the first push."""
        return self._q_last

    def push(self, t: float, q: np.ndarray) -> None:
        """The target q (n_act,) of the control step at stream time ``t`` (s); kept, not
        copied (nor to be changed afterwards: the step's difference to the previous target is
        computed here, once per push, not per sample)."""
        self._q_prev, self._q_last, self._t_last = self._q_last, q, t
        self._dq = self._qd = None
        if self._zero is None or self._zero.shape != np.shape(q):
            self._zero = np.zeros_like(q)
            self._zero.flags.writeable = False
        if self._q_prev is not None:
            self._dq = self._q_last - self._q_prev
            self._qd = self._dq / self.dt
            self._qd.flags.writeable = False

    def frozen(self) -> RollingTargets:
        """A copy that samples as this stream does now, whatever is pushed here afterwards
        (O(1): the pushed targets are never changed, and every push rebinds, never writes,
        the arrays it keeps)."""
        twin = RollingTargets.__new__(RollingTargets)
        twin.__dict__.update(self.__dict__)
        return twin

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """q*(t), qd*(t), each (n_act,), at stream time ``t`` (s) (see the class docstring).

        qd* (and q* while held) are shared, read-only arrays: copy them to change them."""
        if self._q_last is None:
            raise GestureSimError("no control step yet: push a target first")
        if self._q_prev is None or t >= self._t_last:
            return self._q_last, self._zero
        a = (t - (self._t_last - self.dt)) / self.dt
        a = min(max(a, 0.0), 1.0)
        return self._q_prev + a * self._dq, self._qd
