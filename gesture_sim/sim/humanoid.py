"""Access to the MuJoCo humanoid (``assets/mjcf``): loading, joint names and addresses.

The humanoid contract (docs/DESIGN.md, physics task): a free root joint ``root`` on body ``pelvis``
and one same-named position actuator per hinge/slide joint. :data:`ACTUATED_JOINTS` gives the
order of every target vector q*, qd* (radians for hinges, metres for slides), which is the order
in which the joints appear in ``humanoid.xml`` and also the actuator order.

At qpos = 0 of every hinge the humanoid stands upright facing +x, left side towards +y, z up,
arms hanging at its sides, soles on the floor at z = 0 when the root is at :data:`ROOT_HEIGHT`.
"""

from __future__ import annotations

import mujoco
import numpy as np

from gesture_sim import MJCF_DIR  # folder of humanoid.xml and scene.xml (gesture_sim's data rule)
from gesture_sim.errors import GestureSimError
from gesture_sim.sim import looks

HUMANOID_XML = MJCF_DIR / "humanoid.xml"
SCENE_XML = MJCF_DIR / "scene.xml"

#: Height of the pelvis (root) origin above the floor at qpos = 0 (m): soles then touch z = 0.
ROOT_HEIGHT = 0.98

_SIDES = ("left", "right")

#: The fingers, proximal to distal (bodies S_F_proximal/middle/distal, the thumb's
#: S_thumb_metacarpal/proximal/distal).
FINGERS: tuple[str, ...] = ("thumb", "index", "middle", "ring", "little")
#: One hand's finger joints without the side prefix, in XML order: the thumb's carpometacarpal
#: opposition and flexion, MCP and IP flexion, then per long finger MCP spread (abduction), MCP,
#: PIP and DIP flexion. Flexion > 0 curls the finger (humanoid.xml's header).
_HAND: tuple[str, ...] = (
    "thumb_cmc_oppose", "thumb_cmc_flex", "thumb_mcp_flex", "thumb_ip_flex",
    *(f"{f}_{j}" for f in FINGERS[1:] for j in ("spread", "mcp_flex", "pip_flex", "dip_flex")),
)

#: Every actuated hinge/slide joint, in XML order (the order of q*, qd* and of the actuators).
ACTUATED_JOINTS: tuple[str, ...] = (
    "lower_spine_flex", "lower_spine_bend", "lower_spine_twist",
    "upper_spine_flex", "upper_spine_bend", "upper_spine_twist",
    "neck_flex", "neck_bend", "neck_twist",
    "head_flex", "head_bend", "head_twist",
    "jaw_open", "lower_lip_raise", "lower_lip_forward",
    "left_brow_raise", "right_brow_raise", "left_eyelid_close", "right_eyelid_close",
    "upper_lip_raise", "upper_lip_forward",
    *(f"{s}_lip_corner_{j}" for s in _SIDES for j in ("out", "up")),
    *(f"{s}_brow_inner_{j}" for s in _SIDES for j in ("raise", "squeeze")),
    *(f"{s}_eye_{j}" for s in _SIDES for j in ("yaw", "pitch")),
    *(f"{s}_{j}" for s in _SIDES for j in (
        "clavicle_elevate", "clavicle_protract",
        "shoulder_flex", "shoulder_abduct", "shoulder_twist",
        "elbow_flex", "forearm_twist", "wrist_flex", "wrist_deviate", *_HAND)),
    *(f"{s}_{j}" for s in _SIDES for j in (
        "hip_flex", "hip_abduct", "hip_twist", "knee_flex",
        "ankle_flex", "ankle_invert", "toe_flex")),
)

#: Slide joints (metres); every other actuated joint is a hinge (radians).
SLIDE_JOINTS: tuple[str, ...] = (
    "lower_lip_raise", "lower_lip_forward",
    "left_brow_raise", "right_brow_raise", "left_eyelid_close", "right_eyelid_close",
    "upper_lip_raise", "upper_lip_forward",
    *(f"{s}_lip_corner_{j}" for s in _SIDES for j in ("out", "up")),
    *(f"{s}_brow_inner_{j}" for s in _SIDES for j in ("raise", "squeeze")),
)
#: The eyes' hinges (rad): gaze.
EYE_JOINTS: tuple[str, ...] = tuple(f"{s}_eye_{j}" for s in _SIDES for j in ("yaw", "pitch"))

#: The finger joints of both hands (rad), left then right, in XML order.
FINGER_JOINTS: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _HAND)

#: Joint groups used for torque-saturation statistics and gain tables.
JOINT_GROUPS: dict[str, tuple[str, ...]] = {
    "spine": tuple(j for j in ACTUATED_JOINTS if "spine" in j),
    "neck_head": tuple(j for j in ACTUATED_JOINTS if j.startswith(("neck_", "head_"))),
    "face": ("jaw_open", *SLIDE_JOINTS, *EYE_JOINTS),
    "clavicle": tuple(j for j in ACTUATED_JOINTS if "clavicle" in j),
    "shoulder": tuple(j for j in ACTUATED_JOINTS if "shoulder" in j),
    "elbow_forearm": tuple(j for j in ACTUATED_JOINTS if "elbow" in j or "forearm" in j),
    "wrist": tuple(j for j in ACTUATED_JOINTS if "wrist" in j),
    "fingers": FINGER_JOINTS,
    "hip": tuple(j for j in ACTUATED_JOINTS if "hip" in j),
    "knee": tuple(j for j in ACTUATED_JOINTS if "knee" in j),
    "ankle_toe": tuple(j for j in ACTUATED_JOINTS if "ankle" in j or "toe" in j),
}

#: Joints of the legs (hips to toes), driven by the balance controller.
LEG_JOINTS: tuple[str, ...] = tuple(
    j for j in ACTUATED_JOINTS if j.split("_", 1)[1].startswith(("hip", "knee", "ankle", "toe"))
)
#: Joints above the pelvis (spine, neck, head, face, arms, fingers).
UPPER_BODY_JOINTS: tuple[str, ...] = tuple(j for j in ACTUATED_JOINTS if j not in LEG_JOINTS)


def leg_columns(joint_names) -> np.ndarray:
    """Indices of the leg joints (:data:`LEG_JOINTS`) among ``joint_names``: the columns a
    standing body holds at 0 (the standing pose) whatever a clip's legs do."""
    names = list(joint_names)
    return np.array([names.index(j) for j in LEG_JOINTS if j in names], dtype=int)


def hold_legs(q, joint_names) -> np.ndarray:
    """A copy of ``q`` (..., n) with the leg columns at 0 (the standing pose)."""
    q = np.array(q, dtype=float)
    q[..., leg_columns(joint_names)] = 0.0
    return q


#: Sites named by the contract, per side where applicable.
HAND_SITES = ("left_hand_site", "right_hand_site")
WRIST_SITES = ("left_wrist_site", "right_wrist_site")
ELBOW_SITES = ("left_elbow_site", "right_elbow_site")
SHOULDER_SITES = ("left_shoulder_site", "right_shoulder_site")
FOOT_SITES = ("left_foot_site", "right_foot_site")
HEEL_SITES = ("left_heel_site", "right_heel_site")
TOE_SITES = ("left_toe_site", "right_toe_site")
HEAD_SITE = "head_site"
#: Geoms that form the soles (floor contacts of these count as foot contacts).
FOOT_GEOMS = {"left": ("left_foot", "left_toes"), "right": ("right_foot", "right_toes")}


def load_model(scene: bool = True, look: str = looks.DEFAULT_LOOK) -> mujoco.MjModel:
    """Compile the humanoid; with ``scene`` the floor, lights and cameras (``scene.xml``) too.

    ``look`` (:data:`gesture_sim.sim.looks.LOOKS`) is what is drawn: ``"human"`` (the default,
    :data:`~gesture_sim.sim.looks.DEFAULT_LOOK`: a skinned MakeHuman body) or ``"mannequin"``
    (the capsules). It changes no physics.

    Raises:
        GestureSimError: when the MJCF files are missing or do not compile, or the look is
            unknown.
    """
    looks.check_look(look)
    path = SCENE_XML if scene else HUMANOID_XML
    if not path.is_file():
        raise GestureSimError(f"humanoid model not found: {path}")
    try:
        if look == "mannequin":
            model = mujoco.MjModel.from_xml_path(str(path))
        else:
            model = looks.apply_look(mujoco.MjSpec.from_file(str(path)), look).compile()
    except ValueError as exc:
        raise GestureSimError(f"cannot compile {path.name}: {exc}") from exc
    _check_contract(model)
    return model


def _check_contract(model: mujoco.MjModel) -> None:
    one_dof = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    names = tuple(model.joint(j).name for j in range(model.njnt)
                  if int(model.jnt_type[j]) in one_dof)
    if names != ACTUATED_JOINTS:
        raise GestureSimError("humanoid.xml joints do not match ACTUATED_JOINTS (contract broken)")
    act_joints = tuple(model.joint(model.actuator_trnid[a, 0]).name for a in range(model.nu))
    if act_joints != ACTUATED_JOINTS:
        raise GestureSimError("humanoid.xml actuators are not in ACTUATED_JOINTS order")


def joint_ids(model: mujoco.MjModel, names: tuple[str, ...] | list[str] = ACTUATED_JOINTS
              ) -> np.ndarray:
    """Joint ids of ``names``, shape (n,), int."""
    return np.array([model.joint(n).id for n in names], dtype=int)


def qpos_addresses(model: mujoco.MjModel,
                   names: tuple[str, ...] | list[str] = ACTUATED_JOINTS) -> np.ndarray:
    """Indices into ``data.qpos`` of the (1-DoF) joints ``names``, shape (n,), int."""
    return model.jnt_qposadr[joint_ids(model, names)].astype(int)


def qvel_addresses(model: mujoco.MjModel,
                   names: tuple[str, ...] | list[str] = ACTUATED_JOINTS) -> np.ndarray:
    """Indices into ``data.qvel`` / ``qfrc_*`` of the (1-DoF) joints ``names``, shape (n,)."""
    return model.jnt_dofadr[joint_ids(model, names)].astype(int)


def actuator_ids(model: mujoco.MjModel,
                 names: tuple[str, ...] | list[str] = ACTUATED_JOINTS) -> np.ndarray:
    """Actuator ids (same names as the joints), shape (n,), int."""
    return np.array([model.actuator(n).id for n in names], dtype=int)


def actuated_index(names: tuple[str, ...] | list[str]) -> np.ndarray:
    """Positions of ``names`` within :data:`ACTUATED_JOINTS` (index into q*), shape (n,)."""
    lookup = {n: i for i, n in enumerate(ACTUATED_JOINTS)}
    try:
        return np.array([lookup[n] for n in names], dtype=int)
    except KeyError as exc:
        raise GestureSimError(f"unknown humanoid joint: {exc.args[0]}") from exc


def joint_ranges(model: mujoco.MjModel) -> np.ndarray:
    """Lower and upper limits of :data:`ACTUATED_JOINTS`, shape (n_act, 2), rad or m."""
    return model.jnt_range[joint_ids(model)].copy()


def force_ranges(model: mujoco.MjModel) -> np.ndarray:
    """Actuator force limits (N·m or N) in :data:`ACTUATED_JOINTS` order, shape (n_act, 2)."""
    return model.actuator_forcerange[actuator_ids(model)].copy()


def root_qpos(height: float = ROOT_HEIGHT) -> np.ndarray:
    """Free-root qpos (x, y, z, qw, qx, qy, qz) of the upright pose at the origin, shape (7,)."""
    return np.array([0.0, 0.0, height, 1.0, 0.0, 0.0, 0.0])


def qpos_from_targets(model: mujoco.MjModel, q_act: np.ndarray,
                      root: np.ndarray | None = None) -> np.ndarray:
    """A full ``qpos`` (shape (nq,)) from actuated joint values ``q_act`` (shape (n_act,)).

    ``root`` is the free-root (x, y, z, qw, qx, qy, qz); default :func:`root_qpos`.
    """
    q_act = np.asarray(q_act, dtype=float)
    if q_act.shape != (len(ACTUATED_JOINTS),):
        raise GestureSimError(
            f"expected {len(ACTUATED_JOINTS)} joint values, got shape {q_act.shape}")
    qpos = np.zeros(model.nq)
    qpos[:7] = root_qpos() if root is None else root
    qpos[qpos_addresses(model)] = q_act
    return qpos


def standing_height(model: mujoco.MjModel) -> float:
    """Pelvis height of the upright pose (m): the root height at qpos = 0."""
    return float(ROOT_HEIGHT)
