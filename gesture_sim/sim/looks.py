"""How the humanoid looks: the capsule mannequin or a skinned human. Visual only.

A look changes what is drawn, never the physics: the bodies, joints, geoms (sizes, positions,
contacts, masses), actuators and options are those of ``humanoid.xml`` in every look, so a
simulation gives the same numbers whichever look the model was compiled with
(``tests/sim/test_skin.py`` compares every physics array and a simulation run).

- ``"mannequin"``: ``humanoid.xml`` as it is (capsules and ellipsoids in shirt, trousers and skin
  colours, ellipsoid eyes, lids and brows).
- ``"human"``: MuJoCo skins built from MakeHuman's CC0 base mesh and rig by
  ``tools/build_skin.py`` (the files ``assets/mjcf/human/<body>/*.skn``, two body shapes:
  :data:`HUMAN_BODIES`), bound to the humanoid's bodies at qpos = 0 and deformed by linear blend
  skinning as the bodies move: the lower lip and tongue follow ``jaw``, the brows the brow
  bodies, the upper lids the eyelid bodies, so the face signals (jaw, brows, blinks) show. The
  humanoid's own geoms (colliders and mannequin parts) move to geom group :data:`HIDDEN_GROUP`,
  which MuJoCo's renderer and viewer do not draw by default (groups 0-2 are drawn); the viewer's
  group-3 toggle still shows the colliders. Skins use the humanoid's materials by name
  (``shirt``, ``trousers``, ``hair``, ``skin`` ...), so recolouring a material recolours the
  look (the conversation scene does so for person 1), and person k of a scene wears body
  ``HUMAN_BODIES[k % 2]`` with its skin tone (:data:`HUMAN_TONES`): two people are not twins.
  The upper lids rest open (:data:`LID_REST_OPEN_RAD`): MakeHuman's base mesh has them over
  about 45 % of the iris's height, which reads as tired, so when a skin is loaded its upper-lid
  vertices are turned up about the eyeball's centre (:func:`open_lid_rest`), leaving the iris's
  top covered (about a quarter of it); blinks (the eyelid bodies' slide, which still closes
  the eye fully) and gaze (the eye bodies) are unchanged. The shipped ``.skn`` files keep
  MakeHuman's lids; the opening is applied at load time.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gesture_sim import MJCF_DIR
from gesture_sim.errors import GestureSimError

if TYPE_CHECKING:   # the command line reads LOOKS without importing MuJoCo
    import mujoco

#: The looks there are.
LOOKS: tuple[str, ...] = ("mannequin", "human")
#: The look of a model compiled without saying which.
DEFAULT_LOOK = "human"
#: Geom group of the colliders in the human look (not drawn by default: groups 0-2 are).
HIDDEN_GROUP = 3
#: Folder of the human look's skins: one sub-folder per body (:data:`HUMAN_BODIES`).
HUMAN_DIR = MJCF_DIR / "human"
#: The human bodies (two MakeHuman shapes, ``tools/build_skin.py``): person k of a conversation
#: wears ``HUMAN_BODIES[k % 2]``, a single person the first.
HUMAN_BODIES: tuple[str, ...] = ("a", "b")
#: The human look's skins (``HUMAN_DIR / body / f"{name}.skn"``) and the material of each.
HUMAN_SKINS: tuple[tuple[str, str], ...] = (
    ("skin", "skin"), ("shirt", "shirt"), ("trousers", "trousers"), ("shoes", "shoe"),
    ("hair", "hair"), ("brows", "brow"), ("lips", "lips"), ("eyes", "eye_white"),
    ("irises", "iris"), ("teeth", "teeth"), ("mouth", "mouth_inside"),
)
#: Materials the human look adds (name -> rgba) where the humanoid has none of that name.
HUMAN_MATERIALS: dict[str, tuple[float, float, float, float]] = {
    "lips": (0.70, 0.42, 0.40, 1.0),
    "iris": (0.22, 0.15, 0.10, 1.0),
    "teeth": (0.92, 0.90, 0.84, 1.0),
}


#: Material colours (name -> rgba) per body where they differ from the defaults: skin tones.
HUMAN_TONES: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "b": {"skin": (0.62, 0.45, 0.34, 1.0), "lips": (0.50, 0.32, 0.30, 1.0)},
}

#: Upward turn (rad) of the upper lids' rest about each eyeball's centre, per unit of a vertex's
#: weight on the eyelid body (:func:`open_lid_rest`), per human body; 0 keeps MakeHuman's lids.
#: Each is about the most that a full blink (the eyelid's 14 mm slide) still closes over the
#: whole eye on that body (``tests/sim/test_eyes_awake.py``): the lid then rests ~4 mm below
#: the (17 mm) iris's top instead of ~7.5 mm, the aperture 10.5 mm instead of 7-7.5 mm.
LID_REST_OPEN_RAD: dict[str, float] = {"a": 0.40, "b": 0.30}
#: The skin bones (bodies) of the upper lids, and of the eyeballs (their centres: the pivot).
LID_BONES: tuple[str, ...] = ("left_eyelid", "right_eyelid")
EYE_BONES: tuple[str, ...] = ("left_eye", "right_eye")


def read_skn(path: str | Path) -> dict:
    """A MuJoCo ``.skn`` skin file as arrays: ``vert`` (V, 3) m, ``face`` (F, 3) int,
    ``texcoord`` (T, 2) and ``bones``: list of (body name, bindpos (3,), bindquat (4,),
    vertex ids (n,) int, weights (n,))."""
    b = Path(path).read_bytes()
    nv, nt, nf, nb = struct.unpack_from("<4i", b, 0)
    off = 16
    vert = np.frombuffer(b, "<f4", 3 * nv, off).reshape(nv, 3).astype(float)
    off += 12 * nv
    tex = np.frombuffer(b, "<f4", 2 * nt, off).reshape(nt, 2).astype(float)
    off += 8 * nt
    face = np.frombuffer(b, "<i4", 3 * nf, off).reshape(nf, 3).astype(int)
    off += 12 * nf
    bones = []
    for _ in range(nb):
        name = b[off: off + 40].split(b"\0")[0].decode()
        bind = np.frombuffer(b, "<f4", 7, off + 40).astype(float)
        (count,) = struct.unpack_from("<i", b, off + 68)
        off += 72
        ids = np.frombuffer(b, "<i4", count, off).astype(int)
        w = np.frombuffer(b, "<f4", count, off + 4 * count).astype(float)
        off += 8 * count
        bones.append((name, bind[:3], bind[3:], ids, w))
    if off != len(b):
        raise GestureSimError(f"human look: malformed skin file {path}")
    return {"vert": vert, "texcoord": tex, "face": face, "bones": bones}


def open_lid_rest(skn: dict, angle: float) -> np.ndarray:
    """The rest vertices (V, 3) m of skin ``skn`` (:func:`read_skn`) with the upper lids opened:
    each vertex turned up, about the lateral axis through its eyeball's centre (the eye body's
    bind position, the gaze's pivot), by ``angle`` (rad; :data:`LID_REST_OPEN_RAD` in the look)
    times its weight on the eyelid body, so the lid slides up over the eyeball as a lid does
    and the skin it blends into follows by its weight."""
    vert = skn["vert"].copy()
    centres = {b[0]: b[1] for b in skn["bones"] if b[0] in EYE_BONES}
    for bone, _, _, ids, w in skn["bones"]:
        if bone not in LID_BONES:
            continue
        c = centres.get(bone.replace("eyelid", "eye"))
        if c is None:
            raise GestureSimError(f"human look: skin has {bone} but not its eye")
        a = angle * w                         # the body faces +x: up is a turn about -y
        r = vert[ids] - c
        x = np.cos(a) * r[:, 0] - np.sin(a) * r[:, 2]
        z = np.sin(a) * r[:, 0] + np.cos(a) * r[:, 2]
        vert[ids, 0], vert[ids, 2] = c[0] + x, c[2] + z
    return vert


def _add_skin(spec: mujoco.MjSpec, name: str, path: str, material: str,
              lid_open_rad: float) -> None:
    """Add the skin file ``path`` to ``spec``; one with upper-lid bones with the lids opened by
    ``lid_open_rad`` (:func:`open_lid_rest`), given as arrays rather than the file."""
    skn = read_skn(path)
    if lid_open_rad == 0 or not any(b[0] in LID_BONES for b in skn["bones"]):
        spec.add_skin(name=name, file=path, material=material)
        return
    vert = open_lid_rest(skn, lid_open_rad)
    bones = skn["bones"]
    spec.add_skin(name=name, material=material, vert=vert.ravel().tolist(),
                  face=skn["face"].ravel().tolist(),
                  texcoord=skn["texcoord"].ravel().tolist(),
                  bodyname=[b[0] for b in bones],
                  bindpos=np.concatenate([b[1] for b in bones]).tolist(),
                  bindquat=np.concatenate([b[2] for b in bones]).tolist(),
                  vertid=[b[3].tolist() for b in bones],
                  vertweight=[b[4].tolist() for b in bones])


def check_look(look: str) -> str:
    """``look`` if it is one of :data:`LOOKS`; else a :class:`GestureSimError`."""
    if look not in LOOKS:
        raise GestureSimError(f"unknown look {look!r}; choose one of {', '.join(LOOKS)}")
    return look


def human_skin_files(body: str = HUMAN_BODIES[0]) -> list[tuple[str, str]]:
    """(path, material) of each skin of the human look's ``body``; a :class:`GestureSimError`
    when the files are missing."""
    if body not in HUMAN_BODIES:
        raise GestureSimError(f"unknown human body {body!r}; choose one of "
                              f"{', '.join(HUMAN_BODIES)}")
    out = []
    for name, material in HUMAN_SKINS:
        path = HUMAN_DIR / body / f"{name}.skn"
        if not path.is_file():
            raise GestureSimError(f"human look: skin file not found: {path} "
                                  "(build it with tools/build_skin.py)")
        out.append((str(path), material))
    return out


def apply_look(spec: mujoco.MjSpec, look: str, person: int = 0) -> mujoco.MjSpec:
    """Dress the humanoid of ``spec`` in ``look`` (``person``: which of the people of a scene
    it is, so that two people are not twins); returns ``spec``.

    Apply it to a spec that holds one humanoid (``humanoid.xml`` or ``scene.xml``), before it is
    attached into a larger scene: the skins name their bodies without a prefix here, and
    :meth:`mujoco.MjSpec.attach` prefixes them with the rest. Only visual properties change:
    the humanoid's geoms go to :data:`HIDDEN_GROUP`, skins and materials are added.
    """
    check_look(look)
    if look == "mannequin":
        return spec
    root = spec.body("pelvis")
    if root is None:
        raise GestureSimError("no humanoid (body 'pelvis') in this model")
    import mujoco

    for geom in root.find_all(mujoco.mjtObj.mjOBJ_GEOM):
        geom.group = HIDDEN_GROUP
    for name, rgba in HUMAN_MATERIALS.items():
        if spec.material(name) is None:
            spec.add_material(name=name, rgba=list(rgba))
    body = HUMAN_BODIES[person % len(HUMAN_BODIES)]
    for (name, _), (path, material) in zip(HUMAN_SKINS, human_skin_files(body), strict=True):
        _add_skin(spec, f"human_{name}", path, material, LID_REST_OPEN_RAD.get(body, 0.0))
    for name, rgba in HUMAN_TONES.get(body, {}).items():
        spec.material(name).rgba = list(rgba)
    return spec
