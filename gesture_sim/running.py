"""Running (online) mean and variance of a scalar: the one implementation the stages share.

A ground module: the standard library only.

:class:`RunningStat` is West's (1979) weighted incremental mean and variance. The k-th
observation ``x`` (k = 1, 2, ...) moves the statistics by

    ``d = x - mean;  mean += wm(k) * d;  var = (1 - wv(k)) * (var + wv(k) * d * d)``

with weights in (0, 1] that the parameters choose (:meth:`RunningStat.weights`):

* variance weight ``wv(k) = max(1 / (k + prior), min_weight)``: the starting ``var`` is a
  prior worth ``prior`` observations; after about ``1 / min_weight`` observations the
  cumulative average becomes an exponentially weighted one (a memory of ``1 / min_weight``
  observations; ``min_weight = 0``: no forgetting);
* mean weight ``wm(k)``, by ``location``:

  - ``"prior"``: ``wm = wv``: the starting ``mean`` is a prior worth ``prior`` observations;
  - ``"first"``: the first observation sets the mean (``wm(1) = 1``; the starting ``mean`` is
    only what is read before it), then ``wm(k) = max(1 / k, min_weight)``: a cumulative mean
    of the observations that becomes an exponential average. Without a prior (``prior = 0``)
    this is a plain exponential moving average whose time constant is ``1 / min_weight``
    observations;
  - ``"anchored"`` (location-free): the first observation sets the mean and leaves the
    variance (and its prior) alone, observations 2 to ``anchor`` average into the mean
    (``wm(k) = 1 / k``), later ones move it as slowly as a prior's mean would,
    ``wm(k) = max(1 / (2k + prior), min_weight)``. No absolute location enters, so a constant
    offset of every observation (a gain in dB, a speaker's pitch level) shifts the mean with
    it and leaves every z-score (:meth:`RunningStat.z`) unchanged.

``form="welford"`` is the same cumulative statistic (``location="prior"``, no floor:
``wm = wv = 1 / (k + prior)``) in Welford's arithmetic, kept bit for bit for the Levine 2009
features: ``mean += d / N;  m2 += d * (x - mean);  var = m2 / N`` with ``N = k + prior`` and
``m2`` starting at ``var * prior``.

Every update is O(1) time and memory; the statistics are those of everything absorbed so far
(read them before :meth:`RunningStat.update` for a causal z of the new value).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

__all__ = ["ANCHOR", "Form", "Location", "RunningStat"]

#: Where the mean starts (see the module text).
Location = Literal["prior", "first", "anchored"]
#: The update's arithmetic: West's weighted recurrence, or Welford's (cumulative only).
Form = Literal["west", "welford"]
#: Default number of observations that set a location-free (``"anchored"``) mean.
ANCHOR = 5

_LOCATIONS = ("prior", "first", "anchored")
_FORMS = ("west", "welford")


@dataclass
class RunningStat:
    """Running mean and variance of a scalar (see the module text for the update).

    Attributes:
        mean: current mean (units of the observations). With ``location="first"`` or
            ``"anchored"`` it is only a placeholder until the first observation (NaN is fine).
        var: current variance (units squared); at the start the prior variance.
        prior: how many observations the starting ``var`` (and, with ``location="prior"``,
            the starting ``mean``) are worth; >= 0.
        min_weight: floor of the update weights in [0, 1]; the long-run memory is about
            ``1 / min_weight`` observations (0: a cumulative average that never forgets).
        location: ``"prior"``, ``"first"`` or ``"anchored"`` (how the mean starts).
        anchor: with ``location="anchored"``, the observations that set the mean (>= 1).
        var_floor: :attr:`sd` is ``sqrt(max(var, var_floor))`` (keeps z-scores finite).
        form: ``"west"`` or ``"welford"`` (the latter needs ``location="prior"`` and
            ``min_weight=0``).
        n: observations absorbed so far (not counting the prior).
    """

    mean: float = 0.0
    var: float = 0.0
    prior: float = 0.0
    min_weight: float = 0.0
    location: Location = "prior"
    anchor: int = ANCHOR
    var_floor: float = 1e-12
    form: Form = "west"
    n: int = 0
    _m2: float = field(default=0.0, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.location not in _LOCATIONS:
            raise ValueError(f"location must be one of {_LOCATIONS}, got {self.location!r}")
        if self.form not in _FORMS:
            raise ValueError(f"form must be one of {_FORMS}, got {self.form!r}")
        if not self.prior >= 0:
            raise ValueError(f"prior must be >= 0 observations, got {self.prior}")
        if not 0.0 <= self.min_weight <= 1.0:
            raise ValueError(f"min_weight must lie in [0, 1], got {self.min_weight}")
        if self.anchor < 1 or self.n < 0:
            raise ValueError(f"anchor must be >= 1 and n >= 0, got {self.anchor}, {self.n}")
        self.prior = float(self.prior)
        if self.form == "welford":
            if self.location != "prior" or self.min_weight != 0.0:
                raise ValueError("form='welford' is the cumulative statistic: it needs "
                                 "location='prior' and min_weight=0")
            total = self.prior + self.n
            self._m2 = self.var * total
            if total > 0:
                self.var = self._m2 / total

    @property
    def count(self) -> float:
        """Observations the statistics are worth: ``prior + n``."""
        return self.prior + self.n

    @property
    def sd(self) -> float:
        """Standard deviation ``sqrt(max(var, var_floor))`` (units of the observations)."""
        return math.sqrt(max(self.var, self.var_floor))

    def z(self, x: float) -> float:
        """``(x - mean) / sd`` against the current statistics (dimensionless)."""
        return (x - self.mean) / self.sd

    def weights(self, k: int) -> tuple[float, float]:
        """``(wm, wv)``: the mean and variance weights the k-th observation (k >= 1) gets.

        A weight of 1 for the mean at k = 1 (``"first"``, ``"anchored"``) means the
        observation *sets* the mean; ``wv = 0`` (``"anchored"``, k = 1): the variance is left
        alone. For ``form="welford"`` these are the equivalent West weights ``1 / (k + prior)``.
        """
        if self.form == "welford":
            w = 1.0 / (k + self.prior)
            return w, w
        wv = max(1.0 / (k + self.prior), self.min_weight)
        if self.location == "prior":
            return wv, wv
        if self.location == "first":
            return (1.0 if k == 1 else max(1.0 / k, self.min_weight)), wv
        if k == 1:
            return 1.0, 0.0
        if k <= self.anchor:
            return 1.0 / k, wv
        return max(1.0 / (k + (k + self.prior)), self.min_weight), wv

    def update(self, x: float) -> None:
        """Absorb one observation ``x`` (units of the observations)."""
        self.n += 1
        k = self.n
        if self.form == "welford":
            total = k + self.prior
            d = x - self.mean
            self.mean += d / total
            self._m2 += d * (x - self.mean)
            self.var = self._m2 / total
            return
        # the weights of :meth:`weights`, inline (this runs per frame on the audio path);
        # ``b if b > a else a`` is ``max(a, b)``
        wv = 1.0 / (k + self.prior)
        floor = self.min_weight
        wv = floor if floor > wv else wv
        loc = self.location
        if loc == "prior":
            wm = wv
        elif loc == "first":
            wm = 1.0 if k == 1 else (floor if floor > 1.0 / k else 1.0 / k)
        elif k == 1:
            wm, wv = 1.0, 0.0
        elif k <= self.anchor:
            wm = 1.0 / k
        else:
            wm = 1.0 / (k + (k + self.prior))
            wm = floor if floor > wm else wm
        if k == 1 and loc != "prior":
            self.mean = x
            if self.location == "anchored":
                return
            d = x - self.mean  # 0: the first observation only spends a variance weight
        else:
            d = x - self.mean
            self.mean += wm * d
        self.var = (1.0 - wv) * (self.var + wv * d * d)
