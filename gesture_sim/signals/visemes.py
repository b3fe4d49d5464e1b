"""Visemes with dominance coarticulation (Cohen & Massaro 1993, as RUTH blends its visemes).

Phones (:class:`gesture_sim.audio.phones.Phone`, ARPAbet without stress) become viseme segments,
each with a *target* for the articulator channels and a *dominance function* per channel; the
mouth at time ``t`` is the dominance-weighted average of all targets (RUTH §1.4):

    D_i,k(t) = alpha_i,k * exp(-theta_i * |tau|^c),   tau = t - centre_i,
    theta_i = theta_before_i for tau < 0 (anticipation), theta_after_i for tau >= 0 (carry-over),
    y_k(t) = (sum_i D_i,k(t) T_i,k + a_rest * 0) / (sum_i D_i,k(t) + a_rest)

(``k`` the channel, ``a_rest`` a tiny rest dominance so that far from any phone the face rests
and the sum never vanishes). A segment's ``alpha`` is high on the channels its viseme *needs*
(lip closure for /p b m/, rounding for /uw ow w/, lip tuck for /f v/, tongue for /th dh/, the jaw
for vowels) and low on the rest, which it then takes from its neighbours: the /s/ of "soon" is
rounded, the jaw of /m/ follows the vowels around it. Bilabial closure dominates strongly and
narrowly (alpha 8, theta 60 /s) so that /p b m/ close the lips even between open vowels;
vowels dominate weakly and broadly. Diphthongs (AW AY OY OW EY) are two segments (onset target
for the first ``diphthong_split`` of the phone, offset target for the rest).

Output channels (:data:`VISEME_CHANNELS`, the face rig's contract):
    * ``jaw_open``: jaw opening (rad): 0 closed ... about 0.30 for /AA/.
    * ``lip_close``: 0..1, 1 = lips pressed together (the rig closes the lip gap whatever a
      small jaw opening).
    * ``lip_round``: 0..1, protrusion and narrowing; ``lip_spread``: 0..1, corners out.
    * ``lip_tuck``: 0..1, lower lip up under the upper teeth (/f v/).
    * ``tongue_tip``: 0..1, tongue tip visible between/behind the teeth (/th dh/, a bit for /l/).

Viseme classes (:data:`VISEME_CLASSES`; targets per phone in :data:`PHONE_TARGETS`):

    =============  =================================  ==========================================
    class          phones                             shape (primary channels, alpha)
    =============  =================================  ==========================================
    closed         P B M                              lips pressed (lip_close 1; alpha 3)
    labiodental    F V                                lower lip under upper teeth (lip_tuck 1)
    rounded        UW OW W UH AO OY ER R              protruded, narrowed (lip_round .35-.95;
                                                      R and ER partly: .45/.35)
    spread         IY IH EY EH Y                      corners out (lip_spread .35-.7), jaw small
    open           AA AE AH AW AY                     jaw open (.20-.30 rad)
    dental         TH DH                              tongue tip between the teeth
    alveolar       T D N L S Z                        near-closed jaw; L shows the tongue (.35)
    postalveolar   SH ZH CH JH                        slight rounding (.45), lips forward
    velar          K G NG                             neutral, jaw a little open; shape from
                                                      context (all alphas low)
    neutral        HH                                 shape of the next vowel (alphas lowest)
    rest           SIL                                all 0 (mouth closed at rest)
    =============  =================================  ==========================================

EH and Y (not in the issue's list) are put with the spread class (front unrounded), ER with the
rounded (r-coloured, partly rounded).

Offline (:class:`Coarticulator`) every phone is known, so a segment's anticipatory dominance
reaches back before it (lips round before /uw/). Live (:class:`LiveCoarticulator`) a phone is
known only once the recogniser emits it (after it ended, plus the recogniser's latency), so the
output can only look back: anticipatory coarticulation is lost, and the mouth lags the speech by
the recogniser's latency (evaluate at ``t - lag_s`` to keep a phone's shape whole at the cost of
that delay).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from gesture_sim.audio.phones import SIL, Phone
from gesture_sim.errors import GestureSimError

__all__ = ["PHONE_TARGETS", "VISEME_CHANNELS", "VISEME_CLASSES", "Coarticulator",
           "LiveCoarticulator", "VisemeClass", "VisemeConfig", "classify_track",
           "labels_at", "viseme_class"]

#: The output channels, in the order of :meth:`Coarticulator.at`'s vector.
VISEME_CHANNELS: tuple[str, ...] = ("jaw_open", "lip_close", "lip_round", "lip_spread",
                                    "lip_tuck", "tongue_tip")
#: Upper bounds of the channels (rad for the jaw, 0..1 otherwise).
CHANNEL_MAX = np.array([0.35, 1.0, 1.0, 1.0, 1.0, 1.0])
_N = len(VISEME_CHANNELS)


@dataclass(frozen=True)
class VisemeClass:
    """A viseme class: its phones and dominance parameters.

    Attributes:
        name: the class name (``"closed"``).
        phones: the ARPAbet phones in it.
        alpha: peak dominance per channel (6,), in :data:`VISEME_CHANNELS` order.
        theta_before, theta_after: dominance decay rates (1/s^c) before and after the centre.
    """

    name: str
    phones: tuple[str, ...]
    alpha: tuple[float, float, float, float, float, float]
    theta_before: float
    theta_after: float


#                  jaw  close round spread tuck tongue
VISEME_CLASSES: tuple[VisemeClass, ...] = (
    VisemeClass("closed", ("P", "B", "M"), (0.5, 8.0, 0.3, 0.3, 1.0, 0.3), 60.0, 60.0),
    VisemeClass("labiodental", ("F", "V"), (0.6, 1.0, 0.3, 0.3, 2.0, 0.3), 40.0, 40.0),
    VisemeClass("rounded", ("UW", "OW", "W", "UH", "AO", "OY", "ER", "R"),
                (1.0, 0.5, 1.2, 0.8, 0.3, 0.3), 16.0, 22.0),
    VisemeClass("spread", ("IY", "IH", "EY", "EH", "Y"), (1.0, 0.5, 0.8, 1.0, 0.3, 0.3),
                18.0, 22.0),
    VisemeClass("open", ("AA", "AE", "AH", "AW", "AY"), (1.0, 0.5, 0.5, 0.6, 0.3, 0.3),
                18.0, 22.0),
    VisemeClass("dental", ("TH", "DH"), (0.5, 0.5, 0.2, 0.2, 0.3, 1.5), 40.0, 40.0),
    VisemeClass("alveolar", ("T", "D", "N", "L", "S", "Z"), (0.5, 0.4, 0.15, 0.2, 0.3, 0.6),
                35.0, 35.0),
    VisemeClass("postalveolar", ("SH", "ZH", "CH", "JH"), (0.5, 0.4, 0.8, 0.3, 0.3, 0.3),
                30.0, 35.0),
    VisemeClass("velar", ("K", "G", "NG"), (0.4, 0.3, 0.15, 0.15, 0.3, 0.3), 35.0, 35.0),
    VisemeClass("neutral", ("HH",), (0.1, 0.1, 0.05, 0.05, 0.1, 0.1), 35.0, 35.0),
    VisemeClass("rest", (SIL,), (0.8, 0.3, 0.4, 0.4, 0.4, 0.4), 12.0, 12.0),
)
_CLASS_OF = {p: c for c in VISEME_CLASSES for p in c.phones}
CLASS_NAMES: tuple[str, ...] = tuple(c.name for c in VISEME_CLASSES)


def _t(jaw: float = 0.0, close: float = 0.0, rnd: float = 0.0, spread: float = 0.0,
       tuck: float = 0.0, tongue: float = 0.0) -> tuple[float, ...]:
    return (jaw, close, rnd, spread, tuck, tongue)


#: Target per phone (channels of :data:`VISEME_CHANNELS`); diphthongs have (onset, offset).
PHONE_TARGETS: dict[str, tuple[tuple[float, ...], ...]] = {
    "P": (_t(0.02, 1.0),), "B": (_t(0.02, 1.0),), "M": (_t(0.02, 1.0),),
    "F": (_t(0.05, tuck=1.0),), "V": (_t(0.05, tuck=1.0),),
    "UW": (_t(0.06, rnd=0.95),), "UH": (_t(0.10, rnd=0.55),), "W": (_t(0.04, rnd=0.90),),
    "AO": (_t(0.24, rnd=0.50),), "OW": (_t(0.17, rnd=0.60), _t(0.10, rnd=0.80)),
    "OY": (_t(0.17, rnd=0.70), _t(0.08, spread=0.45)),
    "ER": (_t(0.10, rnd=0.35),), "R": (_t(0.07, rnd=0.45),),
    "IY": (_t(0.06, spread=0.70),), "IH": (_t(0.09, spread=0.45),),
    "EY": (_t(0.14, spread=0.40), _t(0.08, spread=0.55)), "EH": (_t(0.17, spread=0.35),),
    "Y": (_t(0.05, spread=0.55),),
    "AA": (_t(0.30, spread=0.10),), "AE": (_t(0.26, spread=0.35),), "AH": (_t(0.20),),
    "AW": (_t(0.28), _t(0.10, rnd=0.70)), "AY": (_t(0.28), _t(0.08, spread=0.50)),
    "TH": (_t(0.07, tongue=1.0),), "DH": (_t(0.07, tongue=1.0),),
    "T": (_t(0.05),), "D": (_t(0.05),), "N": (_t(0.05),), "S": (_t(0.04, spread=0.2),),
    "Z": (_t(0.04, spread=0.2),), "L": (_t(0.10, tongue=0.35),),
    "SH": (_t(0.06, rnd=0.45),), "ZH": (_t(0.06, rnd=0.45),), "CH": (_t(0.06, rnd=0.45),),
    "JH": (_t(0.06, rnd=0.45),),
    "K": (_t(0.09),), "G": (_t(0.09),), "NG": (_t(0.08),),
    "HH": (_t(0.12),),
    SIL: (_t(),),
}


def viseme_class(label: str) -> str:
    """The viseme class name of an ARPAbet phone (no stress digit) or ``"SIL"``."""
    try:
        return _CLASS_OF[label].name
    except KeyError:
        raise GestureSimError(f"visemes: unknown phone {label!r}") from None


@dataclass(frozen=True)
class VisemeConfig:
    """Settings of the coarticulation model.

    Attributes:
        c: the dominance exponent (Cohen–Massaro's ``c``; 1 = exponential fall-off).
        theta_scale: factor on every class's decay rates (>1: less coarticulation).
        rest_alpha: dominance of the always-present rest target (0 on every channel).
        diphthong_split: share of a diphthong given to its onset target.
        window_s: segments further than this from a time are left out of its sum (their
            dominance is below ``exp(-theta * window_s**c)``: negligible).
        targets: per-phone target overrides (as :data:`PHONE_TARGETS`).
    """

    c: float = 1.0
    theta_scale: float = 1.0
    rest_alpha: float = 1e-4
    diphthong_split: float = 0.6
    window_s: float = 1.5
    targets: Mapping[str, tuple[tuple[float, ...], ...]] = field(default_factory=dict)


@dataclass
class _Segments:
    """Viseme segments as arrays: centre (N,), target (N, 6), alpha (N, 6), theta (N, 2),
    known (N,) the stream time from which each is known (-inf offline)."""

    centre: np.ndarray
    target: np.ndarray
    alpha: np.ndarray
    theta: np.ndarray
    known: np.ndarray

    @classmethod
    def empty(cls) -> _Segments:
        return cls(np.zeros(0), np.zeros((0, _N)), np.zeros((0, _N)), np.zeros((0, 2)),
                   np.zeros(0))


def _segments(phones: Iterable[Phone], config: VisemeConfig,
              known: Iterable[float] | None = None) -> _Segments:
    cen, tgt, alp, th, kn = [], [], [], [], []
    knowns = iter(known) if known is not None else None
    for p in phones:
        k = next(knowns) if knowns is not None else -np.inf
        cls = _CLASS_OF.get(p.label)
        if cls is None:
            raise GestureSimError(f"visemes: unknown phone {p.label!r} at {p.start_s:.2f} s")
        if not (np.isfinite(p.start_s) and np.isfinite(p.end_s)) or p.end_s < p.start_s:
            raise GestureSimError(f"visemes: bad phone times {p.start_s}..{p.end_s}")
        targets = config.targets.get(p.label, PHONE_TARGETS[p.label])
        if len(targets) == 1:
            parts = [(p.centre_s, targets[0])]
        else:
            cut = p.start_s + config.diphthong_split * p.duration_s
            parts = [(0.5 * (p.start_s + cut), targets[0]), (0.5 * (cut + p.end_s), targets[1])]
        for c, t in parts:
            cen.append(c)
            tgt.append(t)
            alp.append(cls.alpha)
            th.append((cls.theta_before * config.theta_scale, cls.theta_after * config.theta_scale))
            kn.append(k)
    if not cen:
        return _Segments.empty()
    order = np.argsort(np.asarray(cen), kind="stable")
    return _Segments(np.asarray(cen, float)[order], np.asarray(tgt, float)[order],
                     np.asarray(alp, float)[order], np.asarray(th, float)[order],
                     np.asarray(kn, float)[order])


def _blend(segs: _Segments, times: np.ndarray, config: VisemeConfig,
           clock: np.ndarray | None = None, chunk: int = 256) -> np.ndarray:
    """Dominance-weighted targets at ``times`` (T,) → (T, 6). ``clock`` (T,): the stream time
    at which each output is computed; segments with ``known > clock`` are left out."""
    times = np.asarray(times, dtype=float)
    out = np.zeros((len(times), _N))
    if len(segs.centre) == 0 or len(times) == 0:
        return out
    for i0 in range(0, len(times), chunk):
        t = times[i0:i0 + chunk]
        lo, hi = np.searchsorted(segs.centre, [t.min() - config.window_s,
                                               t.max() + config.window_s])
        if hi <= lo:
            continue
        tau = t[:, None] - segs.centre[None, lo:hi]  # (t, n)
        theta = np.where(tau < 0, segs.theta[None, lo:hi, 0], segs.theta[None, lo:hi, 1])
        d = np.exp(-theta * np.abs(tau) ** config.c)
        d[np.abs(tau) > config.window_s] = 0.0
        if clock is not None:
            d = d * (segs.known[None, lo:hi] <= clock[i0:i0 + chunk, None])
        w = d[:, :, None] * segs.alpha[None, lo:hi, :]  # (t, n, 6)
        num = np.einsum("tnk,nk->tk", w, segs.target[lo:hi])
        den = w.sum(axis=1) + config.rest_alpha
        out[i0:i0 + chunk] = num / den
    return np.clip(out, 0.0, CHANNEL_MAX)


class Coarticulator:
    """Offline visemes: every phone known in advance (anticipation included).

    Args:
        phones: the phones (any order; times in s).
        config: the model's settings.
    """

    def __init__(self, phones: Sequence[Phone], config: VisemeConfig | None = None) -> None:
        self.config = config or VisemeConfig()
        self.phones = tuple(phones)
        self._segs = _segments(self.phones, self.config)

    def at(self, t: float) -> np.ndarray:
        """The channels (6,) at time ``t`` (s): rad for ``jaw_open``, 0..1 for the rest."""
        return _blend(self._segs, np.array([float(t)]), self.config)[0]

    def track(self, times: np.ndarray) -> np.ndarray:
        """The channels at each of ``times`` (T,) (s) → (T, 6), vectorised."""
        return _blend(self._segs, np.asarray(times, dtype=float), self.config)


class LiveCoarticulator:
    """Live visemes from phones as they become known (``push``), looking back only.

    Args:
        config: the model's settings.
        lag_s: ``at(t)`` shows the mouth at ``t - lag_s`` (0: as soon as possible, the phone
            being spoken now is not known yet; the recogniser's typical latency: a phone's
            shape whole, that much late).

    What it trades against :class:`Coarticulator`: a phone's dominance counts only from the
    moment it is pushed, so no phone shapes the mouth before it is known (no anticipatory
    rounding or closure), and the output lags the speech by the recogniser's latency.
    """

    def __init__(self, config: VisemeConfig | None = None, lag_s: float = 0.0) -> None:
        self.config = config or VisemeConfig()
        self.lag_s = float(lag_s)
        self._phones: list[Phone] = []
        self._known: list[float] = []
        self._segs = _Segments.empty()
        self._dirty = False

    def push(self, phone: Phone, emitted_s: float | None = None) -> None:
        """Add a phone, known from stream time ``emitted_s`` (``None``: known for every later
        ``at``; for :meth:`track` of a past stream, give the recogniser's emission time)."""
        self._phones.append(phone)
        self._known.append(-np.inf if emitted_s is None else float(emitted_s))
        self._dirty = True

    def _update(self) -> None:
        if self._dirty:
            self._segs = _segments(self._phones, self.config, self._known)
            self._dirty = False

    def at(self, t: float) -> np.ndarray:
        """The channels (6,) shown at stream time ``t`` (s): the phones known at ``t``,
        evaluated at ``t - lag_s``."""
        self._update()
        return _blend(self._segs, np.array([t - self.lag_s]), self.config,
                      clock=np.array([float(t)]))[0]

    def track(self, times: np.ndarray) -> np.ndarray:
        """:meth:`at` for each of ``times`` (T,) → (T, 6), vectorised; each time sees only the
        phones known at it (by their ``emitted_s``)."""
        self._update()
        times = np.asarray(times, dtype=float)
        return _blend(self._segs, times - self.lag_s, self.config, clock=times)


def labels_at(phones: Sequence[Phone], times: np.ndarray) -> list[str]:
    """The phone label at each of ``times`` (T,) (``SIL`` outside every phone)."""
    ps = sorted(phones, key=lambda p: p.start_s)
    starts = np.array([p.start_s for p in ps])
    out: list[str] = []
    for t in np.asarray(times, dtype=float):
        i = int(np.searchsorted(starts, t, side="right")) - 1
        out.append(ps[i].label if i >= 0 and t < ps[i].end_s else SIL)
    return out


def classify_track(track: np.ndarray) -> list[str]:
    """The viseme class of each frame of a track (T, 6): the class whose mean target is
    nearest (channels scaled to 0..1 by :data:`CHANNEL_MAX`)."""
    protos = []
    for c in VISEME_CLASSES:
        vals = [np.mean(PHONE_TARGETS[p], axis=0) for p in c.phones]
        protos.append(np.mean(vals, axis=0) / CHANNEL_MAX)
    p = np.asarray(protos)
    x = np.asarray(track, dtype=float) / CHANNEL_MAX
    d = ((x[:, None, :] - p[None, :, :]) ** 2).sum(axis=2)
    return [CLASS_NAMES[i] for i in d.argmin(axis=1)]
