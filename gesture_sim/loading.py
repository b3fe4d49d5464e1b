"""One loader for the library, the inference model and the controller policy.

Every entry point — the pipeline, ``eval``, the benchmarks and ``tools/`` — loads its stack with
:func:`load_stack`, so every one of them checks that the model fits the library (the same
kinematic-parameter normalisation) and that the policy was trained for both (fingerprints).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.errors import GestureSimError

#: Policy file name inside a model folder: trained for that model and one library.
POLICY_FILE = "policy.npz"


@dataclass
class Stack:
    """What a run needs, loaded and checked.

    Attributes:
        library_dir, model_dir: the folders. library: the MotionLibrary; model: the
        GestureModel; control_library, state_model: the control layer's views of them;
        policy: the controller Policy (None when not asked for); graph: the MIMiC motion
        graph stored beside the library (None when not asked for).
    """

    library_dir: Path
    model_dir: Path
    library: Any
    model: Any
    control_library: Any
    state_model: Any
    policy: Any = None
    graph: Any = None


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
    pol = (load_policy(control_library, state_model, model_dir, show_progress=show_progress)
           if policy else None)
    motion_graph = None
    if graph:
        from gesture_sim.control.mimic import load_graph

        motion_graph = load_graph(control_library, library_dir)
    return Stack(library_dir, model_dir, lib, gm, control_library, state_model, pol,
                 motion_graph)


def resolve_model_dir(library_dir: Path, model_dir: str | Path | None) -> Path:
    """The model folder: the given one, or the library's ``model/`` subfolder."""
    return Path(model_dir) if model_dir is not None else Path(library_dir) / "model"


def check_model_fits_library(model, library, model_dir: Path, library_dir: Path) -> None:
    """Refuse a model whose kinematic parameter space is not the library's.

    The control layer compares the model's state Gaussians with the library's segment parameters;
    both must be normalised with the same B_X / W_X (a model trained with ``--library`` for that
    library, or any library built with the same normalisation).
    """
    a, b = model.param_normalisation, library.param_normalisation
    try:
        same = (list(a["names"]) == list(b["names"])
                and np.allclose(a["B"], b["B"], rtol=1e-6)
                and np.allclose(a["W"], b["W"], rtol=1e-6))
    except (KeyError, TypeError, ValueError):
        same = False
    if not same:
        raise GestureSimError(
            f"model {model_dir} does not fit library {library_dir}: its kinematic parameters are "
            f"normalised differently; retrain it with `gesture-sim train --library {library_dir}`")


def policy_settings():
    """The control-layer settings of the product's policies (chosen by measurement).

    ``fit_weight`` 2 (fit to the inferred kinematics counts twice the smoothness cost) and an
    interruption penalty 4 below the library's median D_sp; with the default softmin temperature
    these give varied sequences where interruptions happen but most segments play out
    (BENCHMARKS.md, "controller settings"). The paper's unweighted sum is ``ControlSettings()``.
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


def load_policy(control_library, state_model, model_dir: Path, *, train_if_missing: bool = True,
                show_progress: bool = False):
    """The policy stored in ``model_dir`` for this library and model, or a freshly trained one.

    A stored policy for another library/model is refused by fingerprint; then (or when there is
    none) the policy is trained in memory (seconds for the default library) and, where the
    folder is writable, stored for the next run.
    """
    import os

    from gesture_sim.control.policy import Policy

    path = Path(model_dir) / POLICY_FILE
    if path.is_file():
        try:
            return Policy.load(path, control_library.fingerprint, state_model.fingerprint)
        except GestureSimError:
            if not train_if_missing:
                raise
    elif not train_if_missing:
        raise GestureSimError(f"no policy at {path}; train one with `gesture-sim train`")
    policy = train_library_policy(control_library, state_model, show_progress=show_progress)
    if os.access(path.parent, os.W_OK):
        policy.save(path)
    return policy
