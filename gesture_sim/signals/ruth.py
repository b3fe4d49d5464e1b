"""Face and head signals after RUTH (DeCarlo et al. 2004): scheduling and envelopes, causally.

A :class:`RuthSignals` scheduler is stepped once per control step with what the speech has told
so far (the shared accent detector's accents and boundaries with ``t_emitted <= t``, its voice
activity, and the prosody frames' intensity as they became known) and returns offsets for
:data:`SIGNAL_JOINTS` (rad for hinges, m for slides) that :mod:`gesture_sim.sim.layers` adds
onto the clip's target, so that the same PD physics realises them.

Channels (RUTH §2.2: each holds at most one underliner and one baton at a time)
    * ``jog`` (head): a baton ``D*`` (nod down) on the accents the rules mark (strong H-type
      accents or rising L+H*, at least ``nod_gap_s`` apart: ``nod_z``), its size from the
      accent's strength against this speaker's running accent strengths; an underliner over
      the phrase (``TL``/``TR`` alternating per phrase: a tilt with a slight down-nod) opened
      by the phrase's first accent and released by its boundary (or by silence).
    * ``brow``: a baton ``1+2*`` (AU1+2, both brows up) on strong accents: the accented
      nucleus's loudest intensity z plus its highest F0 z (0 when lower than usual), over the
      frames from ``brow_window_s`` before to ``brow_window_s`` after the accent, against this
      speaker's running frame statistics, reaches ``brow_z`` (decided as soon as those frames
      are known, so the brows peak about ``brow_window_s + brow_attack_s`` after emission).
      Only the accents RUTH's rules mark are judged (``brow_marked_only``: the H-type accents
      that may carry a nod), and a raise starts at least ``brow_gap_s`` after the previous one
      (a baton or a register underliner): eyebrow movements go with the prominences that also
      get a head beat and are about 3.4 times rarer than head movements (6.8 % against
      23.2 % of words in Ambrazaitis, Svensson Lundmark & House 2015), and two raises closer
      than one raise's own rise and fall are one movement. ``tools/brow_rates.py`` measures
      the rate on real speech against that reference.
    * ``blink``: at the end of an accented vowel (``vowel_s`` after the accent, probability
      ``p_blink_accent``), at phrase boundaries (``p_blink_boundary``) and spontaneously
      (a seeded Poisson process, ``spontaneous_per_min``), never within ``refractory_s`` of
      the previous blink; they continue in silence.
    * ``jaw``: opens with the speech: ``jaw_max * clip((I - (mu - sd)) / (2.5 sd), 0, 1)`` on
      speech frames (``I`` the frame intensity in dB, ``mu``/``sd`` this speaker's running
      statistics of speech frames, so gain does not matter), closed on silent frames.

Jog codes (RUTH Fig. 8) on the neck and head joints, split ``neck_share`` / rest over the two
levels (RUTH's smooth join with the neck): D/U pitch (``*_flex`` > 0 is a nod down), R/L yaw
(R = towards the model's right, ``*_twist`` < 0), J/C roll (J = clockwise as the viewer sees the
face, i.e. the top of the head towards the model's left, ``*_bend`` > 0; TL = J + D, TR = C + D),
F/B protraction/retraction as neck flexion with the opposite head flexion (gaze stays level);
compound codes are sums of their parts.

Timing (causal; RUTH §1.5 timing rules adapted)
    An accent is known only at its ``t_emitted`` (about 30 ms after its nucleus), so a baton
    starts at emission and its reference peaks ``baton_attack_s - head_lag_s`` later (the head's
    measured PD tracking delay, ``tools/head_lag.py``, is taken off the attack so that the
    *simulated* peak lands ``baton_attack_s`` after emission: as soon as possible after the
    accented syllable). Labels from a markup file are known in advance, so their envelopes start
    early enough for the simulated peak to fall on the labelled time.
    Envelopes: raised-cosine attack to the peak intensity, a hold (underliners: until the phrase
    ends), raised-cosine decay to 0.

Listener's calm: ``calm_s`` after the speech stops, open underliners decay and no new head or
brow signal starts until speech returns; the jaw closes; blinks continue.

Markup (``--signals FILE``, RUTH's symbolic input, offline): one label per line, ``#`` comments::

    1.20 accent [STRENGTH]     an accent at 1.20 s (replaces the detector's accents)
    2.05 boundary              a phrase boundary (replaces the detector's boundaries)
    1.20 nod                   a D* baton peaking at 1.20 s (same as "jog D*")
    1.20 jog UR*               a baton of any jog code peaking at 1.20 s
    0.80-2.00 jog TL           an underliner over 0.80-2.00 s
    1.20 brow                  a 1+2* brow raise peaking at 1.20 s (also "brow 1+2*")
    0.80-2.00 brow 1+2         a brow underliner
    3.10 blink                 a blink closed at 3.10 s
    auto off                   no automatic signals from the speech (only the labels; the jaw
                               still follows the speech)

Times are seconds on the stream clock; offsets rad (hinges) and m (slides).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gesture_sim.contracts import Accent, Boundary
from gesture_sim.errors import GestureSimError
from gesture_sim.running import RunningStat
from gesture_sim.units import semitones

__all__ = ["JOG_CODES", "SIGNAL_JOINTS", "Markup", "MarkupItem", "RuthConfig", "RuthSignals",
           "jog_goal", "load_markup", "parse_markup"]

#: The joints the signals drive, in the order of :meth:`RuthSignals.step`'s offsets.
SIGNAL_JOINTS: tuple[str, ...] = (
    "neck_flex", "neck_bend", "neck_twist", "head_flex", "head_bend", "head_twist",
    "jaw_open", "left_brow_raise", "right_brow_raise", "left_eyelid_close", "right_eyelid_close",
    "left_brow_inner_raise", "right_brow_inner_raise", "left_brow_inner_squeeze",
    "right_brow_inner_squeeze", "left_lip_corner_out", "left_lip_corner_up",
    "right_lip_corner_out", "right_lip_corner_up",
)
_J = {name: i for i, name in enumerate(SIGNAL_JOINTS)}
#: The 14 jog codes of RUTH (Fig. 8).
JOG_CODES: tuple[str, ...] = ("D", "U", "F", "B", "R", "L", "J", "C", "DR", "UR", "DL", "UL",
                              "TL", "TR")
_COMPOUND = {"DR": "DR", "UR": "UR", "DL": "DL", "UL": "UL", "TL": "JD", "TR": "CD"}
CHANNELS = ("jog", "brow", "blink", "smile")
#: The brow codes (RUTH §2.3; FACS): ``1+2`` raises inner and outer brows, ``1`` the inner only,
#: ``2`` the outer only, ``4`` lowers the inner brows and draws them together (a frown).
BROW_CODES: tuple[str, ...] = ("1+2", "1", "2", "4")
#: The pitch-accent types of RUTH's ToBI markup (DeCarlo et al. 2004), as :meth:`RuthSignals`
#: types them from the F0 contour (the ``--signals`` markup here carries no types: an ``accent``
#: has a strength only, and ``accent H*`` is refused).
ACCENT_TYPES: tuple[str, ...] = ("H*", "L+H*", "!H*", "L*")
#: Running frame statistics (:class:`~gesture_sim.running.RunningStat`, the mean from the first
#: speech frame): prior variances of intensity (dB²) and F0 (semitones²), the frames the
#: priors are worth, and the memory (frames, 30 s at 100 Hz).
_I_PRIOR_VAR = 36.0
_F_PRIOR_VAR = 9.0
_FRAME_PRIOR = 50.0
_FRAME_MEMORY = 3000.0


@dataclass(frozen=True)
class RuthConfig:
    """Settings (s, rad, m, z units). Amplitudes follow the digest's §6.2.9 starting values.

    Attributes:
        pitch_rad, yaw_rad, roll_rad, forward_rad: full-scale jog components (nod, turn, tilt,
            and the neck flexion of F/B, the head flexing back by the same).
        neck_share: share of a rotation given to the neck (the rest to the head joints).
        baton_attack_s, baton_decay_s: a head baton's envelope; underliner_attack_s,
            underliner_decay_s: an underliner's ramps; underliner_scale: its size (of full).
        head_lag_s: the head's measured PD tracking delay (``tools/head_lag.py``: 10 ms).
        min_scale, max_scale: a baton's intensity range; it grows with the accent's strength
            (z against the running accent strengths): ``0.7 + 0.2 z`` clipped to the range.
        brow_z: the nucleus prominence (intensity z + F0 z) of an accent that raises the brows;
            brow_window_s: the frames judged around the accent; brow_m: brow raise (m);
            brow_attack_s, brow_decay_s: its envelope. brow_marked_only: only the accents
            RUTH's rules mark (those that may carry a nod: strong H accents or rising L+H*,
            ``nod_z`` / ``nod_rise_pitch_z``) are judged for the brows (False: every H-type
            accent). brow_gap_s: an automatic brow baton starts at least this long (s) after
            the previous automatic raise (baton or register underliner): a second raise before
            the first has come down is one movement to see, not two (a raise rises and falls
            in ``brow_attack_s + brow_decay_s`` = 0.42 s; ``nod_gap_s`` does it for nods).
        blink_m: eyelid travel of a full blink (m); blink_close_s, blink_hold_s, blink_open_s.
        vowel_s: an accented vowel's end after the accent (s); p_blink_accent, p_blink_boundary.
        spontaneous_per_min: rate of the spontaneous blinks; refractory_s: minimum blink gap.
        jaw_max_rad: jaw opening at full normalised intensity; jaw_floor_sd, jaw_span_sd: the
            normalisation (SDs below the running mean where it starts; SDs to full opening).
        calm_s: silence (s) after which the listener's calm begins.
        nod_z, nod_rise_pitch_z, nod_gap_s: an automatic D* baton needs an H-type accent (H*,
            L+H*) that is strong (its strength z reaches ``nod_z``) or a rising L+H* reaching
            F0 z ``nod_rise_pitch_z`` (RUTH's contrastive accent), at least ``nod_gap_s`` after
            the previous head baton.
        low_pitch_z: F0 z at or below which an accent is L*; rise_z, rise_window_s: the F0 rise
            (z) over the window before the accent that makes it L+H*; downstep_z: an H accent
            this much (z) below the phrase's previous one is !H*.
        expanded_z, register_scale: a phrase whose first H accent reaches this F0 z is in an
            expanded register (H^H): a 1+2 brow underliner of this size over the phrase.
        boundary_window_s, boundary_rise_z: the F0 rise (z) over the phrase's last
            ``boundary_window_s`` that makes a high boundary tone (H%), answered by a U* baton
            of size ``up_scale``.
        prior_strength, prior_strength_sd, prior_accents: prior of the running accent strength.
    """

    pitch_rad: float = math.radians(5.0)
    yaw_rad: float = math.radians(6.0)
    roll_rad: float = math.radians(5.0)
    forward_rad: float = math.radians(6.0)
    neck_share: float = 0.4
    baton_attack_s: float = 0.12
    baton_decay_s: float = 0.25
    underliner_attack_s: float = 0.25
    underliner_decay_s: float = 0.3
    underliner_scale: float = 0.6
    head_lag_s: float = 0.01
    min_scale: float = 0.4
    max_scale: float = 1.0
    brow_z: float = 3.0
    brow_window_s: float = 0.03
    brow_m: float = 0.010
    brow_attack_s: float = 0.07
    brow_decay_s: float = 0.35
    brow_marked_only: bool = True
    brow_gap_s: float = 0.5
    blink_m: float = 0.014
    blink_close_s: float = 0.08
    blink_hold_s: float = 0.03
    blink_open_s: float = 0.18
    vowel_s: float = 0.12
    p_blink_accent: float = 0.1
    p_blink_boundary: float = 0.4
    spontaneous_per_min: float = 8.0
    refractory_s: float = 1.5
    jaw_max_rad: float = math.radians(12.0)
    jaw_floor_sd: float = 1.0
    jaw_span_sd: float = 2.5
    calm_s: float = 0.45
    nod_z: float = 0.5
    nod_gap_s: float = 1.5
    nod_rise_pitch_z: float = 1.0
    low_pitch_z: float = -0.5
    rise_z: float = 1.0
    rise_window_s: float = 0.25
    downstep_z: float = 0.5
    expanded_z: float = 1.5
    register_scale: float = 0.5
    boundary_window_s: float = 0.3
    boundary_rise_z: float = 0.8
    up_scale: float = 0.6
    prior_strength: float = 2.5
    prior_strength_sd: float = 1.0
    prior_accents: float = 5.0


def jog_goal(code: str, cfg: RuthConfig | None = None) -> np.ndarray:
    """Full-scale offsets (len(SIGNAL_JOINTS),) of jog ``code`` (with or without ``*``)."""
    c = cfg or RuthConfig()
    base = code.rstrip("*")
    if base not in JOG_CODES:
        raise GestureSimError(f"unknown jog code {code!r}; use one of {', '.join(JOG_CODES)} "
                              "(add * for a baton)")
    g = np.zeros(len(SIGNAL_JOINTS))
    n, h = c.neck_share, 1.0 - c.neck_share
    parts = _COMPOUND.get(base, base)
    for p in parts:
        if p in "DU":
            s = c.pitch_rad * (1.0 if p == "D" else -1.0)
            g[_J["neck_flex"]] += n * s
            g[_J["head_flex"]] += h * s
        elif p in "RL":
            s = c.yaw_rad * (-1.0 if p == "R" else 1.0)
            g[_J["neck_twist"]] += n * s
            g[_J["head_twist"]] += h * s
        elif p in "JC":
            s = c.roll_rad * (1.0 if p == "J" else -1.0)
            g[_J["neck_bend"]] += n * s
            g[_J["head_bend"]] += h * s
        else:  # F / B: neck flexion with the head flexing back (gaze level)
            s = c.forward_rad * (1.0 if p == "F" else -1.0)
            g[_J["neck_flex"]] += s
            g[_J["head_flex"]] -= s
    if base in ("TL", "TR"):  # the down-nod of a tilting nod is a small part of it
        g[_J["neck_flex"]] -= 0.5 * n * c.pitch_rad
        g[_J["head_flex"]] -= 0.5 * h * c.pitch_rad
    return g


def brow_goal(code: str, cfg: RuthConfig | None = None) -> np.ndarray:
    """Full-scale offsets (len(SIGNAL_JOINTS),) of brow ``code`` (:data:`BROW_CODES`, with or
    without ``*``): AU1 the inner brows up, AU2 the outer brows up (``brow_m`` each), AU4 the
    inner brows down and together (:mod:`gesture_sim.signals.face_rig`)."""
    from gesture_sim.signals import face_rig

    c = cfg or RuthConfig()
    base = code.rstrip("*")
    if base not in BROW_CODES:
        raise GestureSimError(f"unknown brow code {code!r}; use one of {', '.join(BROW_CODES)} "
                              "(add * for a baton)")
    g = np.zeros(len(SIGNAL_JOINTS))
    for side in ("left", "right"):
        if base in ("1+2", "1"):
            g[_J[f"{side}_brow_inner_raise"]] = c.brow_m
        if base in ("1+2", "2"):
            g[_J[f"{side}_brow_raise"]] = c.brow_m
        if base == "4":
            g[_J[f"{side}_brow_inner_raise"]] = -face_rig.AU4_DOWN_M
            g[_J[f"{side}_brow_inner_squeeze"]] = face_rig.AU4_SQUEEZE_M
    return g


def smile_goal() -> np.ndarray:
    """Full-scale offsets (len(SIGNAL_JOINTS),) of a smile (RUTH's ``S``): the mouth corners up
    and out (:data:`gesture_sim.signals.face_rig.SMILE_CORNER_UP_M`, ``_OUT_M``)."""
    from gesture_sim.signals import face_rig

    g = np.zeros(len(SIGNAL_JOINTS))
    for side in ("left", "right"):
        g[_J[f"{side}_lip_corner_up"]] = face_rig.SMILE_CORNER_UP_M
        g[_J[f"{side}_lip_corner_out"]] = face_rig.SMILE_CORNER_OUT_M
    return g


def _blink_goal(c: RuthConfig) -> np.ndarray:
    g = np.zeros(len(SIGNAL_JOINTS))
    g[_J["left_eyelid_close"]] = g[_J["right_eyelid_close"]] = c.blink_m
    return g


def rise(x: float) -> float:
    """Raised-cosine ramp 0 -> 1 over x in [0, 1]."""
    x = min(max(x, 0.0), 1.0)
    return 0.5 - 0.5 * math.cos(math.pi * x)


@dataclass
class Action:
    """One timed action (RUTH: goal, start, end, peak intensity, attack, decay).

    The offsets ramp from ``origin`` (the channel's offsets when it started: continuity after a
    replaced action) to ``goal * intensity`` over [start, peak], hold until ``release``, and
    decay to 0 over ``decay`` seconds; ``release`` is ``inf`` for an open underliner.
    """

    kind: str          # "baton" | "underliner"
    code: str
    goal: np.ndarray
    intensity: float
    start: float
    peak: float
    release: float
    decay: float
    origin: np.ndarray | None = None

    @property
    def end(self) -> float:
        return self.release + self.decay

    def level(self, t: float) -> float:
        """The envelope in [0, 1] at ``t``."""
        if t < self.start or t >= self.end:
            return 0.0
        if t < self.peak:
            return rise((t - self.start) / max(self.peak - self.start, 1e-6))
        if t < self.release:
            return 1.0
        return 1.0 - rise((t - self.release) / max(self.decay, 1e-6))

    def value(self, t: float) -> np.ndarray:
        """Offsets (len(SIGNAL_JOINTS),) at ``t``."""
        full = self.goal * self.intensity
        if self.origin is not None and self.start <= t < self.peak:
            w = self.level(t)
            return (1.0 - w) * self.origin + w * full
        return self.level(t) * full

    def close(self, t: float, decay: float) -> None:
        """Release an open (or holding) action at ``t`` with ``decay`` seconds to 0."""
        if t < self.release:
            self.release, self.decay = max(t, self.peak), decay


def _take_over(old: Action | None, new: Action, t: float, busy_until: str) -> bool:
    """Whether ``new`` may replace ``old`` at ``t`` (s): not while ``old`` has not reached its
    ``busy_until`` time (``"peak"`` or ``"release"``); a replaced action still under way hands
    its current offsets to ``new`` as its origin."""
    if old is not None and t < old.end:
        if t < getattr(old, busy_until):
            return False
        new.origin = old.value(t)
    return True


@dataclass
class Channel:
    """At most one underliner and one baton at a time (RUTH §2.2)."""

    name: str
    baton: Action | None = None
    underliner: Action | None = None

    def value(self, t: float) -> np.ndarray:
        out = np.zeros(len(SIGNAL_JOINTS))
        for a in (self.baton, self.underliner):
            if a is not None:
                out += a.value(t)
        return out

    def prune(self, t: float) -> None:
        if self.baton is not None and t >= self.baton.end:
            self.baton = None
        if self.underliner is not None and t >= self.underliner.end:
            self.underliner = None

    def add_baton(self, a: Action, t: float) -> bool:
        """Start baton ``a``; refused while the current one is still rising (before its peak);
        a decaying one is replaced, the new one starting from its current offsets."""
        if not _take_over(self.baton, a, t, "peak"):
            return False
        self.baton = a
        return True

    def add_underliner(self, a: Action, t: float) -> bool:
        """Start underliner ``a``; refused while another one has not begun to release."""
        if not _take_over(self.underliner, a, t, "release"):
            return False
        self.underliner = a
        return True


# ----------------------------------------------------------------------------------- markup

@dataclass(frozen=True)
class MarkupItem:
    """One label: ``label`` in accent, boundary, jog, brow, blink; ``code`` (jog code with
    ``*`` for a baton, ``1+2``/``1+2*`` for brows); ``t0``..``t1`` seconds (equal for a point);
    ``strength`` for accents (z units)."""

    t0: float
    t1: float
    label: str
    code: str = ""
    strength: float = 3.0


@dataclass
class Markup:
    """A parsed ``--signals`` file: its labels (sorted by start) and whether ``auto`` is on."""

    items: list[MarkupItem] = field(default_factory=list)
    auto: bool = True
    source: str = ""

    @property
    def accents(self) -> list[MarkupItem]:
        return [i for i in self.items if i.label == "accent"]

    @property
    def boundaries(self) -> list[MarkupItem]:
        return [i for i in self.items if i.label == "boundary"]


_TIME = r"(\d+(?:\.\d*)?|\.\d+)"
_LINE = re.compile(rf"^{_TIME}(?:\s*-\s*{_TIME})?\s+([A-Za-z]+)(?:\s+(\S+))?\s*$")


def parse_markup(text: str, source: str = "signals") -> Markup:
    """Parse markup text (see the module docstring).

    Raises:
        GestureSimError: one line naming ``source``, the line number and what is wrong.
    """
    m = Markup(source=source)
    for no, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        where = f"{source}:{no}"
        if line.lower() in ("auto off", "auto on"):
            m.auto = line.lower() == "auto on"
            continue
        g = _LINE.match(line)
        if g is None:
            raise GestureSimError(f"{where}: expected 'TIME LABEL [VALUE]' or "
                                  f"'START-END LABEL VALUE', got {raw.strip()!r}")
        t0 = float(g.group(1))
        t1 = float(g.group(2)) if g.group(2) else t0
        label, value = g.group(3).lower(), g.group(4) or ""
        if t1 < t0:
            raise GestureSimError(f"{where}: span ends before it starts ({t0:g}-{t1:g})")
        span = t1 > t0
        if label == "accent":
            try:
                strength = float(value) if value else 3.0
            except ValueError:
                raise GestureSimError(f"{where}: accent strength must be a number, "
                                      f"got {value!r}") from None
            m.items.append(MarkupItem(t0, t0, "accent", strength=strength))
        elif label in ("boundary", "blink"):
            if value or span:
                raise GestureSimError(f"{where}: '{label}' takes a time only")
            m.items.append(MarkupItem(t0, t0, label))
        elif label in ("nod", "jog"):
            code = "D*" if label == "nod" else value.upper()
            if label == "nod" and value:
                raise GestureSimError(f"{where}: 'nod' takes no value (use 'jog CODE')")
            if not code:
                raise GestureSimError(f"{where}: 'jog' needs a code ({', '.join(JOG_CODES)})")
            if code.rstrip("*") not in JOG_CODES:
                raise GestureSimError(f"{where}: unknown jog code {value!r}; use one of "
                                      f"{', '.join(JOG_CODES)} (add * for a baton)")
            _check_form(where, code, span)
            m.items.append(MarkupItem(t0, t1, "jog", code))
        elif label in ("brow", "smile"):
            default = "1+2" if label == "brow" else "S"
            codes = BROW_CODES if label == "brow" else ("S",)
            code = value.upper() or (default if span else default + "*")
            if code.rstrip("*") not in codes:
                raise GestureSimError(f"{where}: unknown {label} code {value!r}; use "
                                      f"{', '.join(codes)} (add * for a baton)")
            _check_form(where, code, span)
            m.items.append(MarkupItem(t0, t1, label, code))
        else:
            raise GestureSimError(f"{where}: unknown label {label!r}; use accent, boundary, "
                                  "nod, jog, brow, smile, blink or 'auto off'")
    m.items.sort(key=lambda i: (i.t0, i.t1))
    return m


def _check_form(where: str, code: str, span: bool) -> None:
    if code.endswith("*") and span:
        raise GestureSimError(f"{where}: a baton ({code}) is a point in time, not a span")
    if not code.endswith("*") and not span:
        raise GestureSimError(f"{where}: an underliner ({code}) needs a span START-END "
                              f"(or write {code}* for a baton)")


def load_markup(path: str | Path) -> Markup:
    """Read and parse a ``--signals`` file (errors are one line, naming the file)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise GestureSimError(f"cannot read signals file {p}: "
                              f"{getattr(exc, 'strerror', None) or exc}") from None
    return parse_markup(text, source=str(p))


# -------------------------------------------------------------------------------- scheduler

class RuthSignals:
    """The causal signal scheduler (see the module docstring).

    Args:
        config: :class:`RuthConfig`. seed: seeds the blink choices (reproducible runs).
        markup: labels that drive or override the signals (:func:`parse_markup`).

    Per control step call :meth:`step`; :attr:`events` keeps every event ``(t, text)``.
    """

    def __init__(self, config: RuthConfig | None = None, seed: int = 0,
                 markup: Markup | None = None) -> None:
        self.cfg = config or RuthConfig()
        self.seed = int(seed)
        self.markup = markup
        #: Whether the jaw opens with the loudness (the mouth's degraded mode without phones;
        #: a :class:`~gesture_sim.stages.MouthLayer` turns it off).
        self.loudness_jaw = True
        self._smile = smile_goal()
        self._blink = _blink_goal(self.cfg)
        self.reset()

    def reset(self) -> None:
        """A new stream at t = 0."""
        self.rng = np.random.default_rng(self.seed)
        self.channels = {name: Channel(name) for name in CHANNELS}
        self.events: list[tuple[float, str]] = []
        self._new: list[tuple[float, str]] = []
        self._boundaries: list[Boundary] = []
        self._accent_queue: list[Accent] = []
        self._blinks_due: list[tuple[float, str]] = []
        self._last_blink = -math.inf
        self._next_spont = self._draw_spont(0.0)
        # accent strength (z units): mean and SD from the prior, a cumulative average
        self._strength = RunningStat(self.cfg.prior_strength, self.cfg.prior_strength_sd ** 2,
                                     self.cfg.prior_accents, var_floor=1e-6)
        self._phrase_open = False
        self._phrase_count = 0
        self._phrase_h: float | None = None   # F0 z of the phrase's last H accent
        self._last_nod = -math.inf
        self._last_brow = -math.inf
        self._calm = True
        self._jaw = 0.0
        self._frames: list[tuple[float, float, bool]] = []
        # frame intensity (dB) and F0 (st): the mean from the first frame, the SD from a prior
        self._i_stat = RunningStat(var=_I_PRIOR_VAR, prior=_FRAME_PRIOR,
                                   min_weight=1.0 / _FRAME_MEMORY, location="first",
                                   var_floor=1e-6)
        self._f_stat = RunningStat(var=_F_PRIOR_VAR, prior=_FRAME_PRIOR,
                                   min_weight=1.0 / _FRAME_MEMORY, location="first",
                                   var_floor=1e-6)
        self._recent: list[tuple[float, float, float]] = []  # (centre, zI, zF) of known frames
        self._t_frame = -math.inf
        self._brow_pending: list[float] = []  # accent times awaiting the brow decision
        self._plan: list[MarkupItem] = list(self.markup.items) if self.markup else []
        self._auto = self.markup.auto if self.markup else True
        self._override_acc = bool(self.markup and self.markup.accents)
        self._override_bnd = bool(self.markup and self.markup.boundaries)

    # ------------------------------------------------------------------ inputs
    def push_frames(self, times: np.ndarray, intensity_db: np.ndarray, silent: np.ndarray,
                    known: np.ndarray, f0_hz: np.ndarray | None = None) -> None:
        """Prosody frames (each (n,)): centre times (s), intensity (dB), silent flags, the
        stream time each became known (s) and F0 (Hz, NaN/0 unvoiced; optional); used once
        ``known <= t`` (causal)."""
        n = len(np.asarray(times))
        f0 = np.full(n, np.nan) if f0_hz is None else np.asarray(f0_hz, float)
        self._frames.extend(zip(np.asarray(known, float).tolist(),
                                np.asarray(times, float).tolist(),
                                np.asarray(intensity_db, float).tolist(),
                                np.asarray(silent, bool).tolist(), f0.tolist(), strict=True))

    def step(self, t: float, accents: Iterable[Accent] = (),
             boundaries: Iterable[Boundary] = (), speaking: bool = False,
             silence_s: float = 0.0) -> tuple[np.ndarray, list[tuple[float, str]]]:
        """Advance to control step ``t`` (s).

        Args:
            accents, boundaries: newly emitted ones (used once ``t_emitted <= t``).
            speaking, silence_s: the detector's voice activity as known at ``t``.

        Returns:
            (offsets (len(SIGNAL_JOINTS),), the events of this step).
        """
        c = self.cfg
        self._new = []
        eps = 1e-9
        if not self._override_acc:
            self._accent_queue.extend(accents)
        if not self._override_bnd:
            self._boundaries.extend(boundaries)
        self._update_frames(t)
        calm = (not speaking) and silence_s >= c.calm_s
        if calm and not self._calm:
            self._enter_calm(t)
        self._calm = calm
        # detector input (auto)
        ready = [a for a in self._accent_queue if a.t_emitted <= t + eps]
        self._accent_queue = [a for a in self._accent_queue if a.t_emitted > t + eps]
        for a in ready:
            if self._auto and not calm:
                self._on_accent(t, a.t, a.strength, ahead=False, pitch_z=a.pitch_z)
        self._decide_brows(t, calm)
        bready = [b for b in self._boundaries if b.t_emitted <= t + eps]
        self._boundaries = [b for b in self._boundaries if b.t_emitted > t + eps]
        for b in bready:
            if self._auto:
                self._on_boundary(t, b.t)
        # markup (known in advance: started early enough to peak at the labelled time)
        self._run_plan(t)
        # blinks
        self._run_blinks(t, spontaneous=self._auto or self.markup is None)
        out = np.zeros(len(SIGNAL_JOINTS))
        for ch in self.channels.values():
            ch.prune(t)
            out += ch.value(t)
        if self.loudness_jaw:
            out[_J["jaw_open"]] += self._jaw
        self.events.extend(self._new)
        return out, self._new

    # ------------------------------------------------------------------ rules
    def _strength_z(self, s: float) -> float:
        """z of an accent strength against the strengths before it; then absorb it."""
        z = self._strength.z(s)
        self._strength.update(s)
        return z

    def accent_type(self, t_acc: float, pitch_z: float = 0.0) -> tuple[str, float]:
        """The ToBI type (:data:`ACCENT_TYPES`) of an accent at ``t_acc`` from the F0 frames
        known so far, and its F0 z: L* at or below ``low_pitch_z``; L+H* when F0 rose by
        ``rise_z`` over the ``rise_window_s`` before it; !H* when ``downstep_z`` below the
        phrase's previous H accent; else H*. Without voiced frames near it, ``pitch_z`` (the
        detector's) gives the level."""
        c = self.cfg
        near = [zf for tc, _, zf in self._recent if abs(tc - t_acc) <= 0.05 and zf != 0.0]
        before = [zf for tc, _, zf in self._recent
                  if t_acc - c.rise_window_s <= tc < t_acc - 0.05 and zf != 0.0]
        pz = max(near) if near else float(pitch_z)
        if pz <= c.low_pitch_z:
            return "L*", pz
        if near and before and pz - min(before) >= c.rise_z:
            return "L+H*", pz
        if self._phrase_h is not None and pz <= self._phrase_h - c.downstep_z:
            return "!H*", pz
        return "H*", pz

    def _on_accent(self, now: float, t_acc: float, strength: float, ahead: bool,
                   pitch_z: float = 0.0) -> None:
        """RUTH's rules on an accent: the phrase's underliner opens on its first accent; a D*
        baton on a strong H-type accent (not on every accent); brows by accent type; a
        register underliner on an expanded phrase; sometimes a blink after the vowel."""
        c = self.cfg
        z = self._strength_z(strength)
        kind, pz = ("H*", 0.0) if ahead else self.accent_type(t_acc, pitch_z)
        self._emit(t_acc, f"accent {kind}")
        scale = min(max(0.7 + 0.2 * z, c.min_scale), c.max_scale)
        peak = now + max(c.baton_attack_s - c.head_lag_s, 0.04)
        if ahead:
            peak = max(t_acc - c.head_lag_s, now + 0.04)
        jog = self.channels["jog"]
        first = not self._phrase_open
        if first:
            self._phrase_open = True
            self._phrase_count += 1
            self._phrase_h = None
            code = "TL" if self._phrase_count % 2 else "TR"
            u = Action("underliner", code, jog_goal(code, c), c.underliner_scale, now,
                       now + c.underliner_attack_s, math.inf, c.underliner_decay_s)
            if jog.add_underliner(u, now):
                self._emit(now, f"jog {code}")
        h_type = kind in ("H*", "L+H*")
        if h_type and self._phrase_h is None and pz >= c.expanded_z and not ahead:
            br = Action("underliner", "1+2", brow_goal("1+2", c), c.register_scale, now,
                        now + c.underliner_attack_s, math.inf, c.underliner_decay_s)
            if self.channels["brow"].add_underliner(br, now):
                self._last_brow = now
                self._emit(now, "brow 1+2 register H^H")
        if h_type:
            self._phrase_h = pz
        marked = z >= c.nod_z or (kind == "L+H*" and pz >= c.nod_rise_pitch_z)
        if h_type and marked and now - self._last_nod >= c.nod_gap_s:
            b = Action("baton", "D*", jog_goal("D", c), scale, now, peak, peak, c.baton_decay_s)
            if jog.add_baton(b, now):
                self._last_nod = now
                self._emit(peak, "nod D*")
        if ahead:  # a labelled accent: strong when its strength says so
            if z >= 0.5:
                bp = max(t_acc, now + 0.04)
                self._start_brow(now, bp)
        elif h_type and (marked or not c.brow_marked_only):
            self._brow_pending.append(t_acc)
        if self.rng.random() < c.p_blink_accent:
            self._blinks_due.append((max(t_acc + c.vowel_s, now), "accent"))

    def _start_brow(self, now: float, peak: float) -> None:
        br = Action("baton", "1+2*", brow_goal("1+2", self.cfg), 1.0, now, peak, peak,
                    self.cfg.brow_decay_s)
        if self.channels["brow"].add_baton(br, now):
            self._emit(peak, "brow 1+2*")

    def _decide_brows(self, t: float, calm: bool) -> None:
        """Brow batons for pending accents whose judged frames are all known."""
        c = self.cfg
        keep = []
        for ta in self._brow_pending:
            if self._t_frame < ta + c.brow_window_s - 1e-9:
                keep.append(ta)
                continue
            win = [(zi, zf) for tc, zi, zf in self._recent
                   if ta - c.brow_window_s - 1e-9 <= tc <= ta + c.brow_window_s + 1e-9]
            if win and not calm:
                prom = max(zi for zi, _ in win) + max(max(zf for _, zf in win), 0.0)
                if prom >= c.brow_z and t - self._last_brow >= c.brow_gap_s - 1e-9:
                    self._last_brow = t
                    self._start_brow(t, t + c.brow_attack_s)
        self._brow_pending = keep

    def boundary_tone(self, t_end: float) -> str:
        """``"H%"`` when F0 rose by ``boundary_rise_z`` over the phrase's last
        ``boundary_window_s`` (voiced frames up to ``t_end``), else ``"L%"``."""
        c = self.cfg
        zs = [(tc, zf) for tc, _, zf in self._recent
              if t_end - c.boundary_window_s <= tc <= t_end + 1e-9 and zf != 0.0]
        if len(zs) < 4:
            return "L%"
        k = max(len(zs) // 3, 1)
        start = float(np.mean([z for _, z in zs[:k]]))
        end = float(np.mean([z for _, z in zs[-k:]]))
        return "H%" if end - start >= c.boundary_rise_z else "L%"

    def _on_boundary(self, now: float, t_end: float) -> None:
        """A phrase ends: its underliners release; a high boundary tone (H%) gets a small U*
        baton; sometimes a blink."""
        c = self.cfg
        tone = self.boundary_tone(t_end)
        self._emit(t_end, f"boundary {tone}")
        for ch in (self.channels["jog"], self.channels["brow"]):
            u = ch.underliner
            if u is not None and now < u.release:
                u.close(now, c.underliner_decay_s)
                self._emit(now, f"{ch.name} end")
        if tone == "H%" and now - self._last_nod >= c.nod_gap_s:
            peak = now + max(c.baton_attack_s - c.head_lag_s, 0.04)
            b = Action("baton", "U*", jog_goal("U", c), c.up_scale, now, peak, peak,
                       c.baton_decay_s)
            if self.channels["jog"].add_baton(b, now):
                self._last_nod = now
                self._emit(peak, "jog U*")
        self._phrase_open = False
        if self.rng.random() < c.p_blink_boundary:
            self._blinks_due.append((now, "boundary"))

    def _enter_calm(self, t: float) -> None:
        for ch in self.channels.values():
            for a in (ch.baton, ch.underliner):
                if a is not None and ch.name != "blink":
                    a.close(t, self.cfg.underliner_decay_s)
        self._phrase_open = False
        self._emit(t, "calm")

    def _run_plan(self, t: float) -> None:
        c = self.cfg
        while self._plan:
            it = self._plan[0]
            lead = {"accent": c.baton_attack_s, "jog": c.baton_attack_s,
                    "brow": c.brow_attack_s, "smile": c.brow_attack_s}.get(it.label, 0.0)
            if it.label in ("jog", "brow", "smile") and not it.code.endswith("*"):
                lead = 0.0
            if t + 1e-9 < it.t0 - lead - (c.head_lag_s if it.label in ("accent", "jog") else 0):
                break
            self._plan.pop(0)
            if it.label == "accent":
                if self._auto:
                    self._on_accent(t, it.t0, it.strength, ahead=True)
            elif it.label == "boundary":
                if self._auto:
                    self._on_boundary(t, it.t0)
            elif it.label == "blink":
                self._blinks_due.append((max(it.t0 - c.blink_close_s, t), "label"))
            elif it.label == "jog" and it.code.endswith("*"):
                peak = max(it.t0 - c.head_lag_s, t + 0.04)
                a = Action("baton", it.code, jog_goal(it.code, c), 1.0, t, peak, peak,
                           c.baton_decay_s)
                if self.channels["jog"].add_baton(a, t):
                    self._emit(peak, f"jog {it.code}")
            elif it.label in ("brow", "smile") and it.code.endswith("*"):
                peak = max(it.t0, t + 0.04)
                a = Action("baton", it.code, self._goal(it), 1.0, t, peak, peak, c.brow_decay_s)
                if self.channels[it.label].add_baton(a, t):
                    self._emit(peak, f"{it.label} {it.code}")
            else:  # an underliner over the span: ramp in, hold, ramp out inside it
                span = it.t1 - it.t0
                att = min(c.underliner_attack_s, span / 3)
                dec = min(c.underliner_decay_s, span / 3)
                a = Action("underliner", it.code, self._goal(it), 1.0 if it.label != "jog"
                           else c.underliner_scale, t, t + att, max(it.t1 - dec, t + att), dec)
                if self.channels[it.label].add_underliner(a, t):
                    self._emit(t, f"{it.label} {it.code}")

    def _goal(self, it: MarkupItem) -> np.ndarray:
        """Full-scale offsets of a labelled brow, smile or jog signal."""
        if it.label == "brow":
            return brow_goal(it.code, self.cfg)
        if it.label == "smile":
            return self._smile
        return jog_goal(it.code, self.cfg)

    def smile_level(self, t: float) -> float:
        """The smile's current level in [0, 1] (what the mouth's shape blends with)."""
        ch = self.channels["smile"]
        return float(sum(a.level(t) * a.intensity for a in (ch.baton, ch.underliner)
                         if a is not None))

    def _draw_spont(self, t: float) -> float:
        rate = self.cfg.spontaneous_per_min / 60.0
        return t + (float(self.rng.exponential(1.0 / rate)) if rate > 0 else math.inf)

    def _run_blinks(self, t: float, spontaneous: bool) -> None:
        c = self.cfg
        if spontaneous and t >= self._next_spont:
            self._blinks_due.append((t, "spontaneous"))
            self._next_spont = self._draw_spont(t)
        due = [b for b in self._blinks_due if b[0] <= t + 1e-9]
        self._blinks_due = [b for b in self._blinks_due if b[0] > t + 1e-9]
        for _, why in due:
            if t - self._last_blink < c.refractory_s and why != "label":
                continue
            peak = t + c.blink_close_s
            a = Action("baton", "blink", self._blink, 1.0, t, peak, peak + c.blink_hold_s,
                       c.blink_open_s)
            if self.channels["blink"].add_baton(a, t):
                self._last_blink = t
                self._emit(peak, f"blink {why}")

    def _update_frames(self, t: float) -> None:
        """Absorb the frames known at ``t``: the jaw, and the frame z values for the brows."""
        c = self.cfg
        k = 0
        for known, tc, i_db, silent, f0 in self._frames:
            if known > t + 1e-9:
                break
            k += 1
            self._t_frame = tc
            if silent or not math.isfinite(i_db):
                self._jaw = 0.0
                continue
            ist, fst = self._i_stat, self._f_stat
            zi = ist.z(i_db) if ist.n else 0.0  # against the frames before this one
            zf = 0.0
            if math.isfinite(f0) and f0 > 0:
                st = semitones(f0, 100.0)
                zf = fst.z(st) if fst.n else 0.0
                fst.update(st)
            self._recent.append((tc, zi, zf))
            if len(self._recent) > 200:          # keep the last 1-2 s of voiced frames
                del self._recent[:-100]
            ist.update(i_db)
            sd = ist.sd
            x = (i_db - (ist.mean - c.jaw_floor_sd * sd)) / (c.jaw_span_sd * sd)
            self._jaw = c.jaw_max_rad * min(max(x, 0.0), 1.0)
        if k:
            del self._frames[:k]

    def _emit(self, t: float, text: str) -> None:
        self._new.append((round(float(t), 4), text))


def signal_counts(events: Sequence[tuple[float, str]]) -> dict[str, int]:
    """Counts of events by their first word and code, e.g. ``{"nod D*": 12, "blink": 5}``."""
    out: dict[str, int] = {}
    for _, text in events:
        key = "blink" if text.startswith("blink") else text
        out[key] = out.get(key, 0) + 1
    return out
