"""Retargeting a source skeleton's motion onto the MuJoCo humanoid's actuated joints.

Euler angles are not copied (skeletons differ in rest pose and joint axes; the humanoid's joints
are hinges). Instead, per frame, a damped-least-squares IK on the MuJoCo model (``mj_jac``,
joint limits as clamps, warm-started from the previous frame; the design of mink/GMR) makes the
humanoid's bone *directions* match the source's: trunk, shoulder line, head up/forward, upper
arm, forearm, hand, thigh, shin, foot. Matching directions rather than positions makes the
result independent of the source's proportions and units.

Alignment: the source's up axis (detected) becomes +z, its facing at the first frame becomes
+x, the root translation is scaled by the leg-length ratio, and the body is lifted so that the
lowest foot point touches z = 0. The fingers are not solved here (their joints stay at 0:
:mod:`gesture_sim.motion.finger_tracks` maps a source's finger motion separately), and the
face joints stay at 0.

Quality (:attr:`RetargetResult.error`): elbow and wrist positions relative to the shoulder,
divided by the arm length (upper arm + forearm), humanoid vs source, in the aligned frame;
the mean over frames, both arms and both points.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError
from gesture_sim.motion.skeleton import SkeletonMotion
from gesture_sim.sim.humanoid import JOINT_GROUPS

#: Key points of the humanoid stored with every clip (sites of the humanoid contract).
KEYPOINTS = ("left_hand", "right_hand", "left_elbow", "right_elbow", "head", "left_foot",
             "right_foot")
_KEYPOINT_SITES = ("left_hand_site", "right_hand_site", "left_elbow_site", "right_elbow_site",
                   "head_site", "left_foot_site", "right_foot_site")
#: Joints the retargeter never drives (the face: jaw, lips, brows, lids, eyes stay at 0).
FACE_JOINTS = JOINT_GROUPS["face"]

# ---------------------------------------------------------------------------------------------
# Skeleton families: canonical point -> source joint name (a tuple = midpoint of those joints).
# "palm": the palm normal at the source's rest pose ("down" for a T-pose, "medial" for arms
# hanging down, None when the rest pose says nothing reliable about the hand's roll).
# ---------------------------------------------------------------------------------------------


def _sided(left: dict[str, str], right_sub: tuple[str, str]) -> dict[str, str]:
    out = dict(left)
    for key, name in left.items():
        out["r_" + key[2:]] = name.replace(*right_sub)
    return out


FAMILIES: dict[str, dict] = {
    "smplx": {
        "points": {
            "pelvis": "pelvis", "neck": "neck", "head": "head", "spine": "spine3",
            **_sided({"l_shoulder": "left_shoulder", "l_elbow": "left_elbow",
                      "l_wrist": "left_wrist", "l_hand_end": "left_middle1",
                      "l_hip": "left_hip", "l_knee": "left_knee", "l_ankle": "left_ankle",
                      "l_toe": "left_foot"}, ("left", "right")),
        },
        "palm": "down", "neutral_rest": True,
    },
    "bandai": {
        "points": {
            "pelvis": "Hips", "neck": "Neck", "head": "Head", "spine": "Chest",
            **_sided({"l_shoulder": "UpperArm_L", "l_elbow": "LowerArm_L", "l_wrist": "Hand_L",
                      "l_hand_end": "Hand_L_End", "l_hip": "UpperLeg_L", "l_knee": "LowerLeg_L",
                      "l_ankle": "Foot_L", "l_toe": "Toes_L"}, ("_L", "_R")),
        },
        "palm": None, "neutral_rest": False,
    },
    "cmu": {
        "points": {
            "pelvis": "Hips", "neck": "Neck", "head": "Head", "spine": "Spine1",
            **_sided({"l_shoulder": "LeftArm", "l_elbow": "LeftForeArm", "l_wrist": "LeftHand",
                      "l_hand_end": "LeftHandIndex1", "l_hip": "LeftUpLeg", "l_knee": "LeftLeg",
                      "l_ankle": "LeftFoot", "l_toe": "LeftToeBase"}, ("Left", "Right")),
        },
        "palm": "down", "neutral_rest": True,
    },
    "mocapbank": {
        "points": {
            "pelvis": "Hips", "neck": "Neck", "head": "Head", "spine": "Chest2",
            **_sided({"l_shoulder": "LeftShoulder", "l_elbow": "LeftElbow",
                      "l_wrist": "LeftWrist", "l_hand_end": "LeftWrist_End",
                      "l_hip": "LeftHip", "l_knee": "LeftKnee", "l_ankle": "LeftAnkle",
                      "l_toe": "LeftAnkle_End"}, ("Left", "Right")),
        },
        "palm": "medial", "neutral_rest": True,
    },
    "pymo23": {
        "points": {
            "pelvis": "Hips", "neck": ("LeftShoulder", "RightShoulder"), "head": "Head",
            "spine": "Spine",
            **_sided({"l_shoulder": "LeftArm", "l_elbow": "LeftForeArm", "l_wrist": "LeftHand",
                      "l_hand_end": "LeftHand_End", "l_hip": "LeftUpLeg", "l_knee": "LeftLeg",
                      "l_ankle": "LeftFoot", "l_toe": "LeftToeBase"}, ("Left", "Right")),
        },
        "palm": "down", "neutral_rest": True,
    },
}
FAMILIES["mixamo"] = {  # Mixamo ("mixamorig:" prefix stripped) uses CMU-like names
    "points": {**FAMILIES["cmu"]["points"], "spine": "Spine2", "l_hand_end": "LeftHandMiddle1",
               "r_hand_end": "RightHandMiddle1"},
    "palm": "down", "neutral_rest": True,
}


def _strip(name: str) -> str:
    return name.rsplit(":", 1)[-1]


def detect_family(names: tuple[str, ...] | list[str]) -> str:
    """The skeleton family whose joint map fits ``names`` (prefixes like ``mixamorig:`` ignored).

    Raises:
        GestureSimError: no built-in map fits.
    """
    have = {_strip(n) for n in names}
    for family, spec in FAMILIES.items():
        needed = set()
        for value in spec["points"].values():
            needed.update(value if isinstance(value, tuple) else (value,))
        if needed <= have:
            return family
    raise GestureSimError(
        "unknown skeleton: no built-in joint map fits its joint names "
        f"({', '.join(list(names)[:8])}, ...); known families: {', '.join(FAMILIES)}")


# ---------------------------------------------------------------------------------------------
# The humanoid model
# ---------------------------------------------------------------------------------------------


def load_humanoid():
    """The humanoid ``mujoco.MjModel`` (body only) and its actuated joint names.

    Uses :mod:`gesture_sim.sim.humanoid` when present, else ``assets/mjcf/humanoid.xml``.
    """
    import mujoco

    try:
        from gesture_sim.sim import humanoid as hm
    except ImportError:
        hm = None
    if hm is not None and hasattr(hm, "load_model"):
        model = hm.load_model(scene=False)
        names = tuple(getattr(hm, "ACTUATED_JOINTS", ()))
    else:
        path = Path(__file__).resolve().parents[2] / "assets" / "mjcf" / "humanoid.xml"
        if not path.exists():
            raise GestureSimError(f"humanoid model not found at {path}")
        model = mujoco.MjModel.from_xml_path(str(path))
        names = ()
    if not names:
        names = hinge_joint_names(model)
    return model, names


def hinge_joint_names(model) -> tuple[str, ...]:
    """Names of the model's hinge and slide joints, in model order."""
    import mujoco

    kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    return tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
                 for j in range(model.njnt) if int(model.jnt_type[j]) in kinds)


@dataclass
class RetargetResult:
    """A retargeted clip.

    Attributes:
        qpos: (T, n_joints) float32 joint positions (rad/m), columns = ``joint_names``.
        root_pos: (T, 3) pelvis position (m), feet on the floor.
        root_quat: (T, 4) pelvis orientation (w, x, y, z), facing +x at the start.
        keypoints: (T, K, 3) world positions (m) of :data:`KEYPOINTS`.
        error: mean retarget error (fraction of arm length), see the module docstring.
        error_p95: 95th percentile over frames of the per-frame error.
        family: the skeleton family used.
        fps: frame rate (Hz).
    """

    qpos: np.ndarray
    root_pos: np.ndarray
    root_quat: np.ndarray
    keypoints: np.ndarray
    error: float
    error_p95: float
    family: str
    fps: float


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


class Retargeter:
    """Retargets :class:`SkeletonMotion` onto the humanoid (one instance per model, reusable).

    Args:
        model: the humanoid ``mujoco.MjModel``; loaded with :func:`load_humanoid` when ``None``.
        joint_names: the actuated joints (columns of the output); from the model when ``None``.
        iterations: IK iterations per frame after the first (warm-started).
        damping: Levenberg-Marquardt damping of the IK step.
    """

    #: (humanoid point a, humanoid point b, source point a, source point b, weight) tasks.
    BONES = (
        ("pelvis", "neck", "pelvis", "neck", 2.0),
        ("r_shoulder", "l_shoulder", "r_shoulder", "l_shoulder", 1.0),
        ("l_shoulder", "l_elbow", "l_shoulder", "l_elbow", 3.0),
        ("l_elbow", "l_wrist", "l_elbow", "l_wrist", 3.0),
        ("l_wrist", "l_hand", "l_wrist", "l_hand_end", 0.5),
        ("r_shoulder", "r_elbow", "r_shoulder", "r_elbow", 3.0),
        ("r_elbow", "r_wrist", "r_elbow", "r_wrist", 3.0),
        ("r_wrist", "r_hand", "r_wrist", "r_hand_end", 0.5),
        ("l_hip", "l_knee", "l_hip", "l_knee", 1.0),
        ("l_knee", "l_ankle", "l_knee", "l_ankle", 1.0),

        ("r_hip", "r_knee", "r_hip", "r_knee", 1.0),
        ("r_knee", "r_ankle", "r_knee", "r_ankle", 1.0),

    )

    def __init__(self, model=None, joint_names: tuple[str, ...] | None = None,
                 iterations: int = 4, damping: float = 0.05) -> None:
        import mujoco

        if model is None:
            model, names = load_humanoid()
            joint_names = joint_names or names
        self.model = model
        self.data = mujoco.MjData(model)
        self.iterations = iterations
        self.damping = damping
        m = model
        if joint_names is None:
            joint_names = hinge_joint_names(m)
        self.joint_names = tuple(joint_names)
        jid = [self._id(mujoco.mjtObj.mjOBJ_JOINT, n) for n in self.joint_names]
        self.qadr = np.array([m.jnt_qposadr[j] for j in jid])
        self.dadr = np.array([m.jnt_dofadr[j] for j in jid])
        self.limited = np.array([bool(m.jnt_limited[j]) for j in jid])
        self.range = np.array([m.jnt_range[j] for j in jid])
        solve = [i for i, n in enumerate(self.joint_names)
                 if n not in FACE_JOINTS + JOINT_GROUPS["fingers"] and not n.endswith("toe_flex")]
        self.solve_idx = np.array(solve)
        root = [j for j in range(m.njnt) if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)]
        if not root:
            raise GestureSimError("humanoid model has no free root joint")
        self.root_qadr = int(m.jnt_qposadr[root[0]])
        self._define_points()

    def _id(self, kind, name: str) -> int:
        import mujoco

        i = mujoco.mj_name2id(self.model, kind, name)
        if i < 0:
            raise GestureSimError(f"humanoid model has no {kind.name[6:].lower()} {name!r}")
        return i

    def _define_points(self) -> None:
        """Humanoid points as (body id, offset in body frame), measured at qpos = 0."""
        import mujoco

        m, d = self.model, self.data
        d.qpos[:] = 0
        d.qpos[self.root_qadr + 3] = 1.0
        mujoco.mj_kinematics(m, d)
        body = lambda n: self._id(mujoco.mjtObj.mjOBJ_BODY, n)  # noqa: E731
        site = lambda n: self._id(mujoco.mjtObj.mjOBJ_SITE, n)  # noqa: E731
        pts: dict[str, tuple[int, np.ndarray]] = {}

        def from_world(name: str, bid: int, world: np.ndarray) -> None:
            pts[name] = (bid, d.xmat[bid].reshape(3, 3).T @ (world - d.xpos[bid]))

        def at_site(name: str, sname: str) -> None:
            s = site(sname)
            from_world(name, int(m.site_bodyid[s]), d.site_xpos[s].copy())

        for name, bname in (("pelvis", "pelvis"), ("neck", "neck"), ("head", "head")):
            from_world(name, body(bname), d.xpos[body(bname)].copy())
        head = body("head")
        from_world("head_up", head, d.xpos[head] + np.array([0, 0, 0.1]))
        from_world("head_fwd", head, d.xpos[head] + np.array([0.1, 0, 0]))
        for s, side in (("l", "left"), ("r", "right")):
            at_site(f"{s}_shoulder", f"{side}_shoulder_site")
            at_site(f"{s}_elbow", f"{side}_elbow_site")
            at_site(f"{s}_wrist", f"{side}_wrist_site")
            at_site(f"{s}_hand", f"{side}_hand_site")
            hb = body(f"{side}_hand")
            medial = np.array([0, -0.05 if s == "l" else 0.05, 0])
            from_world(f"{s}_palm", hb, d.site_xpos[site(f"{side}_hand_site")] + medial)
            for key, bname in (("hip", "thigh"), ("knee", "shin"), ("ankle", "foot")):
                from_world(f"{s}_{key}", body(f"{side}_{bname}"),
                           d.xpos[body(f"{side}_{bname}")].copy())
            at_site(f"{s}_toe", f"{side}_toe_site")
            at_site(f"{s}_heel", f"{side}_heel_site")
        self.points = pts
        self.world0 = {k: d.xmat[b].reshape(3, 3) @ off + d.xpos[b] for k, (b, off) in pts.items()}
        self.foot_sites = [site(f"{side}_{p}_site") for side in ("left", "right")
                           for p in ("heel", "toe", "foot")]
        self.keypoint_sites = [site(n) for n in _KEYPOINT_SITES]
        arm = [np.linalg.norm(self.world0[f"{s}_elbow"] - self.world0[f"{s}_shoulder"])
               + np.linalg.norm(self.world0[f"{s}_wrist"] - self.world0[f"{s}_elbow"])
               for s in "lr"]
        self.arm_length = float(np.mean(arm))
        self.leg_length = float(np.mean([
            np.linalg.norm(self.world0[f"{s}_knee"] - self.world0[f"{s}_hip"])
            + np.linalg.norm(self.world0[f"{s}_ankle"] - self.world0[f"{s}_knee"]) for s in "lr"]))

    # -----------------------------------------------------------------------------------------

    def source_points(self, motion: SkeletonMotion, family: str) -> dict[str, np.ndarray]:
        """Canonical points (T, 3) of the source in its own axes (m)."""
        index = {_strip(n): i for i, n in enumerate(motion.names)}
        out = {}
        for key, value in FAMILIES[family]["points"].items():
            names = value if isinstance(value, tuple) else (value,)
            out[key] = np.mean([motion.positions[:, index[n]] for n in names], axis=0)
        return out

    def retarget(self, motion: SkeletonMotion, family: str | None = None) -> RetargetResult:
        """Retarget ``motion`` (any fps; the output keeps its frame rate).

        Raises:
            GestureSimError: unknown skeleton family.
        """
        family = family or detect_family(motion.names)
        spec = FAMILIES[family]
        src = self.source_points(motion, family)
        index = {_strip(n): i for i, n in enumerate(motion.names)}

        # Body frames from positions: pelvis (hip line + trunk) and chest (shoulder line).
        pelvis_frame = _frame_from(src["l_hip"] - src["r_hip"], src["neck"] - src["pelvis"])
        chest_frame = _frame_from(src["l_shoulder"] - src["r_shoulder"],
                                  src["neck"] - src["spine"])
        head_j = index[_first(spec["points"]["head"])]
        if spec["neutral_rest"]:
            # The file's rest pose (zero rotations) is an upright neutral pose: a joint's rest
            # frame is the body frame of the rest skeleton.
            rest = _rest_positions(motion)
            rest_pt = {k: np.mean([rest[index[n]] for n in _names(v)], axis=0)
                       for k, v in spec["points"].items()}
            rest_frame = _frame_from(rest_pt["l_shoulder"] - rest_pt["r_shoulder"],
                                     rest_pt["neck"] - rest_pt["pelvis"])
            head_local = rest_frame
        else:
            # Calibrate: on average the head faces where the chest faces.
            head_local = _polar(np.einsum("tba,tbc->ac", motion.rotations[:, head_j],
                                          chest_frame))
        head_src = motion.rotations[:, head_j] @ head_local

        # World axes: detected up axis -> +z; facing at frame 0 -> +x.
        up_world = _detect_up(src["neck"] - src["pelvis"])
        fwd0 = pelvis_frame[0, :, 0] - up_world * (pelvis_frame[0, :, 0] @ up_world)
        fwd0 = _unit(fwd0)
        align = np.stack([fwd0, np.cross(up_world, fwd0), up_world])      # rows: new x, y, z

        pts = {k: v @ align.T for k, v in src.items()}
        head_frame = align @ head_src
        root_mat = align @ pelvis_frame
        root_quat = np.roll(Rotation.from_matrix(root_mat).as_quat(), 1, axis=1)  # (w, x, y, z)

        src_leg = np.mean([np.linalg.norm(pts[f"{s}_knee"] - pts[f"{s}_hip"], axis=1).mean()
                           + np.linalg.norm(pts[f"{s}_ankle"] - pts[f"{s}_knee"], axis=1).mean()
                           for s in "lr"])
        scale = self.leg_length / max(src_leg, 1e-6)
        root_pos = (pts["pelvis"] - pts["pelvis"][0] * np.array([1, 1, 0])) * scale
        root_pos[:, 2] += self.world0["pelvis"][2] - root_pos[0, 2]

        # Direction targets (T, 3) per task.
        tasks = []
        for ha, hb, sa, sb, w in self.BONES:
            tasks.append((ha, hb, _unit(pts[sb] - pts[sa]), w))
        for s in "lr":  # soles flat, pointing where the source's feet point
            foot = pts[f"{s}_toe"] - pts[f"{s}_ankle"]
            foot[:, 2] = 0.0
            tasks.append((f"{s}_heel", f"{s}_toe", _unit(foot), 1.0))
        tasks.append(("head", "head_up", head_frame[:, :, 2], 1.0))
        tasks.append(("head", "head_fwd", head_frame[:, :, 0], 1.0))
        if spec["neutral_rest"] and spec["palm"] is not None:
            up_r, left_r = rest_frame[:, 2], rest_frame[:, 1]
            for s, sign in (("l", 1.0), ("r", -1.0)):
                j = index[spec["points"][f"{s}_wrist"]]
                rest_normal = -up_r if spec["palm"] == "down" else -sign * left_r
                normal = np.einsum("tab,b->ta", motion.rotations[:, j], rest_normal) @ align.T
                tasks.append((f"{s}_wrist", f"{s}_palm", normal, 0.3))

        qpos, root_pos, keypoints, hum_arm = self._solve(tasks, root_pos, root_quat)
        error = _arm_error(hum_arm, pts, self.arm_length)
        return RetargetResult(
            qpos=qpos.astype(np.float32), root_pos=root_pos, root_quat=root_quat,
            keypoints=keypoints, error=float(error.mean()),
            error_p95=float(np.percentile(error, 95)), family=family, fps=motion.fps,
        )

    def _solve(self, tasks, root_pos: np.ndarray, root_quat: np.ndarray):
        import mujoco

        m, d = self.model, self.data
        n_frames = len(root_pos)
        nj = len(self.joint_names)
        cols = self.dadr[self.solve_idx]
        qa = self.qadr[self.solve_idx]
        lim = self.limited[self.solve_idx]
        lo = np.where(lim, self.range[self.solve_idx, 0], -np.inf)
        hi = np.where(lim, self.range[self.solve_idx, 1], np.inf)
        n_var = len(self.solve_idx)
        lengths = [np.linalg.norm(self.world0[b] - self.world0[a]) for a, b, _, _ in tasks]
        point_names = sorted({p for a, b, _, _ in tasks for p in (a, b)})
        jacp = np.zeros((3, m.nv))
        qpos_out = np.zeros((n_frames, nj))
        arm_keys = ("l_shoulder", "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist")
        hum_arm = np.zeros((n_frames, 6, 3))
        feet = np.zeros((n_frames, len(self.foot_sites)))
        keypoints = np.zeros((n_frames, len(self.keypoint_sites), 3))
        weights = np.sqrt(np.repeat([w for *_, w in tasks], 3))
        q = np.zeros(n_var)
        d.qpos[:] = 0
        for t in range(n_frames):
            d.qpos[self.root_qadr:self.root_qadr + 3] = root_pos[t]
            d.qpos[self.root_qadr + 3:self.root_qadr + 7] = root_quat[t]
            for it in range(self.iterations if t else 25):
                d.qpos[qa] = q
                mujoco.mj_kinematics(m, d)
                mujoco.mj_comPos(m, d)
                pos, jac = {}, {}
                for p in point_names:
                    bid, off = self.points[p]
                    pos[p] = d.xmat[bid].reshape(3, 3) @ off + d.xpos[bid]
                    mujoco.mj_jac(m, d, jacp, None, pos[p], bid)
                    jac[p] = jacp[:, cols].copy()
                res = np.concatenate([
                    length * target[t] - (pos[b] - pos[a])
                    for (a, b, target, _), length in zip(tasks, lengths, strict=True)])
                J = np.concatenate([jac[b] - jac[a] for a, b, _, _ in tasks])
                Jw = J * weights[:, None]
                H = Jw.T @ Jw
                H[np.diag_indices(n_var)] += self.damping + 1e-3
                g = Jw.T @ (res * weights) - 1e-3 * q
                q = np.clip(q + np.linalg.solve(H, g), lo, hi)
                del it
            d.qpos[qa] = q
            mujoco.mj_kinematics(m, d)
            qpos_out[t, self.solve_idx] = q
            for k, key in enumerate(arm_keys):
                bid, off = self.points[key]
                hum_arm[t, k] = d.xmat[bid].reshape(3, 3) @ off + d.xpos[bid]
            feet[t] = d.site_xpos[self.foot_sites, 2]
            keypoints[t] = d.site_xpos[self.keypoint_sites]
        # Feet on the floor: lift/lower by the lowest foot point (lightly smoothed).
        lift = -feet.min(axis=1)
        if n_frames > 3:
            lift = gaussian_filter1d(lift, 1.0, mode="nearest")
        root_pos = root_pos.copy()
        root_pos[:, 2] += lift
        keypoints[:, :, 2] += lift[:, None]
        hum_arm[:, :, 2] += lift[:, None]
        return qpos_out, root_pos, keypoints, hum_arm

    def keypoints(self, qpos: np.ndarray, root_pos: np.ndarray, root_quat: np.ndarray
                  ) -> np.ndarray:
        """World positions (T, K, 3) of :data:`KEYPOINTS` for a clip replayed kinematically."""
        import mujoco

        m, d = self.model, self.data
        out = np.zeros((len(qpos), len(self.keypoint_sites), 3))
        d.qpos[:] = 0
        for t in range(len(qpos)):
            d.qpos[self.root_qadr:self.root_qadr + 3] = root_pos[t]
            d.qpos[self.root_qadr + 3:self.root_qadr + 7] = root_quat[t]
            d.qpos[self.qadr] = qpos[t]
            mujoco.mj_kinematics(m, d)
            out[t] = d.site_xpos[self.keypoint_sites]
        return out


def _rest_positions(motion: SkeletonMotion) -> np.ndarray:
    """(J, 3) joint positions with every rotation at identity (the file's rest pose)."""
    from gesture_sim.motion.skeleton import forward_kinematics

    n = len(motion.names)
    pos, _ = forward_kinematics(motion.parents, motion.offsets[None],
                                np.broadcast_to(np.eye(3), (1, n, 3, 3)))
    return pos[0]


def _names(value: str | tuple[str, ...]) -> tuple[str, ...]:
    return value if isinstance(value, tuple) else (value,)


def _first(value: str | tuple[str, ...]) -> str:
    return _names(value)[0]


def _frame_from(left: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) with columns forward, left, up from a left and an up vector.

    ``up`` is kept, ``left`` is made orthogonal to it, forward = left x up.
    """
    z = _unit(up)
    y = _unit(left - z * np.sum(left * z, axis=-1, keepdims=True))
    return np.stack([np.cross(y, z), y, z], axis=-1)


def _polar(m: np.ndarray) -> np.ndarray:
    """The rotation nearest to the 3x3 matrix ``m`` (polar decomposition via SVD)."""
    u, _, vt = np.linalg.svd(m)
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] *= -1
        r = u @ vt
    return r


def _detect_up(trunk: np.ndarray) -> np.ndarray:
    """The signed coordinate axis closest to the mean trunk direction (pelvis -> neck)."""
    mean = _unit(trunk.mean(axis=0))
    k = int(np.argmax(np.abs(mean)))
    axis = np.zeros(3)
    axis[k] = np.sign(mean[k])
    return axis


def _arm_error(hum_arm: np.ndarray, pts: dict[str, np.ndarray], hum_arm_len: float) -> np.ndarray:
    """Per-frame retarget error: elbow and wrist relative to the shoulder / arm length."""
    errs = []
    for k, s in enumerate("lr"):
        src_len = (np.linalg.norm(pts[f"{s}_elbow"] - pts[f"{s}_shoulder"], axis=1)
                   + np.linalg.norm(pts[f"{s}_wrist"] - pts[f"{s}_elbow"], axis=1))[:, None]
        sh_h = hum_arm[:, 3 * k]
        for j, key in ((1, "elbow"), (2, "wrist")):
            h = (hum_arm[:, 3 * k + j] - sh_h) / hum_arm_len
            r = (pts[f"{s}_{key}"] - pts[f"{s}_shoulder"]) / src_len
            errs.append(np.linalg.norm(h - r, axis=1))
    return np.mean(errs, axis=0)


def heading_frame(root_pos: np.ndarray, root_quat: np.ndarray, world: np.ndarray) -> np.ndarray:
    """Points (T, K, 3) expressed in the pelvis heading frame.

    The origin is the pelvis projected onto the floor, x is the pelvis's forward direction
    projected horizontally, z is up (so z stays the height above the floor).
    """
    mats = Rotation.from_quat(np.roll(root_quat, -1, axis=1)).as_matrix()
    fwd = mats[:, :, 0].copy()
    fwd[:, 2] = 0
    fwd = _unit(fwd)
    left = np.stack([-fwd[:, 1], fwd[:, 0], np.zeros(len(fwd))], axis=1)
    rel = world - np.concatenate([root_pos[:, :2], np.zeros((len(root_pos), 1))], axis=1)[:, None]
    return np.stack([np.einsum("tkc,tc->tk", rel, fwd), np.einsum("tkc,tc->tk", rel, left),
                     rel[..., 2]], axis=-1)


def match_any(name: str, patterns: list[str]) -> bool:
    """Whether ``name`` matches any fnmatch pattern."""
    return any(fnmatch.fnmatch(name, p) for p in patterns)
