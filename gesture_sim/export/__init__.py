"""The simulated humanoid's motion on other skeletons: SMPL-X (:mod:`.smplx`), Mixamo
(:mod:`.mixamo`), any user's BVH skeleton (:mod:`.skeleton`), and a live VMC pose stream
(:mod:`.vmc`).

The exporters share one mapping, :class:`PoseTransfer`: for every joint of a *target* skeleton
(names, parents, rest offsets; its rest pose is every rotation at identity) a :class:`Follow`
says which humanoid body drives its rotation, where on the humanoid the joint sits, and which
child's bone it aims. Per frame the humanoid is posed (MuJoCo forward kinematics of the qpos
row) and each target joint gets the global rotation

    G_j(t) = S_j(t) · C · R_b(t) · H_j · T_jᵀ

where R_b is the driving body's world rotation, C relabels MuJoCo axes (x forward, y left, z up)
as the target's (X left, Y up, Z forward: the SMPL-X and BVH convention; a pure relabelling,
no mirror), T_j and H_j are the rest frames of the joint's bone on the target and on the
humanoid (built the same way from the bone direction and a roll reference), so ``H_j T_jᵀ`` is
the rest calibration that turns, e.g., the target's T-pose arm into the humanoid's hanging arm,
and S_j is the smallest swing that makes the target bone point exactly at the humanoid's child
point (the identity when both ends of the bone are fixed in the driving body). The local
rotations are ``G_parentᵀ G_j``.

What is exact and what is not:

* **Bone directions are exact** for every aimed bone: the target joint → its aimed child points
  where the humanoid's corresponding points do (the joint centres and sites listed in the
  exporter's table). Bone *lengths* are the target's, so positions match only up to the target's
  proportions (exactly when the target has the humanoid's lengths, as the SMPL-X skeleton the
  project's own reader builds for the humanoid does).
* **Roll** (the twist about a bone) follows the driving body. For a bone that is not aimed
  (a joint with several children: its other children) the child's position is carried rigidly
  by the parent's rotation, so it matches only as far as the rest shapes agree.
* Joints without a driving body (eyes, End Sites) keep their rest pose relative to their
  parent (identity local rotation). The fingers follow the humanoid's finger bodies
  (:func:`finger_follows`): their first two segments aimed (exact), the last turning with the
  humanoid's last joint relative to the segment before (:attr:`Follow.like_parent`:
  ``G_j = S_p · C · R_b(t) · R_b(0)ᵀ R_q(0) · H_p T_pᵀ`` with the parent p's swing S_p, its
  driving body q and its rest calibration), so its direction matches as far as the rest
  shapes of the two last segments agree (within 1.5 degrees on the Mixamo rig).

Frames are whatever rows are given (the caller resamples the simulation to the export rate).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from gesture_sim.errors import GestureSimError

#: MuJoCo world/body axes -> target axes: ``v_target = MJ_TO_TARGET @ v_mujoco`` (x->Z, y->X,
#: z->Y). The same relabelling as :data:`gesture_sim.motion.bvh_export.MJ_TO_BVH` and as the
#: SMPL-X reader's humanoid offsets (:func:`gesture_sim.motion.smplx.humanoid_rest_offsets`).
MJ_TO_TARGET = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])

#: Roll references by name: (humanoid direction in MuJoCo axes, target direction in target axes).
_AXES = {
    "fwd": (np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])),
    "up": (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])),
    "left": (np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])),
}

#: A humanoid point: ``"body:NAME"`` (a body's origin), ``"site:NAME"``,
#: ``("lerp", POINT_A, POINT_B, f)`` (the point a + f (b - a)), or ``("chain", (POINT, ...), f)``
#: (the point at fraction f of the polyline's length); evaluated at the rest pose.
Point = str | tuple


@dataclass(frozen=True)
class Follow:
    """How one target joint follows the humanoid.

    Attributes:
        body: the humanoid body whose rotation drives the joint, or ``None`` to keep the rest
            pose relative to the parent (identity local rotation: fingers, eyes).
        at: the humanoid point where the joint sits (a :data:`Point`); needed for the root, for
            an aimed joint and for a joint another one aims at. It moves with ``body`` (or, for
            a joint without a body, with the nearest ancestor's body).
        aim: the child joint whose bone direction is matched exactly; ``None`` for a joint
            whose orientation is taken as a whole: the rest body frame of the target (upright,
            facing forward: see :attr:`TargetSkeleton.frame_joints`) is mapped onto the body's
            frame at the humanoid's rest pose (the head, toes, jaw).
        roll: the roll reference of an aimed bone: ``"fwd"``, ``"up"``, ``"left"`` (the
            humanoid's and the target's axis of that name), or a pair ``(A, B)`` of target
            joints (the rest vector B -> A on the target, the humanoid points of B -> A).
        origin: where the joint's own aimed bone starts on the humanoid, when that is not
            ``at`` (the point its parent aims at): the wrist aims the Mixamo rig's middle
            finger base at the hand site, while the finger's first segment runs from the
            humanoid's knuckle. ``at`` is then carried by the parent's body, ``origin`` by
            ``body``.
        like_parent: the joint turns with ``body`` *relative to the parent's driving body*,
            in the parent's calibrated frame (the parent's rest calibration and swing; no aim
            of its own): a bone that continues its parent's bone and has no joint beyond it to
            aim at, as a finger's last joint, carries the humanoid's joint angle between the
            two bodies; its rest direction relative to the parent is the target's.
    """

    body: str | None = None
    at: Point | None = None
    aim: str | None = None
    roll: str | tuple[str, str] = "fwd"
    origin: Point | None = None
    like_parent: bool = False


#: The humanoid's finger bodies from the hand outwards (``{side}_{finger}_{segment}``).
FINGER_SEGMENTS: dict[str, tuple[str, str, str]] = {
    "thumb": ("metacarpal", "proximal", "distal"),
    **{f: ("proximal", "middle", "distal") for f in ("index", "middle", "ring", "little")},
}


def finger_follows(joint) -> dict[str, Follow]:
    """How a target's three joints per finger follow the humanoid's fingers.

    ``joint(side, finger, k)`` names the target's k-th joint (k = 1..3, from the hand out) of
    ``finger`` (the humanoid's names: thumb, index, middle, ring, little) on ``side``. Joints
    1 and 2 turn with the humanoid's first two segments of that finger and aim at the next
    joint (so those segments point exactly where the humanoid's do); joint 3 has no joint
    beyond it to aim at (neither SMPL-X nor the Mixamo rig has one) and turns with the
    humanoid's last segment relative to its middle one (:attr:`Follow.like_parent`), so the
    last joint's flexion is carried. The middle finger's first joint is also the point the
    wrist aims at (the hand site, as the project's importer pairs them): it sits there for
    the hand, while its own segment runs from the humanoid's knuckle (:attr:`Follow.origin`).
    """
    out: dict[str, Follow] = {}
    for side in ("left", "right"):
        for finger, segs in FINGER_SEGMENTS.items():
            names = [joint(side, finger, k) for k in (1, 2, 3)]
            bodies = [f"{side}_{finger}_{seg}" for seg in segs]
            if finger == "middle":    # the wrist's aim (see above)
                out[names[0]] = Follow(bodies[0], f"site:{side}_hand_site", aim=names[1],
                                       origin=f"body:{bodies[0]}")
            else:
                out[names[0]] = Follow(bodies[0], f"body:{bodies[0]}", aim=names[1])
            out[names[1]] = Follow(bodies[1], f"body:{bodies[1]}", aim=names[2])
            out[names[2]] = Follow(bodies[2], f"body:{bodies[2]}", like_parent=True)
    return out


@dataclass(frozen=True)
class TargetSkeleton:
    """A target skeleton in target axes (X left, Y up, Z forward), metres.

    Attributes:
        names: joint names, parents before children.
        parents: (J,) parent index, -1 for the root (only index 0).
        offsets: (J, 3) rest offset of each joint from its parent (the root's: its rest
            position).
        frame_joints: names of (pelvis, neck, left shoulder, right shoulder): the rest body frame
            (up = pelvis -> neck, left = right -> left shoulder), as the project's retargeter
            builds it (:mod:`gesture_sim.motion.retarget`).
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    frame_joints: tuple[str, str, str, str]

    def rest_positions(self) -> np.ndarray:
        """(J, 3) joint positions at the rest pose."""
        pos = np.zeros((len(self.names), 3))
        for j, p in enumerate(self.parents):
            pos[j] = self.offsets[j] + (pos[p] if p >= 0 else 0.0)
        return pos

    def index(self, name: str) -> int:
        """Index of joint ``name``."""
        return self.names.index(name)


def frame(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) with columns: the primary direction, the secondary made
    orthogonal to it, and their cross product."""
    e1 = primary / np.linalg.norm(primary, axis=-1, keepdims=True)
    s = secondary - e1 * np.sum(secondary * e1, axis=-1, keepdims=True)
    norm = np.linalg.norm(s, axis=-1, keepdims=True)
    if np.any(norm < 1e-6):
        raise GestureSimError("roll reference parallel to the bone: choose another roll axis")
    e2 = s / norm
    return np.stack([e1, e2, np.cross(e1, e2)], axis=-1)


def body_frame(up: np.ndarray, left: np.ndarray) -> np.ndarray:
    """Columns forward, left, up from an up and a left vector (up kept exactly), as the
    retargeter's ``_frame_from`` builds a body frame."""
    z = up / np.linalg.norm(up)
    y = left - z * (left @ z)
    y = y / np.linalg.norm(y)
    return np.stack([np.cross(y, z), y, z], axis=-1)


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(F, 3, 3) smallest rotations taking unit vectors a (F, 3) onto unit vectors b (F, 3)."""
    cross = np.cross(a, b)
    s = np.linalg.norm(cross, axis=-1)
    c = np.sum(a * b, axis=-1)
    angle = np.arctan2(s, c)
    axis = np.where(s[:, None] > 1e-12, cross / np.maximum(s, 1e-12)[:, None], 0.0)
    return Rotation.from_rotvec(axis * angle[:, None]).as_matrix()


class PoseTransfer:
    """Maps humanoid qpos rows onto a :class:`TargetSkeleton` (see the module docstring).

    Args:
        model: the humanoid ``mujoco.MjModel`` the qpos rows belong to (the body alone or the
            scene with it: bodies are found by name).
        skeleton: the target skeleton.
        follow: target joint name -> :class:`Follow`; a joint missing from it follows its parent
            (identity local rotation). The root must have a body and a point.
    """

    def __init__(self, model: mujoco.MjModel, skeleton: TargetSkeleton,
                 follow: dict[str, Follow]) -> None:
        unknown = sorted(set(follow) - set(skeleton.names))
        if unknown:
            raise GestureSimError(f"joint map names joints the skeleton lacks: {unknown}")
        self.model = model
        self.skeleton = skeleton
        self.follow = [follow.get(n, Follow()) for n in skeleton.names]
        root = self.follow[0]
        if root.body is None or root.at is None or skeleton.parents[0] != -1:
            raise GestureSimError("the target's root joint needs a driving body and a point")
        free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        if len(free) != 1:
            raise GestureSimError(f"expected one free root joint, found {len(free)}")
        self.root_qadr = int(model.jnt_qposadr[free[0]])
        self._rest()
        self._index()

    # ----------------------------------------------------------------------------- rest pose
    def _body(self, name: str) -> int:
        i = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
        if i < 0:
            raise GestureSimError(f"humanoid model has no body {name!r}")
        return int(i)

    def _point(self, spec: Point, data: mujoco.MjData) -> np.ndarray:
        if isinstance(spec, tuple) and spec and spec[0] == "lerp":
            _, a, b, f = spec
            pa, pb = self._point(a, data), self._point(b, data)
            return pa + float(f) * (pb - pa)
        if isinstance(spec, tuple) and spec and spec[0] == "chain":
            _, points, f = spec
            pts = np.array([self._point(q, data) for q in points])
            seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            s = float(f) * seg.sum()
            k = int(np.clip(np.searchsorted(np.cumsum(seg), s), 0, len(seg) - 1))
            u = (s - (np.cumsum(seg)[k] - seg[k])) / max(seg[k], 1e-12)
            return pts[k] + u * (pts[k + 1] - pts[k])
        if isinstance(spec, tuple):
            raise GestureSimError(f"unknown humanoid point {spec!r}")
        kind, _, name = spec.partition(":")
        if kind == "body":
            return data.xpos[self._body(name)].copy()
        if kind == "site":
            i = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, name)
            if i < 0:
                raise GestureSimError(f"humanoid model has no site {name!r}")
            return data.site_xpos[i].copy()
        raise GestureSimError(f"unknown humanoid point {spec!r}")

    def _rest(self) -> None:
        """Rest frames, anchor offsets and calibrations at the humanoid's qpos = 0."""
        m, sk = self.model, self.skeleton
        data = mujoco.MjData(m)
        data.qpos[:] = 0.0
        data.qpos[self.root_qadr + 3] = 1.0
        mujoco.mj_kinematics(m, data)
        n = len(sk.names)
        rest = sk.rest_positions()
        # the body whose frame carries each joint's point: its own, else the nearest ancestor's
        carrier: list[int | None] = []
        for j, f in enumerate(self.follow):
            carrier.append(self._body(f.body) if f.body is not None else
                           (carrier[sk.parents[j]] if sk.parents[j] >= 0 else None))
        self.bodies = sorted({b for b in carrier if b is not None})
        self.carrier = carrier
        self.anchor: dict[int, tuple[int, np.ndarray]] = {}   # joint -> (body, offset in body)
        self.origin: dict[int, tuple[int, np.ndarray]] = {}   # the same for Follow.origin
        world0: dict[int, np.ndarray] = {}
        origin0: dict[int, np.ndarray] = {}                  # where aimed bones start
        for j, f in enumerate(self.follow):
            if f.at is None:
                continue
            b = carrier[j]
            if f.origin is not None:
                b = carrier[sk.parents[j]] if sk.parents[j] >= 0 else None
                ob = carrier[j]
                q = self._point(f.origin, data)
                origin0[j] = q
                self.origin[j] = (ob, data.xmat[ob].reshape(3, 3).T @ (q - data.xpos[ob]))
            if b is None:
                raise GestureSimError(f"joint {sk.names[j]!r} has a point but no driving body")
            p = self._point(f.at, data)
            world0[j] = p
            origin0.setdefault(j, p)
            self.anchor[j] = (b, data.xmat[b].reshape(3, 3).T @ (p - data.xpos[b]))
        pelvis, neck, l_sh, r_sh = (sk.index(x) for x in sk.frame_joints)
        target_body = body_frame(rest[neck] - rest[pelvis], rest[l_sh] - rest[r_sh])
        self.calib = np.tile(np.eye(3), (n, 1, 1))       # H_j T_j^T, body-local -> target rest
        self.aim_rest = np.zeros((n, 3))                 # T_j e1: target rest bone direction
        self.aim_child = np.full(n, -1)
        self.like_parent = np.zeros(n, dtype=bool)
        for j, f in enumerate(self.follow):
            if f.body is None:
                continue
            b = self._body(f.body)
            rb = data.xmat[b].reshape(3, 3)
            if f.like_parent:
                p = sk.parents[j]
                if p < 0 or self.follow[p].body is None or f.aim is not None:
                    raise GestureSimError(f"joint {sk.names[j]!r} turns like its parent: it "
                                          "needs a parent with a driving body and no aim")
                # the parent's calibration, made relative to the two bodies' rest rotations
                pb = data.xmat[self._body(self.follow[p].body)].reshape(3, 3)
                self.calib[j] = rb.T @ pb @ self.calib[p]
                self.like_parent[j] = True
                continue
            if f.aim is None:
                h = rb.T                                  # the humanoid's rest axes, body-local
                t = target_body
            else:
                c = sk.index(f.aim)
                if sk.parents[c] != j:
                    raise GestureSimError(f"{f.aim!r} is not a child of {sk.names[j]!r}")
                if j not in world0 or c not in world0:
                    raise GestureSimError(f"aimed bone {sk.names[j]} -> {f.aim} needs both "
                                          "humanoid points")
                hum_sec, tgt_sec = self._roll(f.roll, world0, rest)
                h = rb.T @ frame(world0[c] - origin0[j], hum_sec)
                t = frame(sk.offsets[c], tgt_sec)
                self.aim_child[j] = c
                self.aim_rest[j] = t[:, 0]
            self.calib[j] = h @ t.T

    def _roll(self, roll, world0: dict[int, np.ndarray], rest: np.ndarray):
        if isinstance(roll, str):
            if roll not in _AXES:
                raise GestureSimError(f"unknown roll reference {roll!r}")
            return _AXES[roll]
        a, b = (self.skeleton.index(x) for x in roll)
        if a not in world0 or b not in world0:
            raise GestureSimError(f"roll pair {roll} needs humanoid points for both joints")
        return world0[a] - world0[b], rest[a] - rest[b]

    def _index(self) -> None:
        """Index arrays for the vectorised :meth:`pose` (after :meth:`_rest`)."""
        sk = self.skeleton
        n = len(sk.names)
        body = np.array([self._body(f.body) if f.body is not None else -1
                         for f in self.follow], dtype=int)
        src = np.arange(n)       # the joint whose rotation each joint takes: itself, or the
        for j in range(n):       # nearest ancestor with a body (identity local rotation)
            if body[j] < 0:
                src[j] = src[sk.parents[j]]
        self._driven = np.flatnonzero(body >= 0)             # joints with a driving body
        self._driven_body = body[self._driven]
        self._source = src
        anchors = sorted(self.anchor)
        row = {j: i for i, j in enumerate(anchors)}
        origins = sorted(self.origin)
        from_row = row | {j: len(anchors) + i for i, j in enumerate(origins)}
        points = [self.anchor[j] for j in anchors] + [self.origin[j] for j in origins]
        self._anchor_body = np.array([b for b, _ in points], dtype=int)
        self._anchor_off = np.array([o for _, o in points]).reshape(-1, 3)
        aimed = np.flatnonzero(self.aim_child >= 0)
        self._aimed = aimed
        self._aim_from = np.array([from_row[int(j)] for j in aimed], dtype=int)
        self._aim_to = np.array([row[int(self.aim_child[j])] for j in aimed], dtype=int)
        in_driven = {int(j): i for i, j in enumerate(self._driven)}
        self._aimed_rows = np.array([in_driven[int(j)] for j in aimed], dtype=int)
        # joints turning like their parent take the swing of the aimed joint their parent
        # is or turns like (parents first): (row among the driven, index among the aimed)
        swing_of = {int(j): i for i, j in enumerate(aimed)}
        for j in np.flatnonzero(self.like_parent):
            p = int(sk.parents[j])
            if p in swing_of:
                swing_of[int(j)] = swing_of[p]
        like = [int(j) for j in np.flatnonzero(self.like_parent) if int(j) in swing_of]
        self._like_rows = np.array([in_driven[j] for j in like], dtype=int)
        self._like_swing = np.array([swing_of[j] for j in like], dtype=int)
        self._root_row = row[0]
        self._data: mujoco.MjData | None = None

    # ----------------------------------------------------------------------------- motion
    def pose(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Map qpos rows (F, nq) onto the target.

        Vectorised over joints: a joint's global rotation depends on its driving body and its
        aimed points only (the swing), never on its parent's, so every joint is computed at
        once; a joint without a body takes its nearest driven ancestor's. ~0.3 ms for one
        frame of the Mixamo rig plus MuJoCo's kinematics per frame (the live streams call it
        once per stream frame: :mod:`gesture_sim.export.vmc`). The transfer keeps one
        ``MjData`` for the kinematics: call it from one thread at a time.

        Returns:
            local (F, J, 3, 3) rotations relative to the parent (the root's: global), global
            (F, J, 3, 3) rotations, and root (F, 3): the humanoid point of the root joint in
            target axes (m, unscaled).
        """
        m = self.model
        qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
        if qpos.ndim != 2 or qpos.shape[1] != m.nq or len(qpos) == 0:
            raise GestureSimError(f"expected qpos frames (F, {m.nq}), got {qpos.shape}")
        if not np.all(np.isfinite(qpos)):
            raise GestureSimError("qpos frames hold non-finite values")
        n_f, sk = len(qpos), self.skeleton
        if self._data is None:
            self._data = mujoco.MjData(m)
        data = self._data
        xmat = np.empty((n_f, m.nbody, 3, 3))
        xpos = np.empty((n_f, m.nbody, 3))
        for f in range(n_f):
            data.qpos[:] = qpos[f]
            mujoco.mj_kinematics(m, data)
            xmat[f] = data.xmat.reshape(-1, 3, 3)
            xpos[f] = data.xpos
        C = MJ_TO_TARGET
        ab = self._anchor_body                                   # the humanoid points (F, P, 3)
        point = (xpos[:, ab] + np.einsum("fnab,nb->fna", xmat[:, ab], self._anchor_off)) @ C.T
        g = C @ xmat[:, self._driven_body] @ self.calib[self._driven]        # (F, D, 3, 3)
        if len(self._aimed):
            r = self._aimed_rows
            want = point[:, self._aim_to] - point[:, self._aim_from]
            want /= np.maximum(np.linalg.norm(want, axis=-1, keepdims=True), 1e-12)
            ga = g[:, r]
            have = (ga @ self.aim_rest[self._aimed][:, :, None])[..., 0]
            swing = _swing(have.reshape(-1, 3), want.reshape(-1, 3)).reshape(n_f, len(r), 3, 3)
            g[:, r] = swing @ ga
            if len(self._like_rows):      # the parent's swing too: G_j = S_p C R_b calib_j
                g[:, self._like_rows] = swing[:, self._like_swing] @ g[:, self._like_rows]
        driven = np.empty((n_f, len(sk.names), 3, 3))
        driven[:, self._driven] = g
        glob = driven[:, self._source]
        local = glob.copy()
        local[:, 1:] = np.swapaxes(glob[:, sk.parents[1:]], -1, -2) @ glob[:, 1:]
        return local, glob, point[:, self._root_row]


def forward_positions(skeleton: TargetSkeleton, glob: np.ndarray,
                      root: np.ndarray) -> np.ndarray:
    """(F, J, 3) joint positions of the target posed with global rotations (F, J, 3, 3), its
    root at ``root`` (F, 3)."""
    n_f, n_j = glob.shape[:2]
    out = np.empty((n_f, n_j, 3))
    for j, p in enumerate(skeleton.parents):
        out[:, j] = root if p < 0 else out[:, p] + glob[:, p] @ skeleton.offsets[j]
    return out


def bvh_hierarchy(parents, head) -> list[str]:
    """The ``HIERARCHY`` block of a BVH: for joint j (in file order, ``parents[j] < j``; -1 the
    root) the lines ``head(j)`` — first the ``ROOT name`` / ``JOINT name`` / ``End Site``
    header, then what goes inside its braces (``OFFSET ...``, ``CHANNELS ...``, nested blocks),
    unindented — indented two spaces per depth, its children nested inside, braces closed."""
    lines = ["HIERARCHY"]
    depth = np.zeros(len(parents), dtype=int)
    open_depths: list[int] = []

    def close_to(d: int) -> None:
        while open_depths and open_depths[-1] >= d:
            lines.append("  " * open_depths.pop() + "}")

    for j, p in enumerate(parents):
        depth[j] = 0 if p < 0 else depth[p] + 1
        close_to(int(depth[j]))
        pad = "  " * int(depth[j])
        first, *inside = head(j)
        lines += [pad + first, pad + "{", *(pad + "  " + x for x in inside)]
        open_depths.append(int(depth[j]))
    close_to(0)
    return lines
