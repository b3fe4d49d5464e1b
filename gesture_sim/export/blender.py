"""FBX and glTF (GLB) files of the skinned human and its motion, written through Blender's Python
module ``bpy`` (the optional extra ``gesture-sim[blender]``; this module imports without it and
:func:`require_bpy` says how to install it).

What a file holds (:func:`write_scene`):

* **One armature** whose bones are the humanoid's bodies that the human look's skins are bound
  to, with their ancestors (the world body excluded): the MuJoCo body tree restricted to them,
  each bone named as its body (``pelvis``, ``abdomen`` … ``right_toes``). A bone's head is its
  body's origin in the skins' bind pose (the humanoid at qpos = 0, standing with its arms
  hanging); its tail points at its main child body (the child with the largest subtree when
  there is one and it is at least 2 cm away), a leaf's tail continues the line from its parent
  body. The bone *moves rigidly with its body*: at every frame its world transform is the body's
  world transform times the body's bind transform's inverse times the bone's rest transform,
  so the skinning is exactly MuJoCo's linear blend skinning.
* **One mesh object per skin** (``human_skin``, ``human_shirt`` … ``human_mouth``), its vertices
  at the bind pose, a vertex group per bone with the skin's weights, parented to the armature
  with an Armature modifier, smooth shaded, with one material whose base colour is the skin's
  MuJoCo material rgba (or the skin's own rgba where it has no material), converted from the
  sRGB display values MuJoCo draws to the linear values Blender, FBX readers and glTF
  (``baseColorFactor``) expect. No textures (the skins have no texture coordinates).
* **glTF's skinning limit**: a glTF vertex carries at most 4 bone weights (the exporter keeps
  the 4 largest and renormalises them); a few of the skin's and shirt's vertices have 5, so
  they move up to ~0.2 mm off MuJoCo's skinning in a GLB. The FBX keeps every weight.
* **The animation**: one keyframe per qpos row (frames 0 … T-1 at ``fps``), every bone's
  location and rotation (quaternion) from MuJoCo forward kinematics (``mujoco.mj_kinematics``)
  of that row: the root translation, the joints, the face's slide joints (brows, lids) as
  bone translations. Linear interpolation between keys.

Axes and units. MuJoCo's world is Z up, the humanoid facing +X with its left towards +Y. In
Blender the character is placed in Blender's own convention, Z up and facing -Y (its left
towards +X): Blender = ``MJ_TO_BLENDER @`` MuJoCo, a rotation of -90 degrees about Z. The files
then hold what their formats expect, metres throughout:

* **glTF** (GLB): Y up, the character facing +Z with its left towards +X, metres, as the glTF
  spec says (the exporter's Y-up conversion is baked into the data).
* **FBX** (Blender's exporter, ``axis_up="Y"``, ``axis_forward="-Z"``): the file's global
  settings say Y up, front +Z, and metres (``UnitScaleFactor`` 100: a unit is 100 cm; node
  scales stay 1). As Blender always writes FBX, the vertices and rest bones are stored in the
  Z-up frame and the top nodes (the armature, the meshes) carry the conversion, a -90 degree
  rotation about X, so a reader that applies node transforms sees the character Y up, facing
  +Z, left +X (Unity's "Bake Axis Conversion" import option folds that rotation away).

Both re-import into Blender with the character standing where it stood (Z up, facing -Y);
:func:`read_back` does so for the checks.
"""

from __future__ import annotations

import contextlib
import io
import os
import tempfile
import time
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from gesture_sim.errors import GestureSimError

#: The one-line message for a missing ``bpy``.
BLENDER_EXTRA_HINT = ("FBX/glTF export needs Blender's Python module: "
                      "pip install 'gesture-sim[blender]' (bpy, about 370 MB download)")
#: The file formats :func:`write_scene` writes.
FORMATS: tuple[str, ...] = ("fbx", "glb")
#: MuJoCo world axes -> Blender world axes (``v_blender = MJ_TO_BLENDER @ v_mujoco``): MuJoCo's
#: forward +X becomes Blender's -Y, left +Y becomes +X, up +Z stays +Z (-90 degrees about Z).
MJ_TO_BLENDER = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
#: Name of the armature object (and its data) in the Blender scene and the files.
ARMATURE_NAME = "gesture_sim_human"
#: Shortest bone (m): Blender drops zero-length bones.
MIN_BONE_LENGTH = 0.03


def require_bpy() -> Any:
    """Import and return Blender's ``bpy`` module; a :class:`GestureSimError` with
    :data:`BLENDER_EXTRA_HINT` when it is not installed (or does not load)."""
    try:
        import bpy
    except ImportError as exc:
        raise GestureSimError(BLENDER_EXTRA_HINT) from exc
    return bpy


# ------------------------------------------------------------------------------ pure numpy part
@dataclass(frozen=True)
class Rig:
    """The armature derived from a compiled humanoid with skins, in Blender axes (metres).

    Attributes:
        bodies: (B,) MuJoCo body id of each bone, parents before children.
        names: (B,) bone names (the body names).
        parents: (B,) index of each bone's parent bone, -1 for the root.
        bind: (B, 4, 4) each body's world transform at the bind pose (Blender axes).
        heads: (B, 3) bone heads (= ``bind[:, :3, 3]``).
        tails: (B, 3) bone tails.
        roll_ref: (B, 3) the direction the bone's local Z axis is aligned to (its body's forward
            axis, or its up axis where the forward one is nearly along the bone).
    """

    bodies: np.ndarray
    names: tuple[str, ...]
    parents: np.ndarray
    bind: np.ndarray
    heads: np.ndarray
    tails: np.ndarray
    roll_ref: np.ndarray


def _transform(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """(..., 4, 4) homogeneous transforms from rotations (..., 3, 3) and positions (..., 3)."""
    out = np.zeros(rot.shape[:-2] + (4, 4))
    out[..., :3, :3] = rot
    out[..., :3, 3] = pos
    out[..., 3, 3] = 1.0
    return out


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices of unit quaternions (..., 4) (w, x, y, z)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def _matrix_quat(r: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) of rotation matrices (..., 3, 3)."""
    from scipy.spatial.transform import Rotation

    xyzw = Rotation.from_matrix(r.reshape(-1, 3, 3)).as_quat()
    return xyzw[:, [3, 0, 1, 2]].reshape(r.shape[:-2] + (4,))


def rig_from_model(model: mujoco.MjModel) -> Rig:
    """The armature of ``model``'s skins (see the module docstring); a :class:`GestureSimError`
    when the model has no skins or two skins bind one body at different poses."""
    if model.nskin == 0:
        raise GestureSimError("the model has no skins: compile it with look='human'")
    bind_pos: dict[int, np.ndarray] = {}
    bind_quat: dict[int, np.ndarray] = {}
    for s in range(model.nskin):
        a = int(model.skin_boneadr[s])
        for k in range(a, a + int(model.skin_bonenum[s])):
            b = int(model.skin_bonebodyid[k])
            p, q = model.skin_bonebindpos[k], model.skin_bonebindquat[k]
            if b in bind_pos and (np.abs(bind_pos[b] - p).max() > 1e-5
                                  or abs(abs(float(bind_quat[b] @ q)) - 1.0) > 1e-6):
                raise GestureSimError(f"skins bind body {model.body(b).name!r} at different poses")
            bind_pos[b], bind_quat[b] = np.array(p, float), np.array(q, float)
    # ancestors without a skin bone of their own: their pose at qpos0
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    keep = set(bind_pos)
    for b in list(keep):
        p = int(model.body_parentid[b])
        while p > 0:
            keep.add(p)
            p = int(model.body_parentid[p])
    bodies = np.array(sorted(keep), dtype=int)        # MuJoCo numbers parents before children
    index = {int(b): i for i, b in enumerate(bodies)}
    parents = np.array([index.get(int(model.body_parentid[b]), -1) for b in bodies])
    if np.sum(parents < 0) != 1:
        raise GestureSimError("the skins' bodies do not form one tree")
    rot = np.array([_quat_matrix(bind_quat[b]) if b in bind_quat
                    else data.xmat[b].reshape(3, 3) for b in bodies])
    pos = np.array([bind_pos[b] if b in bind_pos else data.xpos[b] for b in bodies])
    C = MJ_TO_BLENDER
    rot = C @ rot
    pos = pos @ C.T
    bind = _transform(rot, pos)
    n = len(bodies)
    children: list[list[int]] = [[] for _ in range(n)]
    for i, p in enumerate(parents):
        if p >= 0:
            children[p].append(i)
    size = np.ones(n, dtype=int)
    for i in range(n - 1, -1, -1):
        if parents[i] >= 0:
            size[parents[i]] += size[i]
    tails = np.empty((n, 3))
    roll = np.empty((n, 3))
    for i in range(n):
        head = pos[i]
        main = None
        if children[i]:
            best = max(size[c] for c in children[i])
            top = [c for c in children[i] if size[c] == best]
            if len(top) == 1 and np.linalg.norm(pos[top[0]] - head) >= 0.02:
                main = top[0]
        if main is not None:
            tails[i] = pos[main]
        else:
            p = parents[i]
            d = head - pos[p] if p >= 0 else rot[i][:, 2]
            norm = float(np.linalg.norm(d))
            if norm < 1e-6:
                d, norm = rot[i][:, 2], 1.0
            length = float(np.clip(0.5 * norm, MIN_BONE_LENGTH, 0.12)) if p >= 0 else 0.1
            tails[i] = head + d / norm * length
        axis = (tails[i] - head) / np.linalg.norm(tails[i] - head)
        fwd, up = rot[i][:, 0], rot[i][:, 2]
        roll[i] = fwd if abs(float(fwd @ axis)) < 0.9 else up
    names = tuple(model.body(int(b)).name for b in bodies)
    return Rig(bodies=bodies, names=names, parents=parents, bind=bind, heads=pos.copy(),
               tails=tails, roll_ref=roll)


def body_transforms(model: mujoco.MjModel, qpos: np.ndarray, bodies: np.ndarray) -> np.ndarray:
    """(T, B, 4, 4) world transforms of ``bodies`` (B,) in Blender axes for qpos rows (T, nq),
    by MuJoCo forward kinematics (positions m)."""
    data = mujoco.MjData(model)
    n_t = len(qpos)
    rot = np.empty((n_t, len(bodies), 3, 3))
    pos = np.empty((n_t, len(bodies), 3))
    for t in range(n_t):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        rot[t] = data.xmat[bodies].reshape(-1, 3, 3)
        pos[t] = data.xpos[bodies]
    C = MJ_TO_BLENDER
    return _transform(C @ rot, pos @ C.T)


def pose_basis(rig: Rig, rest_local: np.ndarray, world: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Blender pose channels of every bone and frame.

    Args:
        rig: the armature.
        rest_local: (B, 4, 4) each bone's rest matrix in armature space (Blender's
            ``bone.matrix_local``, read back after the bones are built: the roll is Blender's).
        world: (T, B, 4, 4) the bodies' world transforms (:func:`body_transforms`).

    Returns:
        location (T, B, 3) in m and rotation (T, B, 4) quaternions (w, x, y, z), each bone's
        ``matrix_basis`` relative to its rest and parent, quaternion signs continuous in time.
        With the armature object at the origin, bone b's world matrix is then
        ``world[t, b] @ inv(bind[b]) @ rest_local[b]``.
    """
    rel = world @ np.linalg.inv(rig.bind)              # (T, B, 4, 4) body motion from bind
    basis = np.empty_like(rel)
    root = rig.parents < 0
    basis[:, root] = rel[:, root]
    child = ~root
    par = rig.parents[child]
    basis[:, child] = np.linalg.inv(rel[:, par]) @ rel[:, child]
    basis = np.linalg.inv(rest_local) @ basis @ rest_local
    loc = basis[..., :3, 3]
    quat = _matrix_quat(basis[..., :3, :3])
    flip = np.sign(np.sum(quat[1:] * quat[:-1], axis=-1))
    flip[flip == 0] = 1.0
    quat[1:] *= np.cumprod(flip, axis=0)[..., None]
    return loc, quat


# ------------------------------------------------------------------------------ Blender part
@contextlib.contextmanager
def _quiet():
    """Keep what Blender's Python importers and exporters print (progress lines, glTF's log)
    off stdout; the messages Blender's C code prints still show."""
    with contextlib.redirect_stdout(io.StringIO()):
        yield


def _fresh_scene(bpy: Any) -> Any:
    """An empty scene (factory settings, no cube, camera or light)."""
    with _quiet():
        bpy.ops.wm.read_factory_settings(use_empty=True)
    for coll in (bpy.data.objects, bpy.data.meshes, bpy.data.materials, bpy.data.cameras,
                 bpy.data.lights, bpy.data.actions, bpy.data.armatures):
        for item in list(coll):
            coll.remove(item)
    return bpy.context.scene


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """Linear-light values of sRGB-encoded colour components (..., in [0, 1]): MuJoCo's rgba
    are display values, Blender's and glTF's base colours are linear."""
    c = np.clip(np.asarray(c, dtype=float), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _material(bpy: Any, name: str, rgba: np.ndarray) -> Any:
    """A material of MuJoCo colour ``rgba`` (4,) (sRGB display values; alpha kept)."""
    mat = bpy.data.materials.new(name)
    rgba = np.concatenate([srgb_to_linear(rgba[:3]), [float(rgba[3])]])
    mat.diffuse_color = [float(x) for x in rgba]
    tree = getattr(mat, "node_tree", None)
    if tree is None and hasattr(mat, "use_nodes"):     # Blender < 5: node trees are opt-in
        mat.use_nodes = True
        tree = mat.node_tree
    bsdf = tree.nodes.get("Principled BSDF") if tree is not None else None
    if bsdf is not None:
        bsdf.inputs["Base Color"].default_value = [float(x) for x in rgba[:3]] + [1.0]
        bsdf.inputs["Alpha"].default_value = float(rgba[3])
        bsdf.inputs["Roughness"].default_value = 0.6
    return mat


def _build_armature(bpy: Any, scene: Any, rig: Rig) -> tuple[Any, np.ndarray]:
    """The armature object and its bones' rest matrices (B, 4, 4) in armature space."""
    arm = bpy.data.armatures.new(ARMATURE_NAME)
    obj = bpy.data.objects.new(ARMATURE_NAME, arm)
    scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    edit = []
    for i, name in enumerate(rig.names):
        eb = arm.edit_bones.new(name)
        eb.head = [float(x) for x in rig.heads[i]]
        eb.tail = [float(x) for x in rig.tails[i]]
        eb.align_roll([float(x) for x in rig.roll_ref[i]])
        if rig.parents[i] >= 0:
            eb.parent = edit[rig.parents[i]]
        eb.use_connect = False
        eb.use_deform = True
        edit.append(eb)
    bpy.ops.object.mode_set(mode="OBJECT")
    rest = np.array([np.array(arm.bones[name].matrix_local) for name in rig.names])
    return obj, rest


def _build_meshes(bpy: Any, scene: Any, model: mujoco.MjModel, rig: Rig, arm_obj: Any) -> int:
    """One mesh object per skin (see the module docstring); returns the total vertex count."""
    total = 0
    for s in range(model.nskin):
        name = model.skin(s).name or f"skin{s}"
        va, nv = int(model.skin_vertadr[s]), int(model.skin_vertnum[s])
        fa, nf = int(model.skin_faceadr[s]), int(model.skin_facenum[s])
        verts = model.skin_vert[va:va + nv].astype(float) @ MJ_TO_BLENDER.T
        faces = model.skin_face[fa:fa + nf].astype(int)
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata(verts.tolist(), [], faces.tolist())
        mesh.polygons.foreach_set("use_smooth", [True] * nf)
        mesh.update()
        mat_id = int(model.skin_matid[s])
        rgba = model.mat_rgba[mat_id] if mat_id >= 0 else model.skin_rgba[s]
        mat_name = model.material(mat_id).name if mat_id >= 0 else name
        mesh.materials.append(_material(bpy, mat_name, np.asarray(rgba, float)))
        obj = bpy.data.objects.new(name, mesh)
        scene.collection.objects.link(obj)
        obj.parent = arm_obj
        mod = obj.modifiers.new("Armature", "ARMATURE")
        mod.object = arm_obj
        bone_of = {int(b): rig.names[i] for i, b in enumerate(rig.bodies)}
        a = int(model.skin_boneadr[s])
        for k in range(a, a + int(model.skin_bonenum[s])):
            vg = obj.vertex_groups.new(name=bone_of[int(model.skin_bonebodyid[k])])
            ba, bn = int(model.skin_bonevertadr[k]), int(model.skin_bonevertnum[k])
            ids = model.skin_bonevertid[ba:ba + bn]
            weights = model.skin_bonevertweight[ba:ba + bn]
            for v, w in zip(ids.tolist(), weights.tolist(), strict=True):
                vg.add([v], w, "REPLACE")
        total += nv
    return total


def _set_fps(scene: Any, fps: float) -> None:
    base = max(1, round(fps))
    scene.render.fps = int(base)
    scene.render.fps_base = base / fps


def _animate(bpy: Any, arm_obj: Any, rig: Rig, loc: np.ndarray, quat: np.ndarray) -> None:
    """Keyframes 0 … T-1 of every bone's location (T, B, 3) and rotation (T, B, 4), set in bulk
    (``keyframe_points.add`` + ``foreach_set``), linear interpolation."""
    n_t = len(loc)
    action = bpy.data.actions.new(f"{ARMATURE_NAME}_motion")
    arm_obj.animation_data_create()
    arm_obj.animation_data.action = action
    frames = np.arange(n_t, dtype=np.float32)
    linear = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items["LINEAR"].value
    for i, name in enumerate(rig.names):
        pb = arm_obj.pose.bones[name]
        pb.rotation_mode = "QUATERNION"
        for prop, values in (("location", loc[:, i]), ("rotation_quaternion", quat[:, i])):
            path = f'pose.bones["{name}"].{prop}'
            for axis in range(values.shape[1]):
                if hasattr(action, "fcurve_ensure_for_datablock"):      # Blender >= 4.4
                    fc = action.fcurve_ensure_for_datablock(arm_obj, path, index=axis,
                                                            group_name=name)
                else:
                    fc = action.fcurves.new(path, index=axis, action_group=name)
                kp = fc.keyframe_points
                kp.add(n_t)
                co = np.empty((n_t, 2), dtype=np.float32)
                co[:, 0] = frames
                co[:, 1] = values[:, axis]
                kp.foreach_set("co", co.ravel())
                kp.foreach_set("interpolation", [linear] * n_t)
                fc.update()


def build_scene(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> dict[str, Any]:
    """Build the armature, meshes, materials and animation of :func:`write_scene` in a fresh
    Blender scene (without writing a file). Returns ``{"armature": object, "rig": Rig,
    "frames": T, "vertices": total vertex count, "seconds": build time}``."""
    bpy = require_bpy()
    qpos = np.asarray(qpos, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(qpos) == 0:
        raise GestureSimError(f"expected qpos frames (T, {model.nq}), got {qpos.shape}")
    if not np.all(np.isfinite(qpos)):
        raise GestureSimError("qpos frames hold non-finite values")
    if not (np.isfinite(fps) and fps > 0):
        raise GestureSimError(f"frame rate must be positive, got {fps}")
    t0 = time.perf_counter()
    rig = rig_from_model(model)
    scene = _fresh_scene(bpy)
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 1.0
    _set_fps(scene, float(fps))
    scene.frame_start = 0
    scene.frame_end = len(qpos) - 1
    arm_obj, rest = _build_armature(bpy, scene, rig)
    n_vert = _build_meshes(bpy, scene, model, rig, arm_obj)
    loc, quat = pose_basis(rig, rest, body_transforms(model, qpos, rig.bodies))
    _animate(bpy, arm_obj, rig, loc, quat)
    scene.frame_set(0)
    return {"armature": arm_obj, "rig": rig, "frames": len(qpos), "vertices": n_vert,
            "seconds": time.perf_counter() - t0}


def _export(bpy: Any, path: str, fmt: str) -> None:
    """Run Blender's FBX or glTF exporter on the current scene, writing exactly ``path``."""
    try:
        _run_exporter(bpy, path, fmt)
    except RuntimeError as exc:        # what bpy.ops raises when an operator reports an error
        msg = " ".join(str(exc).split())
        raise GestureSimError(f"Blender's {fmt.upper()} exporter failed on {path}: {msg}") from exc


def _run_exporter(bpy: Any, path: str, fmt: str) -> None:
    if fmt == "fbx":
        with _quiet():
            result = bpy.ops.export_scene.fbx(
                filepath=path, check_existing=False, use_selection=False,
                object_types={"ARMATURE", "MESH"}, apply_unit_scale=True,
                apply_scale_options="FBX_SCALE_UNITS", bake_space_transform=False,
                axis_forward="-Z", axis_up="Y", mesh_smooth_type="FACE",
                add_leaf_bones=False, use_armature_deform_only=False, armature_nodetype="NULL",
                bake_anim=True, bake_anim_use_all_bones=True, bake_anim_use_nla_strips=False,
                bake_anim_use_all_actions=False, bake_anim_force_startend_keying=True,
                bake_anim_step=1.0, bake_anim_simplify_factor=0.0, path_mode="AUTO")
    else:
        # the glTF exporter appends ".glb" to a path without it: write a sibling, then rename
        if not path.lower().endswith(".glb"):
            from gesture_sim.fileio import owned_prefix

            fd, tmp = tempfile.mkstemp(suffix=".glb", prefix=owned_prefix(".tmp-gltf-"),
                                       dir=os.path.dirname(os.path.abspath(path)))
            os.close(fd)
            try:
                _export(bpy, tmp, fmt)
                os.replace(tmp, path)
            finally:
                if os.path.exists(tmp):
                    os.unlink(tmp)
            return
        with _quiet():
            result = bpy.ops.export_scene.gltf(
                filepath=path, check_existing=False, export_format="GLB", export_yup=True,
                export_apply=False, export_skins=True, export_animations=True,
                export_animation_mode="ACTIONS", export_force_sampling=True,
                export_frame_range=True, export_materials="EXPORT", export_cameras=False,
                export_lights=False)
    if "FINISHED" not in result:
        raise GestureSimError(f"Blender's {fmt.upper()} exporter failed on {path}")


def write_scene(path: str | os.PathLike[str], model: mujoco.MjModel, qpos: np.ndarray,
                fps: float, fmt: str) -> int:
    """Write the skinned human moving through qpos rows as an FBX or a binary glTF (GLB) file.

    Args:
        path: the file to write, exactly (no suffix is added; pass a temporary and rename).
        model: the humanoid compiled with its skins (``load_model(scene=False, look="human")``,
            or any model holding the humanoid with the human look).
        qpos: (T, nq) MuJoCo states (root position m, root quaternion w x y z, joints rad / m),
            one per frame.
        fps: frame rate of the rows (Hz); the file's frame rate.
        fmt: ``"fbx"`` or ``"glb"``.

    Returns:
        the number of frames written (T), keyed at frames 0 … T-1.

    Builds a fresh Blender scene (factory settings, nothing else in it) and exports it; see the
    module docstring for what the file holds and its axes (FBX and glTF: Y up, the character
    facing +Z, metres). Raises :class:`GestureSimError` for a missing ``bpy``, bad input or an
    exporter failure.
    """
    if fmt not in FORMATS:
        raise GestureSimError(f"unknown scene format {fmt!r}; choose one of {', '.join(FORMATS)}")
    bpy = require_bpy()
    built = build_scene(model, qpos, fps)
    _export(bpy, os.fspath(path), fmt)
    if not os.path.isfile(path) or os.path.getsize(path) == 0:
        raise GestureSimError(f"Blender's {fmt.upper()} exporter wrote nothing to {path}")
    return int(built["frames"])


# ------------------------------------------------------------------------------ reading back
#: The file formats :func:`read_back` imports (``bvh``: Blender's BVH importer, centimetres).
READ_FORMATS: tuple[str, ...] = ("fbx", "glb", "bvh")
#: The Blender frame of a BVH's first frame after :func:`read_back`.
BVH_FIRST_FRAME = 1


def read_back(path: str | os.PathLike[str], fmt: str, fps: float) -> Any:
    """Import ``path`` (``fmt`` in :data:`READ_FORMATS`) into a fresh Blender scene with
    Blender's own importer and return the armature object (the first one).

    FBX and glTF keys land on the frames they were written on (frame k = time k / fps): the FBX
    import without its default one-frame offset, glTF times converted at ``fps`` (Hz; glTF
    stores seconds, not a frame rate). A BVH's frames start at 1 (:data:`BVH_FIRST_FRAME`:
    Blender's BVH importer starts no earlier), so its frame k + 1 is time k / fps. A BVH is
    read as centimetres (``global_scale`` 0.01) with Y up and the character facing +Z (the
    project's BVH convention), so every format comes back in Blender's axes (Z up, facing -Y),
    metres.
    """
    bpy = require_bpy()
    if fmt not in READ_FORMATS:
        raise GestureSimError(f"unknown format {fmt!r}; choose one of {', '.join(READ_FORMATS)}")
    scene = _fresh_scene(bpy)
    _set_fps(scene, float(fps))
    path = os.fspath(path)
    with _quiet():
        if fmt == "fbx":
            result = bpy.ops.import_scene.fbx(filepath=path, anim_offset=0.0,
                                              automatic_bone_orientation=False)
        elif fmt == "glb":
            result = bpy.ops.import_scene.gltf(filepath=path, disable_bone_shape=True)
        else:
            result = bpy.ops.import_anim.bvh(filepath=path, global_scale=0.01,
                                             frame_start=BVH_FIRST_FRAME,
                                             use_fps_scale=False, update_scene_fps=False,
                                             update_scene_duration=True, rotate_mode="NATIVE",
                                             axis_forward="-Z", axis_up="Y")
    if "FINISHED" not in result:
        raise GestureSimError(f"Blender could not import {path}")
    arms = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
    if not arms:
        raise GestureSimError(f"{path}: no armature after import")
    return arms[0]


def bone_heads(arm_obj: Any, names: list[str] | tuple[str, ...],
               frames: list[int] | np.ndarray) -> np.ndarray:
    """(F, n, 3) world positions (m, Blender axes) of the heads of the pose bones ``names``
    (n,) of ``arm_obj`` at each of ``frames`` (F,)."""
    bpy = require_bpy()
    scene = bpy.context.scene
    missing = [n for n in names if n not in arm_obj.pose.bones]
    if missing:
        raise GestureSimError(f"armature {arm_obj.name!r} lacks bones {missing}")
    out = np.empty((len(frames), len(names), 3))
    for i, f in enumerate(frames):
        scene.frame_set(int(f))
        mw = np.array(arm_obj.matrix_world)
        for j, n in enumerate(names):
            out[i, j] = mw[:3, :3] @ np.array(arm_obj.pose.bones[n].head) + mw[:3, 3]
    return out


def body_positions(model: mujoco.MjModel, qpos: np.ndarray, names: list[str] | tuple[str, ...]
                   ) -> np.ndarray:
    """(T, n, 3) world positions (m, Blender axes: ``MJ_TO_BLENDER`` applied) of the MuJoCo
    bodies ``names`` for qpos rows (T, nq)."""
    ids = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) for n in names])
    if np.any(ids < 0):
        lacking = [n for n, i in zip(names, ids, strict=True) if i < 0]
        raise GestureSimError(f"model lacks bodies {lacking}")
    return body_transforms(model, np.atleast_2d(qpos), ids)[..., :3, 3]


def mujoco_skin_vertices(model: mujoco.MjModel, qpos: np.ndarray) -> list[np.ndarray]:
    """The skins' vertices as MuJoCo's renderer deforms them for one qpos row (nq,)
    (``mujoco.mjv_updateScene``): one (V_s, 3) array per skin, world positions in m, Blender
    axes (``MJ_TO_BLENDER`` applied). The reference a Blender-deformed mesh is checked against."""
    data = mujoco.MjData(model)
    data.qpos[:] = np.asarray(qpos, dtype=float)
    mujoco.mj_forward(model, data)
    scn = mujoco.MjvScene(model, maxgeom=max(1000, 4 * model.ngeom))
    mujoco.mjv_updateScene(model, data, mujoco.MjvOption(), mujoco.MjvPerturb(),
                           mujoco.MjvCamera(), mujoco.mjtCatBit.mjCAT_ALL, scn)
    vert = np.asarray(scn.skinvert, dtype=float).reshape(-1, 3)
    return [vert[int(a):int(a) + int(n)] @ MJ_TO_BLENDER.T
            for a, n in zip(scn.skinvertadr[:scn.nskin], scn.skinvertnum[:scn.nskin],
                            strict=True)]
