"""Chiu (2014)'s sign predictor: speech -> one of the 14 gestural signs per 1-s frame.

The second stage of the thesis's prediction (ch. 4; digest §4) on this project's inputs, adapted:
the code is the project's :class:`~gesture_sim.inference.dcnf.DCNF`, here with the **signs as its
states** (S = 14, :data:`SIGNS`) and a frame of ``frame_s`` seconds (1 s, the
thesis's §4.2.4) as its step.

**Inputs per frame** (:class:`FrameBuilder`; ``D = 7 + V + 13 + 14`` numbers):

* *Prosody* (:data:`PROSODY`, 7 numbers), from the prosody tracker's syllables whose middle
  falls in the frame, each normalised online by a
  :class:`~gesture_sim.inference.normalize.SpeakerNormalizer` in emission order (the same at
  training and run time); **all zero when the frame has no syllable** (the thesis zeroes its
  audio features when not speaking). Of the thesis's six (Scherer et al. 2013): F0 (mean z of
  the voiced syllables), energy (mean intensity z) and energy slope (least-squares slope of the
  syllables' intensity z over the frame, z/s) are computed; NAQ and peak slope (glottal-source
  measures) and spectral stationarity (a spectral measure) are not computed here and are
  **substituted** by the voiced share of the syllables, the F0 z range within the frame and the
  syllable rate (1/s); a speaking share (syllable time / frame time) is added.
* *Words* (V indicators): the training transcripts' vocabulary by count (``min_count``, at most
  ``max_vocab`` words, most frequent first), a word marking its frame and the ``context``
  frames before and after (the thesis's ±1-frame smear).
* *POS* (13 counts, :data:`POS_GROUPS`): the words' Penn tags (:mod:`gesture_sim.audio.pos`)
  folded into coarse groups, counted per frame.
* *Lexicon* (14 indicators): the sign cues of :func:`gesture_sim.signals.sign_lexicon.sign_cues`
  over the frames they span, smeared by ``context`` like the words.

Prosody is standardised with the training statistics; the indicators and counts are not (so a
weight on them reads in potential units per occurrence).

**Model.** ``P(y | x) ∝ exp(Σ_t u_t(y_t) + Σ_t α(y_{t-1}, y_t) [+ β(y_{t-1}, y_t, y_{t+1})])``
with ``u_t = θᵀ f(x_t) + b`` (Chiu Eq. 4.1/4.2). With ``hidden = ()`` (the default: the
shipped data is one minute) ``f(x) = x`` and the model is a linear-chain CRF; ``hidden =
(16,)`` gives Chiu's sigmoid network in front of the chain. Training maximises the conditional
log-likelihood of the labelled frames with L-BFGS (full batch, deterministic; Chiu's dropout
and SGD are not used) minus Gaussian penalties **centred on priors** instead of zero where the
data are few:

* the first-order chain weights α are pulled towards ``log P(to | from)`` of the thesis's
  Table A.1 (:data:`TABLE_A1`; weight ``prior_weight`` per frame of data): the fallback where
  the shipped data cannot estimate 196 transitions;
* the node bias is pulled (``bias_weight``) towards the log sign shares of Table A.1, so a sign
  the data never show keeps about the thesis's rate instead of going to minus infinity;
* with a linear model, the weight of lexicon input "sign s" on state s is pulled towards
  ``lexicon_weight`` (the dictionary as a prior: a sign the words call for is favoured even
  when the training data never saw that word), all other weights towards 0 (``l2``).

**Decoding.** Offline: Viterbi (:meth:`SignModel.decode`), exact for order 1 and 2 (over
pairs), and marginals by forward-backward. Live: :class:`SignFilter`, the causal forward
filter; it trades the future context away (no later frames, the next frame's words unknown,
words only once said and recognised), so it reads each frame with at most the evidence heard so
far; on the last frame of a sequence the filter's belief equals the exact marginal.

**Storage.** ``signs.npz`` (the DCNF arrays) + ``signs.json`` (settings, vocabulary, input
layout, training summary, the library segment signs it was trained with).
"""

from __future__ import annotations

import json
import math
import os
import re
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.contracts import Syllable
from gesture_sim.inference.dcnf import DCNF, ChainStats, objective_and_gradient
from gesture_sim.inference.normalize import SpeakerNormalizer

#: The 14 signs (Chiu Table 3.1; the order of :data:`gesture_sim.motion.signs.SIGNS`).
SIGNS: tuple[str, ...] = (
    "Rest", "Palm-face-up", "Head-nod", "Wipe", "Whole", "Frame", "Dismiss", "Block", "Shrug",
    "More-or-less", "Process", "Deictic.Other", "Deictic.Self", "Beats")
N_SIGNS = len(SIGNS)
SIGN_INDEX = {s: i for i, s in enumerate(SIGNS)}

#: Prosody inputs per frame (module docstring; all 0 in a frame without syllables).
PROSODY: tuple[str, ...] = ("speaking_share", "voiced_share", "f0_z", "f0_range_z",
                            "intensity_z", "intensity_slope_z_per_s", "syllable_rate_hz")
#: Coarse part-of-speech groups (Penn tag prefixes; the last takes the rest).
POS_GROUPS: tuple[str, ...] = ("NN", "VB", "JJ", "RB", "PRP", "DT", "IN", "CC", "UH", "W",
                               "MD", "CD", "other")

#: Chiu (2014) Table A.1: transitions between signs in % of all transitions (row = from,
#: column = to; the digest's reconstruction, in :data:`SIGNS` order).
TABLE_A1 = np.array([
    [29.4, 1.23, 1.5, 0.09, 0.02, 0.06, 0.06, 0.03, 0.57, 0.06, 0.09, 0.59, 0.08, 2.83],
    [1.05, 3.67, 0.13, 0.008, 0.004, 0.005, 0.005, 0.003, 0.03, 0.003, 0.02, 0.08, 0.03, 0.38],
    [1.38, 0.13, 5.97, 0.008, 0.003, 0.005, 0.01, 0.005, 0.06, 0.001, 0.02, 0.08, 0.008, 0.34],
    [0.12, 0.01, 0.01, 0.5, 0.001, 0.003, 0.001, 0, 0.003, 0, 0.001, 0.02, 0.001, 0.06],
    [0.03, 0.001, 0, 0.001, 0.12, 0.003, 0, 0, 0, 0, 0.003, 0.004, 0.001, 0.02],
    [0.04, 0.004, 0.001, 0.008, 0.001, 0.33, 0, 0.001, 0.001, 0, 0.001, 0.009, 0.004, 0.04],
    [0.07, 0.009, 0.003, 0, 0.001, 0, 0.19, 0, 0.003, 0, 0, 0.01, 0.001, 0.02],
    [0.04, 0.003, 0.004, 0.003, 0, 0.003, 0, 0.11, 0, 0, 0.001, 0.003, 0, 0.01],
    [0.52, 0.04, 0.07, 0.003, 0, 0.001, 0.004, 0.001, 0.91, 0, 0.001, 0.02, 0.003, 0.05],
    [0.03, 0.004, 0.008, 0.001, 0.001, 0, 0, 0, 0, 0.11, 0, 0.004, 0, 0.01],
    [0.09, 0.01, 0.009, 0.003, 0, 0.003, 0.001, 0.001, 0, 0.001, 0.62, 0.02, 0.001, 0.05],
    [0.6, 0.05, 0.06, 0.02, 0.009, 0.01, 0.008, 0.003, 0.004, 0.004, 0.01, 2.53, 0.03, 0.4],
    [0.07, 0.03, 0.005, 0.005, 0, 0.001, 0, 0.003, 0, 0.003, 0.001, 0.05, 0.62, 0.14],
    [2.88, 0.25, 0.4, 0.08, 0.02, 0.03, 0.03, 0.02, 0.06, 0.01, 0.04, 0.34, 0.15, 36.6],
])

#: Version of the sign-model files; another major is refused.
SIGN_MODEL_FORMAT = "1.0"
SIGN_MODEL_NPZ = "signs.npz"
SIGN_MODEL_JSON = "signs.json"


def table_a1_log_transitions(floor_pct: float = 1e-3) -> np.ndarray:
    """(S, S) ``log P(to | from)`` of Table A.1, zero cells floored at ``floor_pct`` percent."""
    t = np.maximum(TABLE_A1, floor_pct)
    return np.log(t / t.sum(axis=1, keepdims=True))


def table_a1_marginals() -> np.ndarray:
    """(S,) share of frames per sign implied by Table A.1 (row sums, normalised)."""
    r = TABLE_A1.sum(axis=1)
    return r / r.sum()


# --- words -------------------------------------------------------------------------------------

_TOKEN = re.compile(r"[a-z0-9']+")


def word_tokens(text: str) -> list[str]:
    """Lower-case tokens of a transcript word (punctuation dropped, apostrophes kept)."""
    return _TOKEN.findall(str(text).lower().replace("\u2019", "'"))


def timed_words(words: Sequence[Any]) -> list[tuple[float, float, str]]:
    """``(start_s, end_s, text)`` of :class:`~gesture_sim.audio.phones.Word`-like objects or of
    such tuples, in time order, empty words left out."""
    out = []
    for w in words:
        if isinstance(w, tuple | list):
            a, b, t = w
        else:
            a, b, t = w.start_s, w.end_s, w.text
        if str(t).strip():
            out.append((float(a), float(b), str(t)))
    return sorted(out, key=lambda x: (x[0], x[1]))


def pos_group(tags: Sequence[str]) -> int:
    """Index into :data:`POS_GROUPS` of a word's Penn tags (its first token's tag)."""
    tag = tags[0] if tags else ""
    for i, g in enumerate(POS_GROUPS[:-1]):
        if tag.startswith(g):
            return i
    return len(POS_GROUPS) - 1


def build_vocabulary(transcripts: Sequence[Sequence[Any]], min_count: int = 2,
                     max_vocab: int = 817) -> list[str]:
    """The vocabulary by count over training transcripts (each a sequence of timed words):
    tokens seen at least ``min_count`` times, most frequent first (ties alphabetical), at most
    ``max_vocab`` (817, the thesis's size after its ≥ 10 cut)."""
    counts: dict[str, int] = {}
    for words in transcripts:
        for _, _, text in timed_words(words):
            for tok in word_tokens(text):
                counts[tok] = counts.get(tok, 0) + 1
    keep = [w for w, c in counts.items() if c >= min_count]
    keep.sort(key=lambda w: (-counts[w], w))
    return keep[:max_vocab]


# --- frames ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class InputLayout:
    """Which inputs a model reads (the column blocks of a frame's vector).

    Attributes:
        vocabulary: the word list (V,); prosody, words, pos, lexicon: blocks switched on (a
            block switched off is all zeros, so the shapes stay).
        frame_s: frame length (s); context: frames of word/lexicon smear either side.
    """

    vocabulary: tuple[str, ...] = ()
    prosody: bool = True
    words: bool = True
    pos: bool = True
    lexicon: bool = True
    frame_s: float = 1.0
    context: int = 1

    @property
    def n_inputs(self) -> int:
        """D, numbers per frame."""
        return len(PROSODY) + len(self.vocabulary) + len(POS_GROUPS) + N_SIGNS

    def blocks(self) -> dict[str, slice]:
        """Column slice of each block."""
        a = len(PROSODY)
        b = a + len(self.vocabulary)
        c = b + len(POS_GROUPS)
        return {"prosody": slice(0, a), "words": slice(a, b), "pos": slice(b, c),
                "lexicon": slice(c, c + N_SIGNS)}

    def to_dict(self) -> dict:
        d = asdict(self)
        d["vocabulary"] = list(self.vocabulary)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> InputLayout:
        d = dict(d)
        d["vocabulary"] = tuple(d.get("vocabulary", ()))
        return cls(**d)


class FrameBuilder:
    """Per-frame evidence (syllables, words, tags, cues) and the input vector of a frame.

    Used whole by :func:`frame_inputs` (offline) and incrementally by :class:`SignFilter`
    (live): ``add_syllable`` with a syllable's normalised features (3,) as
    :meth:`~gesture_sim.inference.normalize.SpeakerNormalizer.features` gives them,
    ``add_word`` with a word's time, text and POS group, ``add_cue`` with a sign cue's span and
    sign; ``row(k)`` is the (D,) input of frame k.
    """

    def __init__(self, layout: InputLayout) -> None:
        self.layout = layout
        self._vocab = {w: i for i, w in enumerate(layout.vocabulary)}
        self.syllables: dict[int, list[tuple[float, float, np.ndarray]]] = {}
        self.words: dict[int, set[int]] = {}
        self.pos: dict[int, np.ndarray] = {}
        self.cues: dict[int, set[int]] = {}

    def frame_of(self, t: float) -> int:
        """The frame index of time t (s)."""
        return int(math.floor(max(t, 0.0) / self.layout.frame_s))

    def add_syllable(self, t_start: float, t_end: float, features: np.ndarray) -> None:
        k = self.frame_of(0.5 * (t_start + t_end))
        self.syllables.setdefault(k, []).append((t_start, t_end, np.asarray(features, float)))

    def add_word(self, t_start: float, t_end: float, text: str, group: int) -> None:
        k = self.frame_of(0.5 * (t_start + t_end))
        ids = {self._vocab[t] for t in word_tokens(text) if t in self._vocab}
        if ids:
            self.words.setdefault(k, set()).update(ids)
        self.pos.setdefault(k, np.zeros(len(POS_GROUPS)))[group] += 1.0

    def add_cue(self, t_start: float, t_end: float, sign: str) -> None:
        for k in range(self.frame_of(t_start), self.frame_of(max(t_end - 1e-6, t_start)) + 1):
            self.cues.setdefault(k, set()).add(SIGN_INDEX[sign])

    def forget_before(self, k: int) -> None:
        """Drop the evidence of frames before k (live: memory stays flat)."""
        for d in (self.syllables, self.words, self.pos, self.cues):
            for j in [j for j in d if j < k]:
                del d[j]

    def prosody(self, k: int, span_s: float | None = None) -> np.ndarray:
        """The (7,) prosody of frame k (:data:`PROSODY`); ``span_s``: the part of the frame
        heard so far (s; live, the current frame), over which shares and rates are taken."""
        out = np.zeros(len(PROSODY))
        syl = self.syllables.get(k)
        if not syl:
            return out
        fs = self.layout.frame_s if span_s is None else min(max(span_s, 0.2),
                                                             self.layout.frame_s)
        length = sum(max(b - a, 0.0) for a, b, _ in syl)
        f0 = np.array([x[0] for _, _, x in syl if np.isfinite(x[0])])
        it = np.array([x[1] for _, _, x in syl])
        tm = np.array([0.5 * (a + b) for a, b, _ in syl])
        slope = 0.0
        if len(syl) >= 2 and np.ptp(tm) > 1e-3:
            slope = float(np.polyfit(tm - tm.mean(), it, 1)[0])
        out[:] = [min(length / fs, 1.0), len(f0) / len(syl),
                  float(f0.mean()) if len(f0) else 0.0,
                  float(np.ptp(f0)) if len(f0) else 0.0,
                  float(it.mean()), float(np.clip(slope, -20.0, 20.0)), len(syl) / fs]
        return out

    def row(self, k: int, span_s: float | None = None) -> np.ndarray:
        """The (D,) input of frame k (blocks switched off stay zero; ``span_s`` as for
        :meth:`prosody`)."""
        lay = self.layout
        x = np.zeros(lay.n_inputs)
        b = lay.blocks()
        if lay.prosody:
            x[b["prosody"]] = self.prosody(k, span_s)
        c = lay.context
        if lay.words:
            w = x[b["words"]]
            for j in range(k - c, k + c + 1):
                for i in self.words.get(j, ()):
                    w[i] = 1.0
        if lay.pos and k in self.pos:
            x[b["pos"]] = self.pos[k]
        if lay.lexicon:
            lx = x[b["lexicon"]]
            for j in range(k - c, k + c + 1):
                for i in self.cues.get(j, ()):
                    lx[i] = 1.0
        return x


def syllable_features(syllables: Sequence[Syllable]) -> list[tuple[float, float, np.ndarray]]:
    """``(t_start, t_end, features (3,))`` of syllables normalised online in emission order
    (a fresh :class:`SpeakerNormalizer`, as :class:`SignFilter` does live)."""
    norm = SpeakerNormalizer()
    order = sorted(syllables, key=lambda s: s.t_emitted)
    return [(s.t_start, s.t_end, norm.features(s)) for s in order]


def word_annotations(words: Sequence[Any], tagger: str | None = None
                     ) -> tuple[list[tuple[float, float, str, int]],
                                list[tuple[float, float, str]]]:
    """(words with their POS group, lexicon cues ``(start_s, end_s, sign)``) of a transcript."""
    from gesture_sim.audio.pos import tag_words
    from gesture_sim.signals.sign_lexicon import sign_cues

    tw = timed_words(words)
    tags = tag_words([t for _, _, t in tw], tagger) if tw else []
    out = [(a, b, t, pos_group(tg)) for (a, b, t), tg in zip(tw, tags, strict=True)]
    cues = [(c.start_s, c.end_s, c.sign) for c in sign_cues(tw, tagger=tagger)] if tw else []
    return out, cues


def frame_inputs(layout: InputLayout, duration_s: float, syllables: Sequence[Syllable] = (),
                 words: Sequence[Any] = (), tagger: str | None = None) -> np.ndarray:
    """Inputs (n_frames, D) of a whole recording (offline: every frame sees its neighbours).

    Args:
        layout: the model's :class:`InputLayout`.
        duration_s: recording length (s); ``n_frames = ceil(duration_s / frame_s)``.
        syllables: the prosody tracker's syllables of the recording.
        words: timed words (:func:`timed_words` accepts Word objects or tuples).
        tagger: the POS backend (default: the best available).
    """
    fb = FrameBuilder(layout)
    for a, b, x in syllable_features(syllables):
        fb.add_syllable(a, b, x)
    if words:
        ws, cues = word_annotations(words, tagger)
        for a, b, t, g in ws:
            fb.add_word(a, b, t, g)
        for a, b, s in cues:
            fb.add_cue(a, b, s)
    n = max(int(math.ceil(duration_s / layout.frame_s - 1e-9)), 1)
    return np.array([fb.row(k) for k in range(n)]).reshape(n, layout.n_inputs)


def frame_labels(spans: Sequence[tuple[float, float, str]], n_frames: int,
                 frame_s: float = 1.0, default: str | None = "Rest") -> np.ndarray:
    """Sign index (n_frames,) of each frame: the sign covering most of it among ``spans``
    ``(start_s, end_s, sign)``; frames no span touches get ``default`` (-1 when None)."""
    cover = np.zeros((n_frames, N_SIGNS))
    for a, b, s in spans:
        i = SIGN_INDEX[s]
        for k in range(max(int(a // frame_s), 0), min(int(math.ceil(b / frame_s)), n_frames)):
            lo, hi = max(a, k * frame_s), min(b, (k + 1) * frame_s)
            if hi > lo:
                cover[k, i] += hi - lo
    out = cover.argmax(axis=1)
    empty = cover.sum(axis=1) <= 0
    out[empty] = -1 if default is None else SIGN_INDEX[default]
    return out.astype(int)


# --- the model ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class SignModelSettings:
    """Hyperparameters (the thesis gives none; chosen for about a minute of labelled speech).

    Attributes:
        frame_s: frame length (s); context: word/lexicon smear (frames either side).
        min_count, max_vocab: the vocabulary cut (:func:`build_vocabulary`).
        prosody, words, pos, lexicon: the input blocks used.
        hidden: sigmoid layer sizes (() = linear-chain CRF); order: 1 or 2 (chain order).
        l2: penalty per frame on network/node weights (towards 0 or the lexicon prior).
        bias_weight: penalty per frame pulling the node bias towards the log sign shares of
            Table A.1 (so a sign the data never show keeps the thesis's rate).
        prior_weight: penalty per frame pulling α towards Table A.1's log transitions.
        lexicon_weight: the prior weight of a lexicon cue on its own sign (linear model only;
            0 = no dictionary prior). 8 is about what Table A.1 charges for entering a rare
            sign from Beats and leaving it again within a few frames plus the prior's gap in
            sign shares (7–11 nats), so that a dictionary word alone can turn its frames;
            docs/SIGNS.md §4 measures the trade against the form labels.
        l2_trans2: penalty per frame on second-order weights.
        iterations: L-BFGS iterations; seed: network initialisation.
        word_latency_s: live, a word is used this long after it ends (recognition latency).
        commit_lag_s: live, a frame is final this long after it ends (late syllables).
    """

    frame_s: float = 1.0
    context: int = 1
    min_count: int = 2
    max_vocab: int = 817
    prosody: bool = True
    words: bool = True
    pos: bool = True
    lexicon: bool = True
    hidden: tuple[int, ...] = ()
    order: int = 1
    l2: float = 0.1
    bias_weight: float = 0.02
    prior_weight: float = 0.05
    lexicon_weight: float = 8.0
    l2_trans2: float = 0.05
    iterations: int = 300
    seed: int = 0
    word_latency_s: float = 0.3
    commit_lag_s: float = 0.4

    def to_dict(self) -> dict:
        d = asdict(self)
        d["hidden"] = list(self.hidden)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> SignModelSettings:
        known = {f for f in cls.__dataclass_fields__}
        d = {k: v for k, v in d.items() if k in known}
        if "hidden" in d:
            d["hidden"] = tuple(int(h) for h in d["hidden"])
        return cls(**d)


@dataclass
class SignModel:
    """A trained sign predictor: the chain over signs (a linear-chain CRF unless trained with a
    hidden layer), its input layout and settings.

    Attributes:
        dcnf: the :class:`~gesture_sim.inference.dcnf.DCNF` (S = 14 states, window 1).
        layout: the :class:`InputLayout`; settings: :class:`SignModelSettings`.
        info: training summary (frames, label counts, objective, seconds, data).
        segment_signs: the library segment signs it was trained with (for the chooser:
            saves labelling the library again when its fingerprint matches).
    """

    dcnf: DCNF
    layout: InputLayout
    settings: SignModelSettings
    info: dict = field(default_factory=dict)
    segment_signs: dict = field(default_factory=dict)

    @property
    def n_inputs(self) -> int:
        return self.layout.n_inputs

    def unary(self, x: np.ndarray) -> np.ndarray:
        """Node potentials (n, S) of frame inputs x (n, D)."""
        x = np.asarray(x, dtype=float).reshape(-1, self.n_inputs)
        return self.dcnf.unary(self.dcnf.standardise(x))

    def marginals(self, x: np.ndarray) -> np.ndarray:
        """Exact per-frame marginals (n, S) (forward-backward; offline)."""
        return self.dcnf.posteriors(self.unary(x)).gamma

    def decode(self, x: np.ndarray) -> np.ndarray:
        """The most likely sign sequence (n,) of indices (Viterbi; offline)."""
        return viterbi(self.unary(x), self.dcnf.trans, self.dcnf.trans2)

    def predict(self, x: np.ndarray) -> list[str]:
        """:meth:`decode` as sign names."""
        return [SIGNS[i] for i in self.decode(x)]

    def causal_marginals(self, x: np.ndarray) -> np.ndarray:
        """Forward-filtered marginals (n, S): frame t given frames 0..t only."""
        f = ChainForward(self.dcnf.trans, self.dcnf.trans2)
        u = self.unary(x)
        return np.array([f.step(ut) for ut in u]).reshape(len(u), N_SIGNS)

    def transition_matrix(self) -> np.ndarray:
        """Row-stochastic (S, S) first-order transitions ``∝ exp(α)``."""
        return self.dcnf.transition_matrix()

    # --- storage ---

    def save(self, folder: str | os.PathLike[str]) -> tuple[Path, Path]:
        """Write ``signs.npz`` and ``signs.json`` into ``folder`` (created); returns them."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        npz, js = folder / SIGN_MODEL_NPZ, folder / SIGN_MODEL_JSON
        tmp = folder / (SIGN_MODEL_NPZ + ".tmp.npz")
        np.savez(tmp, **self.dcnf.to_arrays())
        os.replace(tmp, npz)
        meta = {"format": SIGN_MODEL_FORMAT, "signs": list(SIGNS), "dcnf": self.dcnf.meta(),
                "layout": self.layout.to_dict(), "settings": self.settings.to_dict(),
                "inputs": {"prosody": list(PROSODY), "pos_groups": list(POS_GROUPS),
                           "lexicon": list(SIGNS)},
                "info": self.info, "segment_signs": self.segment_signs}
        js.write_text(json.dumps(meta, indent=1), encoding="utf-8")
        return npz, js

    @classmethod
    def load(cls, folder: str | os.PathLike[str]) -> SignModel:
        """Read a folder written by :meth:`save`.

        Raises:
            GestureSimError: one line naming the folder or file at fault: a folder without
                ``signs.npz`` + ``signs.json`` (a motion library folder given instead, say), a
                truncated archive, bad JSON, a JSON that is not an object, another format major
                or sign inventory, arrays that do not fit the settings.
        """
        from gesture_sim.errors import GestureSimError
        from gesture_sim.fileio import decoding_errors

        folder = Path(folder)
        npz, js = folder / SIGN_MODEL_NPZ, folder / SIGN_MODEL_JSON
        missing = [f.name for f in (npz, js) if not f.is_file()]
        if missing:
            hint = ""
            if (folder / "model" / SIGN_MODEL_NPZ).is_file():
                hint = f" (a motion library? its sign model is {folder / 'model'})"
            elif (folder / "manifest.json").is_file():
                hint = " (this looks like a motion library folder, not a sign model)"
            raise GestureSimError(
                f"{folder}: not a sign model folder: {' and '.join(missing)} missing (a sign "
                f"model holds {SIGN_MODEL_NPZ} + {SIGN_MODEL_JSON}, written by "
                f"'gesture-sim train --signs'){hint}")
        rebuild = "retrain it with 'gesture-sim train --signs'"
        with decoding_errors(js, "sign model settings", rebuild):
            meta = json.loads(js.read_text(encoding="utf-8"))
        if not isinstance(meta, dict):
            raise GestureSimError(f"{js}: damaged sign model settings (a JSON "
                                  f"{type(meta).__name__}, not an object); {rebuild}")
        major = str(meta.get("format", "0")).split(".")[0]
        if major != SIGN_MODEL_FORMAT.split(".")[0]:
            raise GestureSimError(f"{js}: sign model format {meta.get('format')!r}; this version "
                                  f"reads format {SIGN_MODEL_FORMAT}; {rebuild}")
        if list(meta.get("signs", ())) != list(SIGNS):
            raise GestureSimError(f"{js}: another sign inventory (this version has "
                                  f"{len(SIGNS)} signs); {rebuild}")
        with decoding_errors(npz, "sign model", rebuild):
            with np.load(npz, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        with decoding_errors(js, "sign model", rebuild):
            dcnf = DCNF.from_arrays(arrays, meta["dcnf"])
            layout = InputLayout.from_dict(meta["layout"])
            if layout.n_inputs != dcnf.n_inputs:
                raise GestureSimError(f"{js}: damaged sign model (a layout of "
                                      f"{layout.n_inputs} inputs, a DCNF of {dcnf.n_inputs}); "
                                      f"{rebuild}")
            return cls(dcnf, layout, SignModelSettings.from_dict(meta["settings"]),
                       meta.get("info", {}), meta.get("segment_signs", {}))

    def new_filter(self, words: Sequence[Any] | None = None) -> SignFilter:
        """A causal :class:`SignFilter` (``words``: timed words known in advance, revealed as
        they are said; None: prosody only)."""
        return SignFilter(self, words)


def default_sign_model_dir() -> Path:
    """Where the shipped sign model lives (``motion_library/default/model``)."""
    from gesture_sim import DEFAULT_LIBRARY_DIR

    return Path(DEFAULT_LIBRARY_DIR) / "model"


# --- decoding ----------------------------------------------------------------------------------


def viterbi(unary: np.ndarray, trans: np.ndarray, trans2: np.ndarray | None = None
            ) -> np.ndarray:
    """Most likely state path (n,) of a first- or second-order chain.

    Args:
        unary: (n, S) node potentials; trans: (S, S) α; trans2: (S, S, S) β or None.
    """
    u = np.asarray(unary, dtype=float)
    n, s = u.shape
    if n == 0:
        return np.zeros(0, dtype=int)
    if trans2 is None or n < 2:
        delta = u[0].copy()
        back = np.zeros((n, s), dtype=int)
        for t in range(1, n):
            sc = delta[:, None] + trans
            back[t] = sc.argmax(axis=0)
            delta = sc.max(axis=0) + u[t]
        path = np.zeros(n, dtype=int)
        path[-1] = int(delta.argmax())
        for t in range(n - 1, 0, -1):
            path[t - 1] = back[t, path[t]]
        return path
    # pairs (q_{t-1}, q_t) for t >= 1
    delta = u[0][:, None] + trans + u[1][None, :]              # (i, j)
    backs = []
    for t in range(2, n):
        sc = delta[:, :, None] + trans2                        # (i, j, k)
        b = sc.argmax(axis=0)                                  # (j, k) -> best i
        delta = sc.max(axis=0) + trans + u[t][None, :]
        backs.append(b)
    j, k = np.unravel_index(int(delta.argmax()), delta.shape)
    path = [int(k), int(j)]
    for b in reversed(backs):
        i = int(b[path[-1], path[-2]])
        path.append(i)
    return np.array(path[::-1], dtype=int)


def _lse(x: np.ndarray, axis: int) -> np.ndarray:
    m = np.max(x, axis=axis, keepdims=True)
    return np.squeeze(m, axis=axis) + np.log(np.sum(np.exp(x - m), axis=axis))


class ChainForward:
    """The forward recursion of a first- or second-order chain, one frame at a time.

    ``step(u)`` with the frame's node potentials (S,) returns the filtered marginal (S,);
    ``peek(us)`` returns the marginal after further frames ``us`` (m, S) without keeping them.
    """

    def __init__(self, trans: np.ndarray, trans2: np.ndarray | None = None) -> None:
        self.trans = np.asarray(trans, dtype=float)
        self.trans2 = None if trans2 is None else np.asarray(trans2, dtype=float)
        self.reset()

    def reset(self) -> None:
        self.log_alpha: np.ndarray | None = None

    def _advance(self, la: np.ndarray | None, u: np.ndarray) -> np.ndarray:
        if la is None:
            out = u.copy()
        elif self.trans2 is None:
            out = _lse(la[:, None] + self.trans, axis=0) + u
        elif la.ndim == 1:
            out = la[:, None] + self.trans + u[None, :]
        else:
            out = _lse(la[:, :, None] + self.trans2, axis=0) + self.trans + u[None, :]
        return out - _lse(out.reshape(-1), axis=0)

    @staticmethod
    def _belief(la: np.ndarray) -> np.ndarray:
        b = np.exp(la) if la.ndim == 1 else np.exp(la).sum(axis=0)
        return b / b.sum()

    def step(self, u: np.ndarray) -> np.ndarray:
        self.log_alpha = self._advance(self.log_alpha, np.asarray(u, dtype=float))
        return self._belief(self.log_alpha)

    def peek(self, us: Sequence[np.ndarray]) -> np.ndarray | None:
        la = self.log_alpha
        for u in us:
            la = self._advance(la, np.asarray(u, dtype=float))
        return None if la is None else self._belief(la)


# --- training ----------------------------------------------------------------------------------


def label_stats(labels: np.ndarray, order: int) -> ChainStats:
    """Target statistics of a hard label sequence (n,) (indices; -1 frames are not allowed)."""
    y = np.asarray(labels, dtype=int)
    n, s = len(y), N_SIGNS
    gamma = np.zeros((n, s))
    gamma[np.arange(n), y] = 1.0
    xi = np.zeros((s, s))
    np.add.at(xi, (y[:-1], y[1:]), 1.0)
    xi3 = None
    if order == 2:
        xi3 = np.zeros((s, s, s))
        if n >= 3:
            np.add.at(xi3, (y[:-2], y[1:-1], y[2:]), 1.0)
    return ChainStats(0.0, gamma, xi, xi3)


def _split_runs(x: np.ndarray, y: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Contiguous parts of (x, y) without unlabelled (-1) frames."""
    out, start = [], None
    for t in range(len(y) + 1):
        ok = t < len(y) and y[t] >= 0
        if ok and start is None:
            start = t
        elif not ok and start is not None:
            out.append((x[start:t], y[start:t]))
            start = None
    return out


def fit_sign_model(inputs: Sequence[np.ndarray], labels: Sequence[np.ndarray],
                   layout: InputLayout, settings: SignModelSettings | None = None,
                   info: dict | None = None) -> SignModel:
    """Train a :class:`SignModel` on labelled recordings.

    Args:
        inputs: per recording, frame inputs (n_i, D) (:func:`frame_inputs` with ``layout``).
        labels: per recording, sign indices (n_i,); -1 marks an unlabelled frame (left out;
            the recording is split there).
        layout: the inputs' layout; settings: hyperparameters.
        info: extra training facts stored with the model (data, sizes).
    """
    from scipy.optimize import minimize

    cfg = settings or SignModelSettings()
    parts = [p for x, y in zip(inputs, labels, strict=True)
             for p in _split_runs(np.asarray(x, float), np.asarray(y, int)) if len(p[0])]
    if not parts:
        raise ValueError("no labelled frames to train on")
    d = layout.n_inputs
    allx = np.concatenate([p[0] for p in parts])
    mean, std = np.zeros(d), np.ones(d)
    pro = layout.blocks()["prosody"]
    mean[pro] = allx[:, pro].mean(axis=0)
    sd = allx[:, pro].std(axis=0)
    std[pro] = np.where(sd > 1e-6, sd, 1.0)
    s = N_SIGNS
    rng = np.random.default_rng(cfg.seed)
    sizes = [d, *cfg.hidden]
    layers = []
    for a, b in zip(sizes[:-1], sizes[1:], strict=True):
        w = np.zeros((a + 1, b))
        w[:-1] = rng.normal(0.0, 1.0 / np.sqrt(max(a, 1)), size=(a, b))
        layers.append(w)
    prior_trans = table_a1_log_transitions()
    theta0 = np.zeros((sizes[-1], s))
    lex_centre = np.zeros_like(theta0)
    if not cfg.hidden and layout.lexicon and cfg.lexicon_weight:
        lx = layout.blocks()["lexicon"]
        lex_centre[lx] = np.eye(s) * cfg.lexicon_weight
        theta0 = lex_centre.copy()
    bias0 = np.log(table_a1_marginals() + 1e-3)
    trans2 = np.zeros((s, s, s)) if cfg.order == 2 else None
    model = DCNF(layers, theta0, bias0, prior_trans.copy(), trans2, mean, std, window=1)
    a0s = [model.standardise(x) for x, _ in parts]
    targets = [label_stats(y, cfg.order) for _, y in parts]
    n_total = float(sum(len(y) for _, y in parts))
    # Gaussian penalties with centres: weight (per frame of data) and centre per parameter
    wts, ctr = [], []
    for w in layers:
        wts.append(np.full(w.size, cfg.l2))
        ctr.append(np.zeros(w.size))
    wts += [np.full(theta0.size, cfg.l2), np.full(s, cfg.bias_weight),
            np.full(s * s, cfg.prior_weight)]
    ctr += [lex_centre.ravel(), bias0.copy(), prior_trans.ravel()]
    if trans2 is not None:
        wts.append(np.full(trans2.size, cfg.l2_trans2))
        ctr.append(np.zeros(trans2.size))
    lam = np.concatenate(wts) * n_total
    centre = np.concatenate(ctr)
    zero = np.zeros_like(lam)

    def fun(v: np.ndarray) -> tuple[float, np.ndarray]:
        f, g = objective_and_gradient(model, v, a0s, targets, zero)
        dv = v - centre
        return (f + 0.5 * float(np.sum(lam * dv * dv))) / n_total, (g + lam * dv) / n_total

    t0 = time.perf_counter()
    res = minimize(fun, model.flat(), jac=True, method="L-BFGS-B",
                   options={"maxiter": int(cfg.iterations)})
    fitted = model.with_flat(res.x)
    counts = np.bincount(np.concatenate([y for _, y in parts]), minlength=s)
    summary = {"frames": int(n_total), "sequences": len(parts),
               "label_counts": {SIGNS[i]: int(c) for i, c in enumerate(counts) if c},
               "objective_per_frame": float(res.fun), "iterations": int(res.nit),
               "seconds": round(time.perf_counter() - t0, 3)}
    return SignModel(fitted, layout, cfg, {**summary, **(info or {})})


def layout_for(settings: SignModelSettings, vocabulary: Sequence[str]) -> InputLayout:
    """The :class:`InputLayout` of ``settings`` over ``vocabulary``."""
    return InputLayout(tuple(vocabulary), settings.prosody, settings.words, settings.pos,
                       settings.lexicon, settings.frame_s, settings.context)


@dataclass
class LabelledTake:
    """One training recording: its syllables, timed words, duration and sign spans.

    Attributes:
        name: a name for reports; duration_s: its length (s).
        syllables: the prosody tracker's syllables; words: timed words (may be empty).
        spans: ``(start_s, end_s, sign)`` annotations (times on the audio's clock).
    """

    name: str
    duration_s: float
    syllables: list
    words: list
    spans: list


def train_on_takes(takes: Sequence[LabelledTake], settings: SignModelSettings | None = None,
                   tagger: str | None = None, unlabelled: str | None = None) -> SignModel:
    """Build the vocabulary, the frame inputs and labels of ``takes`` and fit a model (the
    entry point a corpus command calls: audio + transcript + sign annotations per take).

    Frames no span covers get ``unlabelled`` (a sign name) or are left out (None).
    """
    cfg = settings or SignModelSettings()
    vocab = build_vocabulary([t.words for t in takes], cfg.min_count, cfg.max_vocab)
    layout = layout_for(cfg, vocab)
    xs, ys = [], []
    for t in takes:
        x = frame_inputs(layout, t.duration_s, t.syllables, t.words, tagger)
        xs.append(x)
        ys.append(frame_labels(t.spans, len(x), cfg.frame_s, unlabelled))
    info = {"takes": [{"name": t.name, "duration_s": round(t.duration_s, 3),
                       "words": len(t.words), "syllables": len(t.syllables),
                       "annotations": len(t.spans)} for t in takes],
            "vocabulary_size": len(vocab)}
    return fit_sign_model(xs, ys, layout, cfg, info)


# --- run time ----------------------------------------------------------------------------------


class SignFilter:
    """The causal sign filter: a :class:`~gesture_sim.contracts.BeliefFilter` over the 14 signs.

    ``step(t, syllables)`` takes the syllables emitted since the previous step and returns the
    belief (14,) over the sign of the current frame ``floor(t / frame_s)``. Frames are final
    (their forward message kept) ``commit_lag_s`` after they end; the current and any
    not-yet-final frames are read with what is known at t. Words given in advance (a
    transcript) are revealed ``word_latency_s`` after they end, tagged and matched against the
    lexicon over the last few revealed words. Without words the model runs on prosody alone
    (words, POS and lexicon inputs all zero: what a live run has without a recogniser).
    Words recognised live (:class:`~gesture_sim.audio.live_words.LiveWord`) are handed over
    with :meth:`push_words` as they arrive and revealed at their own ``t_emitted``.
    """

    #: revealed words re-tagged and re-matched against the lexicon when a word arrives
    TAIL = 8
    #: committed frames kept in :attr:`history`
    KEEP = 600
    #: about the prosody tracker's syllable latency (s): the current frame's heard part ends
    #: this long before t
    LATENCY = 0.2

    def __init__(self, model: SignModel, words: Sequence[Any] | None = None) -> None:
        self.model = model
        self.words = timed_words(words or ())
        self._n_given = len(self.words)
        cfg = model.settings
        self.latency = float(cfg.word_latency_s)
        self.lag = float(cfg.commit_lag_s)
        self.frame_s = float(model.layout.frame_s)
        self.reset()

    @property
    def n_states(self) -> int:
        return N_SIGNS

    def set_words(self, words: Sequence[Any] | None) -> None:
        """Timed words known in advance (None: none); takes effect at the next reset."""
        self.words = timed_words(words or ())
        self._n_given = len(self.words)

    def push_words(self, words: Sequence[Any]) -> int:
        """Words recognised live, in the order they became known: objects with ``start_s``,
        ``end_s``, ``text`` and ``t_emitted`` (:class:`~gesture_sim.audio.live_words.LiveWord`)
        or ``(start_s, end_s, text, t_emitted)`` tuples. Each is revealed (tagged, matched
        against the lexicon, added to its frame's inputs) at the first :meth:`step` whose
        ``t >= t_emitted``, so it only bears on beliefs read once the audio that decided it
        was heard; ``word_latency_s`` is not added (``t_emitted`` is the recogniser's own
        latency). Words given in advance (a transcript) take precedence: while there are any,
        live words are not used. Cleared by :meth:`reset`. Returns how many were taken."""
        if self._n_given:
            return 0
        n = 0
        for w in words:
            if isinstance(w, tuple | list):
                a, b, text, t_em = w
            else:
                a, b, text, t_em = w.start_s, w.end_s, w.text, w.t_emitted
            if str(text).strip():
                self._live.append((float(t_em), float(a), float(b), str(text)))
                n += 1
        return n

    def _due(self, i: int) -> float:
        """When word i is revealed: a live word at its ``t_emitted``, a given one
        ``word_latency_s`` after its end."""
        t = self._known_at.get(i)
        return self.words[i][1] + self.latency if t is None else t

    def reset(self) -> None:
        self.builder = FrameBuilder(self.model.layout)
        self.norm = SpeakerNormalizer()
        self.forward = ChainForward(self.model.dcnf.trans, self.model.dcnf.trans2)
        self.committed = 0                # frames 0..committed-1 are final
        del self.words[self._n_given:]    # the live words of the previous stream
        self._live: deque[tuple[float, float, float, str]] = deque()  # pushed, not yet known
        self._known_at: dict[int, float] = {}  # index in words -> t_emitted (live words)
        self._next_word = 0
        self._tags: list[int] = []
        self._cues: dict[int, tuple[float, float, str]] = {}
        self._belief = np.full(N_SIGNS, 1.0 / N_SIGNS)
        #: (frame, its most likely sign when it became final), the last :attr:`KEEP`
        self.history: list[tuple[int, int]] = []

    @property
    def belief(self) -> np.ndarray:
        return self._belief.copy()

    def _reveal(self, t: float) -> None:
        from gesture_sim.audio.pos import tag_words
        from gesture_sim.signals.sign_lexicon import sign_cues

        while self._live and self._live[0][0] <= t:
            t_em, a, b, text = self._live.popleft()
            self._known_at[len(self.words)] = t_em
            self.words.append((a, b, text))
        n0 = self._next_word
        while self._next_word < len(self.words) and self._due(self._next_word) <= t:
            self._next_word += 1
        if self._next_word == n0:
            return
        lo = max(0, self._next_word - self.TAIL)
        tail = self.words[lo:self._next_word]
        tags = tag_words([w for _, _, w in tail])
        for i in range(n0, self._next_word):
            a, b, text = self.words[i]
            self.builder.add_word(a, b, text, pos_group(tags[i - lo]))
        for c in sign_cues(tail):
            first = next(i for i in range(lo, self._next_word) if self.words[i][0] == c.start_s)
            if first not in self._cues and first >= n0 - 1:
                self._cues[first] = (c.start_s, c.end_s, c.sign)
                self.builder.add_cue(c.start_s, c.end_s, c.sign)

    def step(self, t: float, syllables: Sequence[Syllable] = ()) -> np.ndarray:
        for s in syllables:
            self.builder.add_syllable(s.t_start, s.t_end, self.norm.features(s))
        if self.words or self._live:
            self._reveal(t)
        k = self.builder.frame_of(t)
        while (self.committed + 1) * self.frame_s + self.lag <= t:
            u = self.model.unary(self.builder.row(self.committed))[0]
            b = self.forward.step(u)
            self.history.append((self.committed, int(np.argmax(b))))
            if len(self.history) > self.KEEP:
                del self.history[: -self.KEEP]
            self.committed += 1
            self.builder.forget_before(self.committed - self.model.layout.context - 1)
        # the frames not yet final, read with what is known now; the current frame's shares
        # and rates over the part heard (less the tracker's latency), so that a frame just
        # begun does not read as a quiet one
        rows = [self.builder.row(j, None if j < k else t - j * self.frame_s - self.LATENCY)
                for j in range(self.committed, k + 1)]
        b = self.forward.peek(list(self.model.unary(np.array(rows)))) if rows else None
        if b is not None:
            self._belief = b
        return self._belief.copy()

    @property
    def heard_cues(self) -> list[tuple[float, float, str]]:
        """The lexicon cues ``(start_s, end_s, sign)`` heard so far, in order."""
        return [self._cues[i] for i in sorted(self._cues)]

    @property
    def heard_words(self) -> int:
        """How many of the given words have been revealed so far."""
        return self._next_word

    def sign(self) -> str:
        """The most likely sign now."""
        return SIGNS[int(np.argmax(self._belief))]
