"""``gesture-sim export MOTION.npz --format … -o OUT`` (issue 32, item 6): a render's saved
motion written in every format without rendering again.

What is checked:

* **The same files as the writers** ``render`` uses: a motion npz (``motion_arrays``, the
  ``render --npz`` layout) of a shipped library clip, exported to smplx, bvh-mixamo, bvh and a
  user skeleton, is byte for byte what ``write_*_from_trace`` writes for the same trace over the
  same span, and reads back (:func:`gesture_sim.motion.bvh.read_bvh`, the SMPL-X reader) with
  ``ceil(span · fps)`` frames.
* **A real render** (slow): ``render --npz --bvh --mixamo --smplx --to-skeleton`` of 4 s of
  speech, then ``export`` of its npz: the same files (the BVHs byte for byte, the SMPL-X arrays
  equal), because the render's trace spans exactly the audio (rows 0 … 4.0 s) that its own
  exports cover; the joint positions read back are the same (measured: 120 frames each, 0 mm).
* **Errors** are one line and exit status 2 before any work: a missing, non-npz or foreign
  input, an unknown format, ``skeleton`` without ``--to-skeleton``, ``--to-skeleton`` with
  another format, the output equal to the input, a wrong extension; FBX/glTF without a working
  ``bpy`` name the extra. An existing output is replaced (as ``render`` does), atomically: a
  failed export leaves it as it was.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gesture_sim import cli
from gesture_sim.app import motion_export as me
from gesture_sim.motion.bvh import read_bvh
from gesture_sim.motion.smplx import humanoid_rest_offsets, read_smplx
from gesture_sim.sim import humanoid as hm

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
SKELETON = DATA / "motion" / "neutral_16_000.bvh"
SPEECH = DATA / "audio" / "arctic_a0007.wav"
#: the synthetic motion: rows at 100 Hz from t0 (a trace starts after the first step)
N_ROWS, RATE, T0 = 121, 100.0, 0.01


@pytest.fixture(scope="module")
def model():
    return hm.load_model(scene=True, look="human")


@pytest.fixture(scope="module")
def motion(model, tmp_path_factory) -> tuple[Path, SimpleNamespace]:
    """A ``render --npz`` file of 1.2 s of a gesturing body: every joint swinging within its
    range (its own phase), the root swaying and turning, rows at 100 Hz."""
    from scipy.spatial.transform import Rotation

    t = T0 + np.arange(N_ROWS) / RATE
    lo, hi = hm.joint_ranges(model).T
    phase = np.random.default_rng(2).uniform(0, 2 * np.pi, len(lo))
    mid, amp = (lo + hi) / 2, 0.35 * (hi - lo)
    targets = mid + amp * np.sin(2 * np.pi * 0.8 * t[:, None] + phase)
    qpos = np.array([hm.qpos_from_targets(model, a) for a in targets])
    qpos[:, 0] += 0.05 * np.sin(2 * np.pi * 0.5 * t)
    qpos[:, 3:7] = Rotation.from_euler("z", 20 * np.sin(2 * np.pi * 0.4 * t)[:, None],
                                       degrees=True).as_quat(scalar_first=True)
    qadr = hm.qpos_addresses(model)
    trace = SimpleNamespace(time=t, qpos=qpos, joint_names=hm.ACTUATED_JOINTS,
                            q=qpos[:, qadr], q_target=qpos[:, qadr])
    decisions = [{"t": 0.0, "segment_id": 0, "frame": 0, "kind": "start", "clip": "c"}]
    path = tmp_path_factory.mktemp("motion") / "take.npz"
    me.write_npz(path, me.motion_arrays(model, trace, decisions))
    return path, trace


def export(*argv: str, capsys=None) -> tuple[int, str, str]:
    rc = cli.main(["export", *map(str, argv)])
    out, err = capsys.readouterr() if capsys is not None else ("", "")
    return rc, out, err


SPAN = (N_ROWS - 1) / RATE
FRAMES = 36   # ceil(1.2 s * 30 Hz)


@pytest.mark.parametrize("fmt, suffix, writer", [
    ("bvh", ".bvh", me.write_bvh_from_trace),
    ("bvh-mixamo", ".bvh", me.write_mixamo_from_trace),
    ("smplx", ".npz", me.write_smplx_from_trace),
    ("skeleton", ".bvh", None),
])
def test_each_format_is_what_render_writes(fmt, suffix, writer, model, motion, tmp_path,
                                           capsys) -> None:
    path, trace = motion
    out = tmp_path / f"out{suffix}"
    extra = ["--to-skeleton", SKELETON] if fmt == "skeleton" else []
    rc, stdout, err = export(path, "--format", fmt, "-o", out, *extra, "--json", capsys=capsys)
    assert rc == 0, err
    summary = json.loads(stdout)
    assert summary["format"] == fmt and summary["output"] == str(out)
    assert summary["frames"] == FRAMES and summary["motion_frames"] == N_ROWS
    assert summary["duration_s"] == pytest.approx(SPAN)
    ref = tmp_path / f"ref{suffix}"
    if fmt == "skeleton":
        me.write_skeleton_from_trace(ref, SKELETON, model, trace, SPAN)
    else:
        writer(ref, model, trace, SPAN)
    if fmt == "smplx":   # an npz: the same arrays (zip timestamps differ)
        with np.load(out) as a, np.load(ref) as b:
            assert sorted(a.files) == sorted(b.files)
            for k in a.files:
                assert np.array_equal(a[k], b[k]), k
        back = read_smplx(out, offsets=humanoid_rest_offsets(model))
        assert back.positions.shape[0] == FRAMES and back.fps == 30
        assert np.allclose(back.positions,
                           read_smplx(ref, offsets=humanoid_rest_offsets(model)).positions)
    else:
        assert out.read_bytes() == ref.read_bytes()
        back = read_bvh(out)
        assert back.positions.shape[0] == FRAMES and back.fps == pytest.approx(30)
    assert not list(tmp_path.glob(".*tmp*")) and not list(tmp_path.glob("*.tmp*"))


def test_fps_and_an_existing_output_is_replaced(motion, tmp_path, capsys) -> None:
    path, _ = motion
    out = tmp_path / "m.bvh"
    out.write_text("old")
    rc, stdout, err = export(path, "--format", "bvh-mixamo", "-o", out, "--fps", "60",
                             capsys=capsys)
    assert rc == 0, err
    assert f"wrote {out}: bvh-mixamo, 72 frames at 60 fps" in stdout
    assert read_bvh(out).positions.shape[0] == 72          # ceil(1.2 s * 60 Hz)


@pytest.mark.parametrize("argv, message", [
    (["{missing}", "--format", "bvh", "-o", "{out}.bvh"], "MOTION {missing}: motion file not "
                                                         "found"),
    (["{bvh_in}", "--format", "bvh", "-o", "{out}.bvh"], "not a motion .npz"),
    (["{foreign}", "--format", "bvh", "-o", "{out}.bvh"], "not a gesture_sim.motion_npz file"),
    (["{npz}", "--format", "skeleton", "-o", "{out}.bvh"], "--format skeleton needs "
                                                          "--to-skeleton"),
    (["{npz}", "--format", "bvh", "--to-skeleton", "{bvh_in}", "-o", "{out}.bvh"],
     "--to-skeleton: only with --format skeleton"),
    (["{npz}", "--format", "smplx", "-o", "{npz}"], "is the input file"),
    (["{npz}", "--format", "bvh", "-o", "{out}.npz"], "unsupported file type '.npz'"),
    (["{npz}", "--format", "bvh", "-o", "{out}.bvh", "--fps", "0"], "--fps"),
])
def test_errors_are_one_line_before_any_work(argv, message, motion, tmp_path, capsys) -> None:
    path, _ = motion
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, format=np.array("something else"), time=np.zeros(2))
    names = {"missing": tmp_path / "nope.npz", "bvh_in": SKELETON, "foreign": foreign,
             "npz": path, "out": tmp_path / "out"}
    argv = [a.format(**names) for a in argv]
    rc, _, err = export(*argv, capsys=capsys)
    assert rc == 2
    line = err.strip()
    assert "\n" not in line and line.startswith("gesture-sim: error: "), err
    assert message.format(**names) in line
    assert not (tmp_path / "out.bvh").exists() and not (tmp_path / "out.npz").exists()
    assert path.stat().st_size > 0          # the input is intact


def test_an_unknown_format_is_a_usage_error(motion, tmp_path, capsys) -> None:
    path, _ = motion
    with pytest.raises(SystemExit) as info:
        cli.main(["export", str(path), "--format", "usd", "-o", str(tmp_path / "x.usd")])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "invalid choice: 'usd'" in err


def test_a_motion_of_another_model_is_refused(model, tmp_path, capsys) -> None:
    bad = tmp_path / "short.npz"
    np.savez(bad, format=np.array(me.NPZ_FORMAT), time=np.arange(3) / 100,
             qpos=np.zeros((3, model.nq - 1)))
    rc, _, err = export(bad, "--format", "bvh", "-o", tmp_path / "x.bvh", capsys=capsys)
    assert rc == 2 and f"qpos has shape (3, {model.nq - 1}), expected (3, {model.nq})" in err
    assert not (tmp_path / "x.bvh").exists()
    # the same number of columns, but another humanoid's (a joint renamed): by name
    names = me.qpos_names(model)
    names[20] = "old_joint"
    np.savez(bad, format=np.array(me.NPZ_FORMAT), time=np.arange(3) / 100,
             qpos=np.tile(model.qpos0, (3, 1)), qpos_names=np.array(names))
    rc, _, err = export(bad, "--format", "bvh", "-o", tmp_path / "x.bvh", capsys=capsys)
    assert rc == 2 and "written for another version of the humanoid" in err
    assert "column 20 is 'old_joint'" in err and "\n" not in err.strip()


@pytest.mark.parametrize("fmt, missing", [("fbx", "bpy"), ("glb", "bpy"),
                                          ("glb", "gesture_sim.export.blender")])
def test_fbx_and_glb_without_blender_name_the_extra(fmt, missing, motion, tmp_path, capsys,
                                                     monkeypatch) -> None:
    """Without ``bpy`` (or without the Blender module itself): one line naming the extra, and
    nothing written."""
    monkeypatch.setitem(sys.modules, missing, None)      # `import` of it raises ImportError
    path, _ = motion
    out = tmp_path / f"x.{fmt}"
    rc, _, err = export(path, "--format", fmt, "-o", out, capsys=capsys)
    assert rc == 2
    line = err.strip()
    assert "\n" not in line and "pip install 'gesture-sim[blender]'" in line, err
    assert line.startswith("gesture-sim: error: FBX/glTF export needs Blender's Python module")
    assert list(tmp_path.iterdir()) == []        # no output, no temporary left behind


@pytest.mark.slow
def test_export_of_a_render_matches_its_own_exports(tmp_path) -> None:
    """``render --npz --mixamo --smplx`` then ``export`` of the npz: the same joint positions
    over the frames both files have."""
    d = tmp_path
    cmd = [sys.executable, "-m", "gesture_sim.cli"]
    r = subprocess.run([*cmd, "render", str(SPEECH), "-o", str(d / "r.mp4"), "--width", "160",
                        "--height", "90", "--quality", "fast", "--workers", "1",
                        "--npz", str(d / "r.npz"), "--mixamo", str(d / "r_mixamo.bvh"),
                        "--smplx", str(d / "r_smplx.npz"), "--bvh", str(d / "r.bvh"),
                        "--to-skeleton", str(SKELETON), str(d / "r_skeleton.bvh"), "--json"],
                       capture_output=True, text=True, timeout=600, cwd=ROOT,
                       env={**__import__("os").environ, "MUJOCO_GL": "egl"})
    assert r.returncode == 0, r.stderr[-3000:]
    for fmt, out, extra in (("bvh-mixamo", "e_mixamo.bvh", []), ("smplx", "e_smplx.npz", []),
                            ("bvh", "e.bvh", []),
                            ("skeleton", "e_skeleton.bvh", ["--to-skeleton", str(SKELETON)])):
        e = subprocess.run([*cmd, "export", str(d / "r.npz"), "--format", fmt, "-o",
                            str(d / out), *extra, "--json"], capture_output=True, text=True,
                           timeout=300, cwd=ROOT)
        assert e.returncode == 0, e.stderr[-3000:]
    model = hm.load_model(scene=True, look="human")
    offsets = humanoid_rest_offsets(model)
    pairs = [(read_bvh(d / "r_mixamo.bvh"), read_bvh(d / "e_mixamo.bvh")),
             (read_bvh(d / "r.bvh"), read_bvh(d / "e.bvh")),
             (read_bvh(d / "r_skeleton.bvh"), read_bvh(d / "e_skeleton.bvh")),
             (read_smplx(d / "r_smplx.npz", offsets=offsets),
              read_smplx(d / "e_smplx.npz", offsets=offsets))]
    for rendered, exported in pairs:
        n_r, n_e = len(rendered.positions), len(exported.positions)
        assert n_r == n_e == 120, (n_r, n_e)            # 4.0 s at 30 fps
        err = np.abs(rendered.positions - exported.positions).max()
        assert err < 1e-9, err
        print(f"{rendered.source}: {n_r} rendered / {n_e} exported frames, max |dp| "
              f"{1e3 * err:.4f} mm")
    assert (d / "r_mixamo.bvh").read_bytes() == (d / "e_mixamo.bvh").read_bytes()
    assert (d / "r.bvh").read_bytes() == (d / "e.bvh").read_bytes()
    assert (d / "r_skeleton.bvh").read_bytes() == (d / "e_skeleton.bvh").read_bytes()
    with np.load(d / "r_smplx.npz") as a, np.load(d / "e_smplx.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        assert all(np.array_equal(a[k], b[k]) for k in a.files)


def _bpy_works() -> bool:
    from gesture_sim.errors import GestureSimError

    try:
        from gesture_sim.export.blender import require_bpy

        require_bpy()
    except (ImportError, GestureSimError):
        return False
    return True


@pytest.mark.parametrize("fmt", ["fbx", "glb"])
def test_fbx_and_glb_through_blender(fmt, model, motion, tmp_path, capsys) -> None:
    """With a working ``bpy``: the file Blender reads back holds the export's frames, the bones
    where the MuJoCo bodies are (within 1 cm, as ``test_blender.py`` checks the writer)."""
    if not _bpy_works():
        pytest.skip("no working bpy (the extra gesture-sim[blender])")
    from gesture_sim.app.video import resample_qpos
    from gesture_sim.export.blender import body_positions, bone_heads, read_back

    path, trace = motion
    out = tmp_path / f"x.{fmt}"
    rc, stdout, err = export(path, "--format", fmt, "-o", out, "--json", capsys=capsys)
    assert rc == 0, err
    assert json.loads(stdout)["frames"] == FRAMES
    assert out.stat().st_size > 10_000 and sorted(p.name for p in tmp_path.iterdir()) == [
        out.name]
    arm = read_back(out, fmt, 30.0)
    assert tuple(round(x) for x in arm.animation_data.action.frame_range) == (0, FRAMES - 1)
    qpos = resample_qpos(model, trace.time, trace.qpos, 30.0, n_frames=FRAMES)
    frames = [0, FRAMES // 2, FRAMES - 1]
    bones = ["pelvis", "head", "right_hand", "left_hand"]
    got = bone_heads(arm, bones, frames)
    want = body_positions(model, qpos[frames], bones)
    assert np.linalg.norm(got - want, axis=-1).max() < 0.01
