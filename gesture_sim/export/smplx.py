"""SMPL-X parameters in BEAT2's npz layout, from the simulated humanoid's motion.

The file matches BEAT2's ``smplxflame_30`` takes key for key (dtypes and shapes as in
``2_scott_0_1_1.npz``), so tools that read BEAT2 (EMAGE, the BEAT2 evaluation scripts, the
SMPL-X Blender add-on) read it, and so does the project's own reader
(:func:`gesture_sim.motion.smplx.read_smplx`):

==================== ============ ======= ====================================================
key                  shape        dtype   meaning
==================== ============ ======= ====================================================
``poses``            (T, 165)     float32 55 joints x axis-angle (rad), SMPL-X order
                                          (:data:`~gesture_sim.motion.smplx.SMPLX_JOINTS`):
                                          global orient, 21 body joints, jaw, eyes, 30 finger
                                          joints
``trans``            (T, 3)       float64 root translation (m), Y up
``betas``            (300,)       float32 shape: zeros (the mean body)
``expressions``      (T, 100)     float64 FLAME expression: zeros (the jaw is in ``poses``)
``model``            ()           <U9     ``"smplx2020"``
``gender``           ()           <U7     ``"neutral"``
``mocap_frame_rate`` ()           int32   frames per second (30 from ``render --smplx``)
==================== ============ ======= ====================================================

The rotations are the inverse of the project's import (:mod:`gesture_sim.motion.smplx` +
:mod:`gesture_sim.motion.retarget`): SMPL-X axes (X left, Y up, Z forward, T-pose rest), the
humanoid's z-up, x-forward world relabelled as the reader's
:func:`~gesture_sim.motion.smplx.humanoid_rest_offsets` does, and each joint's rotation
calibrated against exactly that rest skeleton (:class:`gesture_sim.export.PoseTransfer`):
the T-pose arm of the SMPL-X rest maps onto the humanoid's hanging arm (palms down -> palms
facing the thighs), trunk, legs and head onto the humanoid's own rest. So the project's reader,
given the humanoid's offsets, puts every joint centre (hips, knees, ankles, spine, neck, head,
collars, shoulders, elbows, wrists; the middle finger's base in the direction of the humanoid's
hand site) where the humanoid has it, to float32 precision.

What is approximate:

* **Rest skeleton.** A real SMPL-X body (the licence-gated model file, which this project does
  not read) has its own rest skeleton and proportions (``betas`` = 0: the mean body). The
  rotations carry the humanoid's bone directions onto it; where SMPL-X's rest bones point a few
  degrees differently from the humanoid-derived skeleton (spine curve, shoulder slope, feet),
  those bones are off by that much, and hand positions differ by the difference in proportions.
* **Translation.** ``trans`` is the humanoid's pelvis position (SMPL-X axes, floor at Y = 0)
  minus :data:`SMPLX_PELVIS_REST`, an *estimate* of where the neutral model's pelvis joint sits
  in its rest template (a real SMPL-X body is placed at ``trans`` + its pelvis rest position);
  with the real model the soles may float or sink by a few centimetres. The project's reader
  takes ``trans`` as the pelvis position and its retargeter re-bases the height, so the constant
  does not matter there.
* **Hand direction.** The wrist aims the middle finger's base at the humanoid's hand site, the
  pairing the project's importer uses (wrist -> middle1 against wrist -> hand site); that site
  lies on the palm's surface, 2 cm off the hand body's axis, so on a real SMPL-X body the hand
  sits about 15 degrees further towards the palm than the humanoid's hand.
* **Hands, eyes, face.** The fingers follow the humanoid's finger bodies (each finger's first
  two joints aimed along its segments; the third joint keeps its rest relative to the second,
  :func:`~gesture_sim.export.finger_follows`), from SMPL-X's T-pose rest calibrated onto the
  humanoid's resting hand. The eyes are 0; the jaw follows the humanoid's ``jaw_open`` hinge;
  ``expressions`` are zeros.
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.export import Follow, PoseTransfer, TargetSkeleton, finger_follows
from gesture_sim.fileio import atomic_path
from gesture_sim.motion.smplx import SMPLX_JOINTS, SMPLX_PARENTS, humanoid_rest_offsets

#: Estimated rest position (m, SMPL-X axes) of the neutral SMPL-X model's pelvis joint for
#: betas = 0 (the template's origin lies above the pelvis). Not read from the model file: an
#: approximation, consistent with BEAT2's takes (trans Y ~ 1.30 m for a standing speaker).
SMPLX_PELVIS_REST = np.array([0.0, -0.35, 0.0])
#: Shape coefficients BEAT2 stores (``betas`` (300,)) and expression coefficients per frame.
N_BETAS, N_EXPRESSIONS = 300, 100
MODEL_NAME, GENDER = "smplx2020", "neutral"


def _follow() -> dict[str, Follow]:
    """SMPL-X joint -> the humanoid body and point it follows (see :mod:`gesture_sim.export`)."""
    f = {
        "pelvis": Follow("pelvis", "body:pelvis", aim="spine1", roll=("left_hip", "right_hip")),
        "spine1": Follow("abdomen", "body:abdomen", aim="spine2"),
        "spine2": Follow("chest", "body:chest", aim="spine3"),
        # the reader's spine3: 0.4 of the way from the chest to the neck (both fixed in chest)
        "spine3": Follow("chest", ("lerp", "body:chest", "body:neck", 0.4), aim="neck"),
        "neck": Follow("neck", "body:neck", aim="head"),
        "head": Follow("head", "body:head"),
        "jaw": Follow("jaw", "body:jaw"),
    }
    for side in ("left", "right"):
        f |= {
            f"{side}_hip": Follow(f"{side}_thigh", f"body:{side}_thigh", aim=f"{side}_knee"),
            f"{side}_knee": Follow(f"{side}_shin", f"body:{side}_shin", aim=f"{side}_ankle"),
            f"{side}_ankle": Follow(f"{side}_foot", f"body:{side}_foot", aim=f"{side}_foot",
                                    roll="up"),
            f"{side}_foot": Follow(f"{side}_toes", f"body:{side}_toes"),
            f"{side}_collar": Follow(f"{side}_clavicle", f"body:{side}_clavicle",
                                     aim=f"{side}_shoulder"),
            f"{side}_shoulder": Follow(f"{side}_upper_arm", f"site:{side}_shoulder_site",
                                       aim=f"{side}_elbow"),
            f"{side}_elbow": Follow(f"{side}_forearm", f"site:{side}_elbow_site",
                                    aim=f"{side}_wrist"),
            f"{side}_wrist": Follow(f"{side}_hand", f"site:{side}_wrist_site",
                                    aim=f"{side}_middle1"),
        }
    # the fingers (the reader's hand end: wrist -> middle1 is the humanoid's hand site)
    f |= finger_follows(lambda side, finger, k: f"{side}_{_SMPLX_FINGER.get(finger, finger)}{k}")
    return f


#: The humanoid's finger names that SMPL-X names otherwise.
_SMPLX_FINGER = {"little": "pinky"}


#: How each SMPL-X joint follows the humanoid (joints not listed keep their rest pose).
SMPLX_FOLLOW: dict[str, Follow] = _follow()


def smplx_skeleton(model: mujoco.MjModel) -> TargetSkeleton:
    """The SMPL-X skeleton the project's reader builds for this humanoid (T-pose rest)."""
    return TargetSkeleton(
        names=SMPLX_JOINTS, parents=SMPLX_PARENTS.copy(), offsets=humanoid_rest_offsets(model),
        frame_joints=("pelvis", "neck", "left_shoulder", "right_shoulder"))


def smplx_arrays(model: mujoco.MjModel, qpos: np.ndarray, fps: float = 30.0
                 ) -> dict[str, np.ndarray]:
    """The BEAT2-layout arrays (see the module docstring) of qpos frames (F, nq) at ``fps``.

    ``mocap_frame_rate`` is an int32 as in BEAT2 when ``fps`` is a whole number, else a
    float64 (which BEAT2's readers, and the project's, also accept).
    """
    if not (np.isfinite(fps) and fps > 0):
        raise GestureSimError(f"SMPL-X frame rate must be positive, got {fps}")
    transfer = PoseTransfer(model, smplx_skeleton(model), SMPLX_FOLLOW)
    local, _, root = transfer.pose(qpos)
    n_f = len(local)
    poses = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_rotvec().reshape(n_f, 165)
    rate = (np.array(int(round(fps)), dtype=np.int32) if abs(fps - round(fps)) < 1e-9
            else np.array(float(fps)))
    return {
        "betas": np.zeros(N_BETAS, dtype=np.float32),
        "poses": poses.astype(np.float32),
        "expressions": np.zeros((n_f, N_EXPRESSIONS)),
        "trans": root - SMPLX_PELVIS_REST,
        "model": np.array(MODEL_NAME),
        "gender": np.array(GENDER),
        "mocap_frame_rate": rate,
    }


def save_npz(fh, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` to an open binary file as an uncompressed npz (as BEAT2's are)."""
    np.savez(fh, **arrays)


def write_smplx(path: str | os.PathLike[str], model: mujoco.MjModel, qpos: np.ndarray,
                fps: float = 30.0) -> Path:
    """Write qpos frames (F, nq) at ``fps`` (Hz) as a BEAT2-layout SMPL-X npz, atomically."""
    arrays = smplx_arrays(model, qpos, fps)
    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
        save_npz(fh, arrays)
    return Path(path)
