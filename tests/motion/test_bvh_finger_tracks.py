"""BVH finger joints -> the humanoid's finger targets (known answers on written BVH files)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gesture_sim.motion.bvh import read_bvh
from gesture_sim.motion.finger_tracks import (
    FINGER_TRACKS,
    MESH_REST_DEG,
    bvh_finger_angles,
    bvh_finger_track,
    parse_finger_name,
)
from gesture_sim.sim.humanoid import FINGER_JOINTS

DATA = Path(__file__).resolve().parents[1] / "data" / "motion"
LONG = ("index", "middle", "ring", "little")
#: The humanoid's hand frame at qpos 0 as its header describes it (columns: fingers, radial
#: towards the thumb, palmar normal): fingers down, thumb forward, palm towards the thigh.
HUMANOID_HAND = {"left": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]]),
                 "right": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])}


@pytest.fixture(scope="module")
def model():
    from gesture_sim.sim.humanoid import load_model

    return load_model(scene=False)


# --- a tiny BVH writer -------------------------------------------------------------------------

class Skel:
    """Joints (name, parent, offset, rotation channel order); End Sites have order None."""

    def __init__(self) -> None:
        self.joints: list[tuple[str, int, np.ndarray, str | None]] = []

    def add(self, name: str, parent: str | None, offset, order: str | None = "ZXY") -> str:
        p = -1 if parent is None else [j[0] for j in self.joints].index(parent)
        self.joints.append((name, p, np.asarray(offset, dtype=float), order))
        return name

    def rest(self, name: str) -> np.ndarray:
        names = [j[0] for j in self.joints]
        j, pos = names.index(name), np.zeros(3)
        while j >= 0:
            pos = pos + self.joints[j][2]
            j = self.joints[j][1]
        return pos

    def write(self, path: Path, frames: list[dict[str, np.ndarray]], root_pos=(0, 0, 0),
              fps: float = 30.0) -> None:
        lines = ["HIERARCHY"]
        emitted: list[int] = []    # the joints in file order (the MOTION columns' order)

        def emit(j: int, depth: int) -> None:
            emitted.append(j)
            name, parent, off, order = self.joints[j]
            pad = "  " * depth
            kids = [k for k, jj in enumerate(self.joints) if jj[1] == j]
            if order is None:
                lines.extend([f"{pad}End Site", f"{pad}{{",
                              f"{pad}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}", f"{pad}}}"])
                return
            chans = " ".join(f"{a}rotation" for a in order)
            head = "ROOT" if parent < 0 else "JOINT"
            lines.extend([f"{pad}{head} {name}", f"{pad}{{",
                          f"{pad}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}"])
            if parent < 0:
                lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition {chans}")
            else:
                lines.append(f"{pad}  CHANNELS 3 {chans}")
            for k in kids:
                emit(k, depth + 1)
            lines.append(f"{pad}}}")

        emit(0, 0)
        lines.extend(["MOTION", f"Frames: {len(frames)}", f"Frame Time: {1.0 / fps:.8f}"])
        for frame in frames:
            row = []
            for name, parent, _, order in (self.joints[j] for j in emitted):
                if order is None:
                    continue
                if parent < 0:
                    row.extend(np.asarray(frame.get("@root", root_pos), dtype=float).tolist())
                rot = frame.get(name, np.eye(3))
                row.extend(Rotation.from_matrix(rot).as_euler(order, degrees=True).tolist())
            lines.append(" ".join(f"{v:.6f}" for v in row))
        path.write_text("\n".join(lines) + "\n")


def _rot(axis: np.ndarray, deg: float) -> np.ndarray:
    return Rotation.from_rotvec(np.radians(deg) * np.asarray(axis) / np.linalg.norm(axis)
                                ).as_matrix()


class Hand:
    """A hand put into a BVH: its frame ``frame`` (columns: fingers, radial, palmar normal, in the
    file's axes), straight long fingers in the palm's plane (or the middle's PIP curled by
    ``curl``), the thumb the humanoid's own (its rest polyline taken into ``frame``)."""

    MCP = {"index": (9.0, 2.4), "middle": (9.4, 0.4), "ring": (9.0, -1.5), "little": (8.4, -3.3)}
    BONES = (4.2, 2.6, 2.0)

    def __init__(self, skel: Skel, model, side: str, wrist: str, frame: np.ndarray,
                 names: dict, scale: float, order: str, curl: float = 0.0) -> None:
        import mujoco

        self.side, self.frame, self.model, self.names = side, frame, model, names
        f, r, n = frame.T
        self.to_file = frame @ HUMANOID_HAND[side].T      # humanoid hand -> file axes
        self.axis: dict[str, np.ndarray] = {}
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        for digit in LONG:
            mcp = (self.MCP[digit][0] * f + self.MCP[digit][1] * r) * scale / 100.0
            parent = wrist
            if names.get("inhand"):
                parent = skel.add(names["inhand"].format(digit=digit), wrist, 0.3 * mcp, order)
                mcp = 0.7 * mcp
            d = f.copy()
            for k in range(len(self.BONES)):
                name = names["digit"].format(digit=digit, k=k + 1)
                offset = mcp if k == 0 else d * self.BONES[k - 1] * scale / 100.0
                if digit == "middle" and k == 2 and curl:
                    offset = _rot(np.cross(f, n), curl) @ offset  # the middle phalanx curled
                    d = offset / np.linalg.norm(offset)
                parent = skel.add(name, parent, offset, order)
                self.axis[f"{digit}{k + 1}"] = np.cross(d, n)   # flexion: perpendicular to
                #                                             the segment and the palm normal
            if names.get("tip"):
                parent = skel.add(names["tip"].format(digit=digit), parent,
                                  d * self.BONES[-1] * scale / 100.0, order)
            skel.add(parent + "_End", parent, d * 1.0 * scale / 100.0, None)
        # thumb: the humanoid's, in this hand's frame
        hand = data.xpos[model.body(f"{side}_hand").id]
        pts = [data.xpos[model.body(f"{side}_thumb_{b}").id] for b in
               ("metacarpal", "proximal", "distal")]
        pts.append(data.site_xpos[model.site(f"{side}_thumb_tip").id])
        pts = [self.to_file @ (p - hand) * scale for p in pts]
        parent = wrist
        for k in range(3):
            name = names["digit"].format(digit="Thumb", k=k + 1)
            parent = skel.add(name, parent, pts[k] - (pts[k - 1] if k else 0.0), order)
        skel.add(parent + "_End", parent, pts[3] - pts[2], None)
        for j in ("thumb_cmc_oppose", "thumb_cmc_flex", "thumb_mcp_flex", "thumb_ip_flex"):
            self.axis[j] = self.to_file @ model.jnt_axis[model.joint(f"{side}_{j}").id]

    def spread_axis(self, digit: str) -> np.ndarray:
        """The palm normal, signed so that a positive turn moves the finger away from the
        middle finger (the index towards the thumb)."""
        f, r, n = self.frame.T
        toward_thumb = np.cross(n, f) @ r > 0
        return n if toward_thumb == (digit in ("index", "middle")) else -n

    def joint(self, digit: str, k: int) -> str:
        if digit == "thumb":
            return self.names["digit"].format(digit="Thumb", k=k)
        return self.names["digit"].format(digit=digit, k=k)


def _poses(hands: dict[str, Hand]) -> tuple[list[dict], list[dict]]:
    """Frames (joint -> local rotation) and their expected humanoid angles (deg from straight):
    rest; index MCP 60, middle 30 at all three, the thumb opposed 35 (left) / index 50, little
    20 x 3 (right); then the index MCP flexed 40 after a 10 spread, ring PIP 45, thumb CMC
    flexion 20, MCP 20 and IP 30."""
    frames, expect = [{}], [{}]
    f1, e1, f2, e2 = {}, {}, {}, {}
    for side, h in hands.items():
        ax = h.axis
        if side == "left":
            f1[h.joint("index", 1)] = _rot(ax["index1"], 60)
            e1["left_index_mcp_flex"] = 60
            for k in (1, 2, 3):
                f1[h.joint("middle", k)] = _rot(ax[f"middle{k}"], 30)
                e1[f"left_middle_{('mcp', 'pip', 'dip')[k - 1]}_flex"] = 30
            f1[h.joint("thumb", 1)] = _rot(ax["thumb_cmc_oppose"], 35)
            e1["left_thumb_cmc_oppose"] = 35
        else:
            f1[h.joint("index", 1)] = _rot(ax["index1"], 50)
            e1["right_index_mcp_flex"] = 50
            for k in (1, 2, 3):
                f1[h.joint("little", k)] = _rot(ax[f"little{k}"], 20)
                e1[f"right_little_{('mcp', 'pip', 'dip')[k - 1]}_flex"] = 20
        f2[h.joint("index", 1)] = _rot(h.spread_axis("index"), 10) @ _rot(ax["index1"], 40)
        e2.update({f"{side}_index_spread": 10, f"{side}_index_mcp_flex": 40})
        f2[h.joint("ring", 2)] = _rot(ax["ring2"], 45)
        e2[f"{side}_ring_pip_flex"] = 45
        f2[h.joint("thumb", 1)] = _rot(ax["thumb_cmc_flex"], 20)
        f2[h.joint("thumb", 2)] = _rot(ax["thumb_mcp_flex"], 20)
        f2[h.joint("thumb", 3)] = _rot(ax["thumb_ip_flex"], 30)
        e2.update({f"{side}_thumb_cmc_flex": 20, f"{side}_thumb_mcp_flex": 20,
                   f"{side}_thumb_ip_flex": 30})
    frames += [f1, f2]
    expect += [e1, e2]
    return frames, expect


def _expected(expect: list[dict], curl: dict | None = None) -> np.ndarray:
    """(T, 40) deg: the expected angles from straight, plus the rest geometry's ``curl`` (and
    the thumb's, the humanoid's own rest thumb: :data:`MESH_REST_DEG`)."""
    curl = {**{f"{side}_thumb_{j}": MESH_REST_DEG[f"thumb_{j}"] for side in ("left", "right")
               for j in ("mcp_flex", "ip_flex")}, **(curl or {})}
    out = np.zeros((len(expect), len(FINGER_JOINTS)))
    for t, e in enumerate(expect):
        for j, v in e.items():
            out[t, FINGER_JOINTS.index(j)] = v
        for j, v in (curl or {}).items():
            out[t, FINGER_JOINTS.index(j)] += v
    return out


class _CapFormat(str):
    """A joint-name pattern whose ``{digit}`` is written the Mixamo way (``Index``, ``Pinky``)."""

    def format(self, *args, **kw):
        d = kw.get("digit")
        if d is not None:
            kw["digit"] = "Pinky" if d == "little" else d.capitalize()
        return str.format(self, *args, **kw)


def _mixamo_body(model) -> tuple[Skel, dict[str, Hand]]:
    """A Mixamo-named full body, Y up, facing +z, T-pose, centimetres."""
    s = Skel()
    p = "mixamorig:"
    s.add(p + "Hips", None, (0, 100, 0))
    s.add(p + "Spine", p + "Hips", (0, 10, 0))
    s.add(p + "Spine1", p + "Spine", (0, 10, 0))
    s.add(p + "Spine2", p + "Spine1", (0, 10, 0))
    s.add(p + "Neck", p + "Spine2", (0, 15, 0))
    s.add(p + "Head", p + "Neck", (0, 10, 0))
    s.add(p + "Head_End", p + "Head", (0, 18, 0), None)
    hands = {}
    for side, sx in (("Left", 1.0), ("Right", -1.0)):
        s.add(f"{p}{side}Shoulder", p + "Spine2", (sx * 5, 10, 0))
        s.add(f"{p}{side}Arm", f"{p}{side}Shoulder", (sx * 12, 0, 0))
        s.add(f"{p}{side}ForeArm", f"{p}{side}Arm", (sx * 28, 0, 0))
        s.add(f"{p}{side}Hand", f"{p}{side}ForeArm", (sx * 25, 0, 0))
        frame = np.array([[sx, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=float).T  # f r n columns
        names = {"digit": _CapFormat(p + side + "Hand{digit}{k}"),
                 "tip": _CapFormat(p + side + "Hand{digit}4")}
        hands[side.lower()] = Hand(s, model, side.lower(), f"{p}{side}Hand", frame, names,
                                   100.0, "ZXY")
        s.add(f"{p}{side}UpLeg", p + "Hips", (sx * 9, -5, 0))
        s.add(f"{p}{side}Leg", f"{p}{side}UpLeg", (0, -42, 0))
        s.add(f"{p}{side}Foot", f"{p}{side}Leg", (0, -42, 0))
        s.add(f"{p}{side}ToeBase", f"{p}{side}Foot", (0, -6, 12))
        s.add(f"{p}{side}ToeBase_End", f"{p}{side}ToeBase", (0, 0, 5), None)
    return s, hands


def _check(got: np.ndarray, want: np.ndarray, tol_long: float, tol_thumb: float) -> float:
    err = np.abs(np.degrees(got) - want)
    thumb = np.array(["thumb" in j for j in FINGER_JOINTS])
    assert err[:, ~thumb].max() < tol_long, (err[:, ~thumb].max(), np.unravel_index(
        np.argmax(err[:, ~thumb]), err[:, ~thumb].shape))
    assert err[:, thumb].max() < tol_thumb, err[:, thumb].max()
    return float(err.max())


def test_finger_names_of_the_common_conventions() -> None:
    assert parse_finger_name("mixamorig:LeftHandIndex1") == ("left", "index", 1)
    assert parse_finger_name("mixamorig:RightHandPinky3") == ("right", "little", 3)
    assert parse_finger_name("LeftHandThumb2") == ("left", "thumb", 2)
    assert parse_finger_name("LeftInHandMiddle") == ("left", "middle", 0)
    assert parse_finger_name("RightHandPinky") == ("right", "little", -1)
    assert parse_finger_name("LHandI2") == ("left", "index", 2)
    assert parse_finger_name("RHandR") == ("right", "ring", -1)
    assert parse_finger_name("RThumb") == ("right", "thumb", -1)
    assert parse_finger_name("ring_02_l") == ("left", "ring", 2)
    assert parse_finger_name("index_metacarpal_r") == ("right", "index", 0)
    for other in ("LeftHand", "LeftHandIndex3_End", "RightForeArm", "LeftFingerBase", "Ring"):
        assert parse_finger_name(other) is None


def test_mixamo_t_pose_y_up_known_angles(model, tmp_path) -> None:
    skel, hands = _mixamo_body(model)
    frames, expect = _poses(hands)
    path = tmp_path / "mixamo.bvh"
    skel.write(path, frames)
    motion = read_bvh(path)
    angles, have = bvh_finger_angles(motion, model)
    assert have.all()
    err = _check(angles, _expected(expect), 1.0, 3.0)
    print(f"mixamo: max angle error {err:.2f} deg")
    # the track: the angles less the mesh's rest, within the ranges; straight fingers of the
    # rest frame are straight (-rest), resampled to another rate on request
    track = bvh_finger_track(motion, model, 30.0, motion.n_frames)
    rest = np.radians([MESH_REST_DEG[j.split("_", 1)[1]] for j in FINGER_JOINTS])
    rng = np.array([model.jnt_range[model.joint(j).id] for j in FINGER_JOINTS])
    assert track.shape == (3, 40) and track.dtype == np.float32
    assert np.all(track >= rng[:, 0]) and np.all(track <= rng[:, 1])
    inside = (angles - rest > rng[:, 0] + 0.02) & (angles - rest < rng[:, 1] - 0.02)
    np.testing.assert_allclose(track[inside], (angles - rest)[inside], atol=1e-5)
    assert bvh_finger_track(path, model, 60.0, 5).shape == (5, 40)


def test_z_up_oblique_hands_with_metacarpals_known_angles(model, tmp_path) -> None:
    """ZEGGS / BEAT names with metacarpal joints (``LeftInHandIndex``, ``RightHandIndex``
    before ``RightHandIndex1``), Z up, hands in arbitrary
    orientations (not axis-aligned), XYZ channels, metres, the middle finger's PIP curled 15 deg
    at rest (so its angles from straight are 15 deg more there)."""
    s = Skel()
    s.add("Hips", None, (0, 0, 1.0), "XYZ")
    s.add("Spine", "Hips", (0, 0, 0.4), "XYZ")
    hands = {}
    turn = {"left": Rotation.from_euler("xyz", [25, -50, 70], degrees=True).as_matrix(),
            "right": Rotation.from_euler("xyz", [-40, 20, -110], degrees=True).as_matrix()}
    for side, sx in (("left", 1.0), ("right", -1.0)):
        cap = side.capitalize()
        s.add(f"{cap}Arm", "Spine", (0.2 * sx, 0, 0), "XYZ")
        s.add(f"{cap}Hand", f"{cap}Arm", (0.5 * sx, 0, -0.2), "XYZ")
        names = {"digit": _CapFormat(cap + "Hand{digit}{k}"),      # ZEGGS left, BEAT right
                 "inhand": _CapFormat(cap + ("InHand{digit}" if side == "left"
                                             else "Hand{digit}"))}
        hands[side] = Hand(s, model, side, f"{cap}Hand", turn[side] @ HUMANOID_HAND[side],
                           names, 1.0, "XYZ", curl=15.0)
    frames, expect = _poses(hands)
    # a metacarpal joint's turn counts in the MCP's flexion
    h = hands["left"]
    g = hands["right"]
    frames.append({"LeftInHandMiddle": _rot(h.axis["middle1"], 10),
                   h.joint("middle", 1): _rot(h.axis["middle1"], 20),
                   "RightHandRing": _rot(g.axis["ring1"], 15)})
    expect.append({"left_middle_mcp_flex": 30, "right_ring_mcp_flex": 15})
    path = tmp_path / "zup.bvh"
    s.write(path, frames)
    motion = read_bvh(path, unit_scale=1.0)
    angles, have = bvh_finger_angles(motion, model)
    assert have.all()
    curl = {f"{side}_middle_pip_flex": 15.0 for side in ("left", "right")}
    err = _check(angles, _expected(expect, curl), 1.0, 3.0)
    print(f"z-up: max angle error {err:.2f} deg")


def test_cmu_fingers_in_one_and_a_thumb(model, tmp_path) -> None:
    """CMU: ``LeftFingerBase`` (the palm: its turn is the wrist's, not the fingers') carries
    ``LeftHandIndex1``, all four fingers in one (their MCP flexion); ``LThumb`` hangs off the
    hand; the joints the skeleton lacks (PIP, DIP, spread) hold the relaxed hand."""
    from gesture_sim.motion.finger_tracks import relaxed_finger_q

    s = Skel()
    s.add("Hips", None, (0, 0.9, 0))
    s.add("LeftArm", "Hips", (0.2, 0.5, 0))
    s.add("LeftHand", "LeftArm", (0.5, 0, 0))
    s.add("LeftFingerBase", "LeftHand", (0, 0, 0))
    s.add("LeftHandIndex1", "LeftFingerBase", (0.06, 0, 0))
    s.add("LeftHandIndex1_End", "LeftHandIndex1", (0.05, 0, 0), None)
    s.add("LThumb", "LeftHand", (0, 0, 0))
    s.add("LThumb_End", "LThumb", (0.03, 0, 0.03), None)
    path = tmp_path / "cmu.bvh"
    flex_axis = np.array([0.0, 0.0, -1.0])        # fingers +x, palm down (-y): curl about -z
    s.write(path, [{}, {"LeftFingerBase": _rot(flex_axis, 30),
                        "LeftHandIndex1": _rot(flex_axis, 20)}])
    motion = read_bvh(path, unit_scale=1.0)
    angles, have = bvh_finger_angles(motion, model)
    for f in LONG:
        c = FINGER_JOINTS.index(f"left_{f}_mcp_flex")
        assert have[c] and np.degrees(angles[1, c]) == pytest.approx(20.0, abs=0.1)
    assert have[FINGER_JOINTS.index("left_thumb_cmc_oppose")]
    assert not have[FINGER_JOINTS.index("left_index_pip_flex")]
    track = bvh_finger_track(motion, model, 30.0, 2)
    assert np.allclose(track[:, ~have], relaxed_finger_q()[~have], atol=1e-6)


def test_a_skeleton_without_fingers_gives_none(model) -> None:
    motion = read_bvh(DATA / "dataset-1_bye_sad_001.bvh")
    assert bvh_finger_angles(motion, model) is None
    assert bvh_finger_track(motion, model, 30.0, motion.n_frames) is None


def test_finger_joints_that_never_move_give_none(model, tmp_path) -> None:
    skel, _ = _mixamo_body(model)
    path = tmp_path / "still.bvh"
    skel.write(path, [{}] * 3)
    assert bvh_finger_track(path, model, 30.0, 3) is None


def test_library_build_of_a_bvh_with_fingers_writes_finger_tracks(model, tmp_path,
                                                                   capsys) -> None:
    from gesture_sim.cli import main
    from gesture_sim.motion.finger_tracks import load_finger_tracks
    from gesture_sim.motion.library import MotionLibrary

    skel, hands = _mixamo_body(model)
    n = 24
    frames = []
    for t in range(n):
        w = 0.5 - 0.5 * np.cos(2 * np.pi * t / n)
        fr = {"mixamorig:LeftArm": _rot((0, 0, 1), -60 + 40 * w),
              "mixamorig:RightArm": _rot((0, 0, 1), 60 - 40 * w),
              "mixamorig:LeftForeArm": _rot((0, 1, 0), 50 * w)}
        h = hands["left"]
        for k in (1, 2, 3):
            fr[h.joint("index", k)] = _rot(h.axis[f"index{k}"], 70 * w)
        frames.append(fr)
    path = tmp_path / "fingers_take.bvh"
    skel.write(path, frames)
    out = tmp_path / "lib"
    assert main(["library", "build", str(path), "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["finger_tracks"] == ["fingers_take"]
    assert (out / FINGER_TRACKS).is_file()
    lib = MotionLibrary.load(out)
    tracks = load_finger_tracks(out, lib)
    track = np.degrees(tracks[0])
    assert track.shape == (lib.clips[0].n_frames, 40)
    c = FINGER_JOINTS.index("left_index_pip_flex")
    peak = int(np.argmax(track[:, c]))
    assert track[peak, c] == pytest.approx(70 - MESH_REST_DEG["index_pip_flex"], abs=3)
    lo, hi = np.degrees(model.jnt_range[model.joint("left_index_pip_flex").id])
    straight = max(-MESH_REST_DEG["index_pip_flex"], lo + 0.01 * (hi - lo))  # within the range
    assert track[0, c] == pytest.approx(straight, abs=0.5)             # straight at the start
