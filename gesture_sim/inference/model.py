"""The trained inference model: HMM, prosody clusters, CRF, baseline, settings; save/load.

On disk a model is a folder with ``model.json`` (version, settings, fingerprint, normaliser seed
statistics, training summary, baseline statistics) and ``model.npz`` (all arrays). Loading takes
a few milliseconds.

Run time: ``model.new_filter()`` gives a :class:`GestureFilter` (remapped CRF) and
``model.new_filter("levine09")`` the baseline, and ``model.new_filter("dcnf")`` the DCNF of
Chiu 2014 when the model has one (:attr:`GestureModel.dcnf`); all have
``step(t, syllables) -> belief (S,)`` (called once per control step with the syllables emitted
since the previous step), ``reset()`` and ``n_states``. ``model.transition_matrix`` (S, S) is
row-stochastic: ``[i, j] = P(q_{t+1} = j | q_t = i)``; ``model.hmm.means`` (S, 6) and
``model.hmm.covars`` (S, 6, 6) are the states' Gaussian kinematic summaries in the normalised
parameter space recorded in ``model.param_normalisation``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.contracts import Syllable
from gesture_sim.errors import GestureSimError
from gesture_sim.fileio import (
    atomic_outputs,
    damaged,
    decoding_exceptions,
    jsonable,
)
from gesture_sim.inference.clusters import ProsodyClusters
from gesture_sim.inference.crf import CRFFilter, RemappedCRF
from gesture_sim.inference.dcnf import DCNF, N_BASE, DCNFFilter, DCNFInputs, pad_input
from gesture_sim.inference.features import StepInputs, StepSettings
from gesture_sim.inference.hmm import KinematicHMM
from gesture_sim.inference.levine09 import Levine09Filter, Levine09Model
from gesture_sim.inference.levine09_sections import load_levine09

#: Format version; :meth:`GestureModel.load` refuses another major version. 1.1 added the
#: optional DCNF block (``"dcnf"`` in model.json, ``dcnf_*`` arrays); 1.0 files still load.
MODEL_VERSION = "1.1"
MODEL_JSON = "model.json"
MODEL_NPZ = "model.npz"
#: How to repair a damaged model (the end of every decoding error).
_RETRAIN = "retrain it with 'gesture-sim train'"


@dataclass
class GestureModel:
    """Everything the inference layer needs at run time.

    Attributes:
        hmm: the kinematic HMM (hidden states and their Gaussians).
        clusters: the prosody Gaussian mixture (K components).
        crf: the remapped CRF (window W).
        settings: step rate and silence rule of the per-step inputs.
        normalizer_seed: :meth:`SpeakerNormalizer.to_dict` seeded on the training speech.
        param_normalisation: ``{"names", "B", "W"}`` of the kinematic parameters.
        fingerprint: content hash of the training data (steps X, Y and settings).
        baseline: the Levine 2009 model over the same states (optional).
        library_fingerprint: fingerprint of the motion library whose normalisation was used.
        summary: training summary (JSON-ready).
        version: format version.
        dcnf: the DCNF (Chiu 2014) over the same states and inputs (optional).
    """

    hmm: KinematicHMM
    clusters: ProsodyClusters
    crf: RemappedCRF
    settings: StepSettings
    normalizer_seed: dict[str, Any]
    param_normalisation: dict[str, Any]
    fingerprint: str
    baseline: Levine09Model | None = None
    library_fingerprint: str | None = None
    summary: dict[str, Any] = field(default_factory=dict)
    version: str = MODEL_VERSION
    dcnf: DCNF | None = None

    @property
    def n_states(self) -> int:
        return self.hmm.n_states

    @property
    def transition_matrix(self) -> np.ndarray:
        """(S, S) row-stochastic CRF transition matrix, ``[i, j] ∝ exp(λ_ij)``."""
        return self.crf.transition_matrix()

    def predict(self, belief: np.ndarray, n_steps: int) -> np.ndarray:
        """Belief (S,) propagated ``n_steps`` ahead without observations: ``b T^n``."""
        return np.asarray(belief) @ np.linalg.matrix_power(self.transition_matrix, n_steps)

    @property
    def pad_membership(self) -> np.ndarray:
        """Cluster membership (K,) of the silence input (also the window before the start)."""
        return self.clusters.membership(self.settings.silence())

    @property
    def dcnf_pad(self) -> np.ndarray:
        """DCNF input (D,) of a step before the stream starts."""
        return pad_input(self.settings.silence(), self.pad_membership)

    def new_filter(self, kind: str = "crf") -> GestureFilter | DCNFGestureFilter | Levine09Filter:
        """A fresh run-time filter: ``"crf"`` (default), ``"dcnf"`` or ``"levine09"``."""
        if kind == "crf":
            return GestureFilter(self)
        if kind == "dcnf":
            if self.dcnf is None:
                raise GestureSimError(
                    "this inference model has no DCNF; add one with tools/add_dcnf.py")
            return DCNFGestureFilter(self)
        if kind == "levine09":
            if self.baseline is None:
                raise GestureSimError("this model has no Levine 2009 baseline; retrain it")
            return self.baseline.new_filter()
        raise GestureSimError(f"unknown filter kind {kind!r} (crf, dcnf or levine09)")

    # --- save / load --------------------------------------------------------------------------

    def save(self, folder: str | os.PathLike[str]) -> None:
        """Write ``model.json`` and ``model.npz`` into ``folder`` (created): both under
        temporary names first, renamed together at the end, so a failure leaves the previous
        model whole (never a new npz beside an old json)."""
        folder = Path(folder)
        arrays = self.hmm.to_arrays() | self.clusters.to_arrays() | self.crf.to_arrays()
        if self.baseline is not None:
            arrays |= self.baseline.to_arrays()
        if self.dcnf is not None:
            arrays |= self.dcnf.to_arrays()
        meta = {
            "version": self.version,
            "settings": self.settings.to_dict(),
            "normalizer_seed": self.normalizer_seed,
            "param_normalisation": self.param_normalisation,
            "fingerprint": self.fingerprint,
            "library_fingerprint": self.library_fingerprint,
            "n_states": self.n_states,
            "n_clusters": self.clusters.n_clusters,
            "window": self.crf.window,
            "baseline": self.baseline.meta() if self.baseline is not None else None,
            "summary": self.summary,
            "dcnf": self.dcnf.meta() if self.dcnf is not None else None,
        }
        with atomic_outputs(folder / MODEL_NPZ, folder / MODEL_JSON) as (npz_tmp, json_tmp):
            with open(npz_tmp, "wb") as fh:
                np.savez(fh, **arrays)
            json_tmp.write_text(json.dumps(jsonable(meta, finite=False), indent=1),
                                encoding="utf-8")

    @classmethod
    def load(cls, folder: str | os.PathLike[str]) -> GestureModel:
        """Read a model folder written by :meth:`save`; any decoding failure (a truncated npz,
        bad JSON, missing keys) is one GestureSimError naming the folder."""
        from gesture_sim.fileio import decoding_errors

        with decoding_errors(folder, "inference model", _RETRAIN):
            return cls._load(folder)

    @classmethod
    def _load(cls, folder: str | os.PathLike[str]) -> GestureModel:
        """Read a model folder written by :meth:`save`."""
        folder = Path(folder)
        if not (folder / MODEL_JSON).is_file() or not (folder / MODEL_NPZ).is_file():
            raise GestureSimError(
                f"{folder} is not an inference model (needs {MODEL_JSON} and {MODEL_NPZ}); "
                "train one with `gesture-sim train`")
        try:
            meta = json.loads((folder / MODEL_JSON).read_text(encoding="utf-8"))
            with np.load(folder / MODEL_NPZ, allow_pickle=False) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except decoding_exceptions() as exc:
            raise damaged(folder, "inference model", _RETRAIN, exc) from exc
        if not isinstance(meta, dict):
            raise GestureSimError(f"{folder / MODEL_JSON}: damaged inference model (not a JSON "
                                  f"object); {_RETRAIN}")
        major = str(meta.get("version", "0")).split(".")[0]
        if major != MODEL_VERSION.split(".")[0]:
            raise GestureSimError(
                f"inference model {folder} has format version {meta.get('version')}, this "
                f"gesture-sim reads {MODEL_VERSION}; retrain it")
        baseline = None
        if meta.get("baseline") is not None:
            baseline = load_levine09(arrays, meta["baseline"])
        hmm, clusters = KinematicHMM.from_arrays(arrays), ProsodyClusters.from_arrays(arrays)
        dcnf = None
        if meta.get("dcnf") is not None:
            try:
                dcnf = DCNF.from_arrays(arrays, meta["dcnf"])
                dcnf.check(hmm.n_states, N_BASE + clusters.n_clusters)
            except (ValueError, KeyError, TypeError) as exc:
                raise GestureSimError(
                    f"inference model {folder}: its DCNF does not fit the model's "
                    f"{hmm.n_states} states and {clusters.n_clusters} clusters ({exc}); "
                    "retrain it") from exc
        return cls(
            hmm=hmm, clusters=clusters, crf=RemappedCRF.from_arrays(arrays),
            settings=StepSettings(**meta["settings"]),
            normalizer_seed=meta["normalizer_seed"],
            param_normalisation=meta["param_normalisation"], fingerprint=meta["fingerprint"],
            baseline=baseline, library_fingerprint=meta.get("library_fingerprint"),
            summary=meta.get("summary", {}), version=meta["version"], dcnf=dcnf,
        )


def make_normalizer(seed: dict[str, Any]):
    """A :class:`~gesture_sim.inference.normalize.SpeakerNormalizer` from seed statistics.

    The means keep the training speaker's prior (its count). Measured: the location-free
    variant (``RunningStat.n_mean``: the speaker's own level from the first syllables) made the
    CRF's memberships uninformative on the synthetic loud/quiet test (the belief stopped
    following loudness), so it is available but not used; the timing layer's gain invariance
    comes from the accent detector's own running statistics."""
    from gesture_sim.inference.normalize import SpeakerNormalizer

    return SpeakerNormalizer.from_dict(seed)


class _FeatureFilter:
    """What the run-time filters share: syllables → the causal per-step features
    (:class:`~gesture_sim.inference.features.StepInputs`) → cluster memberships → the
    subclass's forward step (``_forward``)."""

    model: GestureModel
    inputs: StepInputs

    @property
    def n_states(self) -> int:
        return self.model.n_states

    def step(self, t: float, syllables: Sequence[Syllable] = ()) -> np.ndarray:
        """One control step at time t (s) given newly emitted syllables; belief (S,)."""
        for s in syllables:
            self.inputs.push(s)
        return self.step_features(self.inputs.at(t))

    def step_features(self, x: np.ndarray) -> np.ndarray:
        """One step from a ready per-step feature vector x (3,); belief (S,)."""
        self.last_features = x
        self.last_membership = self.model.clusters.membership(x)
        return self._forward(x, self.last_membership)

    def _forward(self, x: np.ndarray, membership: np.ndarray) -> np.ndarray:
        raise NotImplementedError


class GestureFilter(_FeatureFilter):
    """The run-time CRF belief: syllables → per-step features → memberships → forward step.

    Call :meth:`step` once per control step (time ``t`` in s, steps ``1 / rate_hz`` apart)
    with the syllables emitted since the previous call; it returns the belief (S,) over the
    hidden states, summing to 1. The speaker normaliser starts from the model's seed
    statistics and adapts online.
    """

    def __init__(self, model: GestureModel) -> None:
        self.model = model
        self.reset()

    def reset(self) -> None:
        """Start a new stream."""
        self.inputs = StepInputs(make_normalizer(self.model.normalizer_seed), self.model.settings)
        self.crf_filter: CRFFilter = self.model.crf.new_filter(self.model.pad_membership)
        self.last_features = self.model.settings.silence()
        self.last_membership = self.model.pad_membership

    @property
    def belief(self) -> np.ndarray:
        return self.crf_filter.belief

    def _forward(self, x: np.ndarray, membership: np.ndarray) -> np.ndarray:
        return self.crf_filter.step_membership(membership)


class DCNFGestureFilter(_FeatureFilter):
    """The run-time DCNF belief, with the interface of :class:`GestureFilter`.

    Syllables → the same per-step features and cluster memberships as the CRF →
    :class:`~gesture_sim.inference.dcnf.DCNFInputs` (adds voicing, silence, F0 and intensity
    slopes) → :class:`~gesture_sim.inference.dcnf.DCNFFilter` (network + causal forward step
    over state pairs). ``step(t, syllables)`` returns the belief (S,), summing to 1.
    """

    def __init__(self, model: GestureModel) -> None:
        if model.dcnf is None:
            raise GestureSimError("this inference model has no DCNF")
        self.model = model
        self.reset()

    def reset(self) -> None:
        """Start a new stream."""
        m = self.model
        self.inputs = StepInputs(make_normalizer(m.normalizer_seed), m.settings)
        self.dcnf_inputs = DCNFInputs(m.settings.silence())
        self.dcnf_filter: DCNFFilter = m.dcnf.new_filter(m.dcnf_pad)
        self.last_features = m.settings.silence()
        self.last_membership = m.pad_membership

    @property
    def belief(self) -> np.ndarray:
        return self.dcnf_filter.belief

    def transition_matrix(self) -> np.ndarray:
        """(S, S) row-stochastic first-order part of the DCNF chain (a one-step prior)."""
        return self.model.dcnf.transition_matrix()

    def _forward(self, x: np.ndarray, membership: np.ndarray) -> np.ndarray:
        return self.dcnf_filter.step(self.dcnf_inputs.push(x, membership))
