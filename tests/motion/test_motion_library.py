"""The library: contract, tags, save/load round trip, fingerprint, the command line."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.cli import main
from gesture_sim.errors import GestureSimError
from gesture_sim.motion.library import MotionLibrary

DATA = Path(__file__).resolve().parents[1] / "data" / "motion"


def test_library_contract(small_library, retargeter):
    lib, reports = small_library
    assert lib.fps == 30.0
    assert lib.joint_names == retargeter.joint_names
    assert [r.name for r in reports] == ["2_scott_0_1_1_first10s",
                                        "dataset-2_wave-right-hand_normal_001"]
    assert lib.params.shape == (len(lib.segments), 6)
    for s in lib.segments:
        clip = lib.clips[s.clip]
        assert lib.segment_qpos(s.index).shape == (s.length, len(lib.joint_names))
        assert 0 < s.interrupt_frames[0] < s.interrupt_frames[1] < s.interrupt_frames[2] < s.length
        if s.successor >= 0:
            nxt = lib.segments[s.successor]
            assert nxt.clip == s.clip and nxt.start == s.end and nxt.predecessor == s.index
        else:
            assert s.end == clip.n_frames
    for clip in lib.clips:
        assert clip.qpos.dtype == np.float32
        assert clip.licence == "CC BY-NC 4.0"
        assert clip.root_pos.shape == (clip.n_frames, 3)
        assert clip.root_quat.shape == (clip.n_frames, 4)


def test_wave_strokes_are_tagged_and_speech_is_not(small_library):
    lib, _ = small_library
    wave = [s for s in lib.segments if s.clip == 1]
    tagged = [s for s in wave if "wave" in s.tags]
    assert lib.clips[1].tags == ("wave",) and lib.clips[0].tags == ()
    assert 0 < len(tagged) < len(wave) + 1
    assert not any(s.tags for s in lib.segments if s.clip == 0)
    # Tagged strokes move faster than the untagged segments of the clip (V is column 2).
    untagged = [s for s in wave if not s.tags]
    if untagged:
        assert min(s.params[2] for s in tagged) > max(s.params[2] for s in untagged)


def test_save_load_round_trip(small_library, tmp_path):
    lib, _ = small_library
    lib.save(tmp_path / "lib")
    back = MotionLibrary.load(tmp_path / "lib")
    assert back.fingerprint == lib.fingerprint
    assert back.joint_names == lib.joint_names and back.fps == lib.fps
    assert back.param_normalisation == lib.param_normalisation
    for a, b in zip(lib.clips, back.clips, strict=True):
        np.testing.assert_array_equal(a.qpos, b.qpos)
        np.testing.assert_array_equal(a.root_quat, b.root_quat)
        assert (a.name, a.source, a.licence, a.tags) == (b.name, b.source, b.licence, b.tags)
        np.testing.assert_allclose(a.keypoints, b.keypoints, atol=2e-3)  # float16 on disk
    for a, b in zip(lib.segments, back.segments, strict=True):
        assert (a.clip, a.start, a.end, a.predecessor, a.successor, a.interrupt_frames,
                a.tags) == (b.clip, b.start, b.end, b.predecessor, b.successor,
                            b.interrupt_frames, b.tags)
        np.testing.assert_array_equal(a.params, b.params)
    d1, d2 = lib.distances(), back.distances()
    np.testing.assert_allclose(d1.d_seg, d2.d_seg, atol=0.05)


def test_fingerprint_tracks_content(small_library, tmp_path):
    lib, _ = small_library
    lib.save(tmp_path / "a")
    other = MotionLibrary.load(tmp_path / "a")
    other.clips[0].qpos[0, 0] += 0.1
    other._fingerprint = None
    assert other.fingerprint != lib.fingerprint
    # A library whose arrays were swapped for other content is refused.
    other.save(tmp_path / "b")
    shutil.copy(tmp_path / "b" / "library.npz", tmp_path / "a" / "library.npz")
    with pytest.raises(GestureSimError, match="fingerprint"):
        MotionLibrary.load(tmp_path / "a")


def test_load_refuses_other_versions_and_non_libraries(small_library, tmp_path):
    lib, _ = small_library
    lib.save(tmp_path / "lib")
    manifest = json.loads((tmp_path / "lib" / "manifest.json").read_text())
    manifest["format_version"] = 99
    (tmp_path / "lib" / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(GestureSimError, match="version 99"):
        MotionLibrary.load(tmp_path / "lib")
    with pytest.raises(GestureSimError, match="not a motion library"):
        MotionLibrary.load(tmp_path)


def test_library_distances_on_real_segments(small_library):
    lib, _ = small_library
    d = lib.distances()
    n = len(lib.segments)
    assert d.d_in.shape == (n, 3, n)
    np.testing.assert_allclose(d.d_seg, d.d_seg.T)
    for s in lib.segments:
        if s.successor >= 0:
            assert d.d_sp[s.index, s.successor] == pytest.approx(0.0, abs=1e-9)


def test_cli_build_info_and_errors(tmp_path, capsys):
    out = tmp_path / "lib"
    tags = tmp_path / "tags.json"
    tags.write_text(json.dumps({"*bye*": ["bye"]}))
    assert main(["library", "build", str(DATA / "dataset-1_bye_sad_001.bvh"), "-o", str(out),
                 "--tags", str(tags), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["clips"] == 1 and summary["segments"] >= 2
    assert summary["files"][0]["retarget_error"] < 0.1
    assert main(["library", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["fingerprint"] == summary["fingerprint"]
    assert info["tags"].get("bye", 0) >= 1
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\n")
    assert main(["library", "build", str(bad), "-o", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gesture-sim: error:") and "\n" not in err


def test_cli_preview_renders_a_contact_sheet(small_library, tmp_path, capsys):
    import imageio.v3 as iio

    lib, _ = small_library
    lib.save(tmp_path / "lib")
    png = tmp_path / "sheet.png"
    assert main(["library", "preview", str(tmp_path / "lib"), "-o", str(png), "--max", "4",
                 "--columns", "2", "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert len(shown["segments"]) == 4
    img = iio.imread(png)
    assert img.shape[0] > 400 and img.shape[1] > 300
    assert img.reshape(-1, img.shape[-1]).std(axis=0).max() > 10  # not a blank image


def test_analyse_motion_matches_the_library_segmentation(small_library, retargeter):
    from gesture_sim.motion.build import analyse_motion

    lib, _ = small_library
    a = analyse_motion(DATA / "2_scott_0_1_1_first10s.npz", lib.param_normalisation,
                       retargeter=retargeter)
    ours = [(s.start, s.end) for s in lib.segments if s.clip == 0]
    assert [tuple(r) for r in a.segments] == ours
    np.testing.assert_allclose(a.params, lib.params[: len(ours)], atol=1e-5)


def test_a_failed_save_leaves_the_previous_library_whole(tmp_path, monkeypatch) -> None:
    """Issue 27, sweep defect 4: a failure after the arrays are written (here: the manifest's
    serialisation, as a full disk would) publishes nothing; the old library still loads."""
    import errno

    import gesture_sim.motion.library as ml

    lib = MotionLibrary.load(DATA.parents[2] / "motion_library" / "default")
    out = tmp_path / "lib"
    small = lib.subset(["dataset-1_bow_*"])
    small.save(out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(ml.json, "dumps", full)
    with pytest.raises(OSError):
        lib.subset(["dataset-1_bye_*"]).save(out)
    monkeypatch.undo()
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before   # no temporaries either
    assert MotionLibrary.load(out).fingerprint == small.fingerprint
