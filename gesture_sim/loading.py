"""One loader for the library, the inference model and the controller policy.

Every entry point — the pipeline, ``eval``, the benchmarks and ``tools/`` — loads its stack with
:func:`load_stack`, so every one of them checks that the model fits the library (the same
kinematic-parameter normalisation) and that the policy was trained for both (fingerprints).

A library swap keeps the inference model (Gesture Controllers' modularity): a library built
with the model's normalisation (``gesture-sim library build --normalisation-from MODEL``, or a
:meth:`~gesture_sim.motion.library.MotionLibrary.subset` of a library the model fits) needs
only its control layer. The policy of the model's own library (the one it was trained with,
``model.library_fingerprint``) is cached in the model folder (``MODEL/policy.npz``); the policy
of any other library is cached beside that library (``LIBRARY/policies/<state model
fingerprint>.npz``), so training it never writes into the model folder.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.errors import GestureSimError

#: Policy file name inside a model folder: trained for that model and its own library.
POLICY_FILE = "policy.npz"
#: Folder inside a library holding its policies for borrowed models, one file per model.
POLICY_DIR = "policies"


@dataclass
class Stack:
    """What a run needs, loaded and checked.

    Attributes:
        library_dir, model_dir: the folders. library: the MotionLibrary; model: the
        GestureModel; control_library, state_model: the control layer's views of them;
        policy: the controller Policy (None when not asked for); graph: the MIMiC motion
        graph stored beside the library (None when not asked for); finger_tracks: the clips'
        finger motion stored beside the library (clip index -> (T, 40) rad;
        :mod:`gesture_sim.motion.finger_tracks`; empty when there is none).
    """

    library_dir: Path
    model_dir: Path
    library: Any
    model: Any
    control_library: Any
    state_model: Any
    policy: Any = None
    graph: Any = None
    finger_tracks: dict = field(default_factory=dict)


def load_stack(library: str | Path | None = None, model: str | Path | None = None, *,
               policy: bool = True, graph: bool = False, show_progress: bool = False) -> Stack:
    """Load a library folder and a model folder (defaults: the shipped ones), check that they
    fit, and (``policy``) load or train the controller policy for them, (``graph``) the MIMiC
    motion graph of the library."""
    from gesture_sim import DEFAULT_LIBRARY_DIR
    from gesture_sim.control.inputs import ControlLibrary, StateModel
    from gesture_sim.inference.model import GestureModel
    from gesture_sim.motion.library import MotionLibrary

    library_dir = Path(library) if library is not None else DEFAULT_LIBRARY_DIR
    lib = MotionLibrary.load(library_dir)
    model_dir = resolve_model_dir(library_dir, model)
    gm = GestureModel.load(model_dir)
    check_model_fits_library(gm, lib, model_dir, library_dir)
    control_library = ControlLibrary.from_motion_library(lib)
    state_model = StateModel.from_inference(gm)
    pol = (load_policy(control_library, state_model, model_dir, library_dir=library_dir,
                       own_library=is_own_library(gm, lib), show_progress=show_progress)
           if policy else None)
    motion_graph = None
    if graph:
        from gesture_sim.control.mimic import load_graph

        motion_graph = load_graph(control_library, library_dir)
    from gesture_sim.motion.finger_tracks import load_finger_tracks

    return Stack(library_dir, model_dir, lib, gm, control_library, state_model, pol,
                 motion_graph, load_finger_tracks(library_dir, lib))


def resolve_model_dir(library_dir: Path, model_dir: str | Path | None) -> Path:
    """The model folder: the given one, else the library's ``model/`` subfolder when it has one,
    else the shipped model (``motion_library/default/model``: a library built with its
    normalisation, or a subset of the default library, has no model of its own)."""
    from gesture_sim import DEFAULT_LIBRARY_DIR

    if model_dir is not None:
        return Path(model_dir)
    own = Path(library_dir) / "model"
    return own if own.is_dir() else DEFAULT_LIBRARY_DIR / "model"


def same_normalisation(a: dict, b: dict) -> bool:
    """Whether two ``{"names", "B", "W"}`` normalisations are one (names equal, B and W equal
    to a relative 1e-6); a malformed one is never the same."""
    try:
        return (list(a["names"]) == list(b["names"])
                and np.allclose(a["B"], b["B"], rtol=1e-6)
                and np.allclose(a["W"], b["W"], rtol=1e-6))
    except (KeyError, TypeError, ValueError):
        return False


def check_model_fits_library(model, library, model_dir: Path, library_dir: Path) -> None:
    """Refuse a model whose kinematic parameter space is not the library's.

    The control layer compares the model's state Gaussians with the library's segment parameters;
    both must be normalised with the same B_X / W_X (a model trained with ``--library`` for that
    library, or any library built with the model's normalisation, ``library build
    --normalisation-from MODEL``). The one-line error names both fixes.
    """
    if not same_normalisation(model.param_normalisation, library.param_normalisation):
        raise GestureSimError(
            f"model {model_dir} does not fit library {library_dir}: its kinematic parameters are "
            f"normalised differently; rebuild the library with the model's normalisation "
            f"(`gesture-sim library build ... --normalisation-from {model_dir}`) or retrain the "
            f"model for it (`gesture-sim train --library {library_dir} ...`)")


def is_own_library(model, library) -> bool:
    """Whether ``library`` is the one the model was trained with (its recorded fingerprint)."""
    return bool(getattr(model, "library_fingerprint", None)) and (
        model.library_fingerprint == library.fingerprint)


def normalisation_from(folder: str | Path) -> dict:
    """The kinematic-parameter normalisation ``{"names", "B", "W"}`` of an inference model folder
    (``model.json``) or of a motion library folder (``manifest.json``), checked.

    Raises:
        GestureSimError: the folder is neither, or its normalisation is malformed.
    """
    from gesture_sim.motion.build import check_normalisation

    folder = Path(folder)
    if (folder / "model.json").is_file():
        from gesture_sim.inference.model import GestureModel

        norm = GestureModel.load(folder).param_normalisation
        kind = "model"
    elif (folder / "manifest.json").is_file():
        from gesture_sim.motion.library import MotionLibrary

        norm = MotionLibrary.load(folder).param_normalisation
        kind = "library"
    else:
        raise GestureSimError(f"{folder} is neither an inference model folder (model.json) nor a "
                              "motion library folder (manifest.json)")
    return check_normalisation(norm, f"the parameter normalisation of {kind} {folder}")


def policy_settings():
    """The control-layer settings of the product's policies (chosen by measurement).

    ``fit_weight`` 2 (fit to the inferred kinematics counts twice the smoothness cost) and an
    interruption penalty 4 below the library's median D_sp; with the default softmin temperature
    these give varied sequences where interruptions happen but most segments play out
    (docs/history.md, the controller's row). The paper's unweighted sum is ``ControlSettings()``.
    """
    from gesture_sim.control.costs import ControlSettings

    return ControlSettings(fit_weight=2.0, extra_interrupt_penalty=-4.0)


def train_library_policy(control_library, state_model, show_progress: bool = False):
    """Solve the controller MDP for a library and model: the default tones (calm, neutral,
    energetic: D, V, A shifted by ∓0.75 SD) and every tag of the library as a semantic label,
    with :func:`policy_settings`.

    Not the tones fitted from the Bandai Namco styles (:func:`~gesture_sim.control.style.
    fitted_tones`): measured on the default library, its "energetic" performances (active,
    angry, happy, proud) have a *smaller* mean extent (D −0.44 SD) and velocity (V −0.26 SD)
    than the "normal" ones, and the calm ones smaller still (D −0.57, V −0.78): as segmented
    here, the styles differ more in duration and height than in extent, so a fitted energetic
    tone would make lively speech give smaller motion. The shifts stay until a styled
    co-speech corpus exists."""
    from gesture_sim.control.policy import train_policy
    from gesture_sim.control.style import default_tones

    labels = tuple(sorted(control_library.all_tags()))
    return train_policy(control_library, state_model, policy_settings(), tones=default_tones(),
                        labels=labels, show_progress=show_progress)


def policy_path(model_dir: str | Path, state_model, *, library_dir: str | Path | None = None,
                own_library: bool = True) -> Path:
    """Where the policy of a library and model is cached: ``MODEL/policy.npz`` for the model's
    own library (or when no library folder is given), else
    ``LIBRARY/policies/<state model fingerprint>.npz``."""
    if own_library or library_dir is None:
        return Path(model_dir) / POLICY_FILE
    return Path(library_dir) / POLICY_DIR / f"{state_model.fingerprint}.npz"


def load_policy(control_library, state_model, model_dir: Path, *,
                library_dir: str | Path | None = None, own_library: bool = True,
                train_if_missing: bool = True, show_progress: bool = False):
    """The cached policy for this library and model, or a freshly trained one.

    Looks at :func:`policy_path` and then in ``MODEL/policy.npz``; a stored policy for another
    library/model is refused by fingerprint. Then (or when there is none) the policy is trained
    in memory (15-25 s for the default library's 497 segments on 2 busy cores, about 1 s for a
    library of a few
    clips: ``gesture-sim library policy``) and, where the folder is writable, stored at
    :func:`policy_path` for the next run: beside the library, not in the model folder, unless
    it is the model's own library (``own_library``), so a library swap never writes into the
    model folder.
    """
    from gesture_sim.control.policy import Policy

    target = policy_path(model_dir, state_model, library_dir=library_dir,
                         own_library=own_library)
    candidates = list(dict.fromkeys([target, Path(model_dir) / POLICY_FILE]))
    errors = []
    for path in candidates:
        if path.is_file():
            try:
                return Policy.load(path, control_library.fingerprint, state_model.fingerprint)
            except GestureSimError as exc:
                errors.append(exc)
    if not train_if_missing:
        if errors:
            raise errors[-1]
        raise GestureSimError(f"no policy at {target}; train one with "
                              f"`gesture-sim library policy {library_dir or '<LIBRARY>'} "
                              f"--model {model_dir}`")
    policy = train_library_policy(control_library, state_model, show_progress=show_progress)
    save_policy(policy, target, quiet=True)
    return policy


def save_policy(policy, path: str | Path, *, quiet: bool = False) -> bool:
    """Store a policy at ``path`` (its folder created); ``quiet``: skip an unwritable place
    (returns False) instead of raising GestureSimError."""
    import os

    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        if quiet:
            return False
        raise GestureSimError(f"cannot create {path.parent}: {exc.strerror}") from exc
    if not os.access(path.parent, os.W_OK):
        if quiet:
            return False
        raise GestureSimError(f"cannot write the policy into {path.parent}")
    try:
        policy.save(path)
    except OSError as exc:
        if quiet:
            return False
        raise GestureSimError(f"cannot write the policy {path}: {exc.strerror}") from exc
    return True
