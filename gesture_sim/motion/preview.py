"""Contact sheets of library poses rendered on the humanoid (headless: ``MUJOCO_GL=egl``)."""

from __future__ import annotations

import os

import numpy as np

from gesture_sim.errors import GestureSimError


def _scene_model():
    """The humanoid scene (floor, lights) for rendering; the body-only model as a fallback."""
    try:
        from gesture_sim.sim import humanoid as hm

        return hm.load_model(scene=True)
    except (ImportError, AttributeError):
        from gesture_sim.motion.retarget import load_humanoid

        return load_humanoid()[0]


def render_poses(
    poses: list[tuple[np.ndarray, np.ndarray, np.ndarray]], joint_names: tuple[str, ...],
    model=None, width: int = 240, height: int = 320, azimuth: float = 160.0,
    elevation: float = -8.0, distance: float = 3.4,
) -> list[np.ndarray]:
    """Render humanoid poses, one image each.

    Args:
        poses: ``(qpos (n_joints,), root_pos (3,), root_quat (4,) w-x-y-z)`` per image.
        joint_names: the names of the qpos columns.
        model: a scene ``mujoco.MjModel``; the humanoid scene when ``None``.
        width, height: image size (px).
        azimuth, elevation, distance: free camera around the pelvis (deg, deg, m); azimuth 180
            looks at the humanoid's front.

    Returns:
        (height, width, 3) uint8 images.
    """
    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco

    model = model or _scene_model()
    data = mujoco.MjData(model)
    root = next(j for j in range(model.njnt)
                if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE))
    radr = model.jnt_qposadr[root]
    qadr = []
    for name in joint_names:
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0:
            raise GestureSimError(f"the humanoid has no joint {name!r} used by the library")
        qadr.append(model.jnt_qposadr[j])
    qadr = np.array(qadr)
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # noqa: BLE001 - GL back-ends raise assorted types
        raise GestureSimError(f"cannot render offscreen (set MUJOCO_GL=egl?): {exc}") from exc
    cam = mujoco.MjvCamera()
    cam.azimuth, cam.elevation, cam.distance = azimuth, elevation, distance
    images = []
    try:
        for qpos, root_pos, root_quat in poses:
            data.qpos[:] = 0
            data.qpos[radr:radr + 3] = [0.0, 0.0, root_pos[2]]
            data.qpos[radr + 3:radr + 7] = root_quat
            data.qpos[qadr] = qpos
            mujoco.mj_forward(model, data)
            cam.lookat[:] = [0.0, 0.0, 1.0]
            renderer.update_scene(data, camera=cam)
            images.append(renderer.render().copy())
    finally:
        renderer.close()
    return images


def contact_sheet(images: list[np.ndarray], labels: list[str], columns: int = 8) -> np.ndarray:
    """Tile images (all the same size) into one sheet with a caption under each (uint8 RGB)."""
    from PIL import Image, ImageDraw

    if not images:
        raise GestureSimError("nothing to put on the contact sheet")
    h, w = images[0].shape[:2]
    cap = 28
    rows = int(np.ceil(len(images) / columns))
    sheet = Image.new("RGB", (columns * w, rows * (h + cap)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for k, (img, label) in enumerate(zip(images, labels, strict=True)):
        x, y = (k % columns) * w, (k // columns) * (h + cap)
        sheet.paste(Image.fromarray(img), (x, y))
        for i, line in enumerate(label.split("\n")[:2]):
            draw.text((x + 4, y + h + 2 + 12 * i), line[: w // 6], fill=(0, 0, 0))
    return np.asarray(sheet)
