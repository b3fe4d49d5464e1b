"""Generated hostile inputs for the reliability catalogue: broken and odd audio, motion,
library, model and policy files, written into a folder by :func:`make_all`.

Every file is made from scratch here (or from the small fixtures in tests/data), so the
catalogue needs no stored junk.
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import wave
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
SPEECH = DATA / "audio" / "arctic_a0007.wav"
BVH = DATA / "motion" / "dataset-1_bow_active_001.bvh"
DEFAULT_LIBRARY = ROOT / "motion_library" / "default"


def _wav(path: Path, samples: np.ndarray, rate: int = 16000, width: int = 2,
         channels: int = 1) -> Path:
    x = np.asarray(samples, dtype=np.float64)
    if width == 1:
        raw = np.clip(x * 127 + 128, 0, 255).astype(np.uint8).tobytes()
    elif width == 2:
        raw = np.clip(x * 32767, -32768, 32767).astype("<i2").tobytes()
    elif width == 3:
        v = np.clip(x * 8388607, -8388608, 8388607).astype("<i4")
        raw = b"".join(int(s).to_bytes(4, "little", signed=True)[:3] for s in v)
    else:
        raw = np.clip(x * 2147483647, -2**31, 2**31 - 1).astype("<i4").tobytes()
    with wave.open(str(path), "wb") as w:
        w.setnchannels(channels)
        w.setsampwidth(width)
        w.setframerate(rate)
        w.writeframes(raw)
    return path


def _float_wav(path: Path, samples: np.ndarray, rate: int = 16000, bits: int = 32) -> Path:
    """An IEEE-float WAV (format tag 3), samples written as given (NaN/inf included)."""
    data = np.asarray(samples, dtype="<f4" if bits == 32 else "<f8").tobytes()
    block = bits // 8
    fmt = struct.pack("<HHIIHH", 3, 1, rate, rate * block, block, bits)
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + \
        struct.pack("<I", len(data)) + data
    path.write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)
    return path


def speech() -> np.ndarray:
    """The test speech (16 kHz mono float in [-1, 1])."""
    from scipy.io import wavfile

    rate, x = wavfile.read(SPEECH)
    assert rate == 16000
    return x.astype(np.float64) / 32768.0


def make_audio(d: Path) -> dict[str, Path]:
    """Broken, odd and hostile audio files."""
    d.mkdir(parents=True, exist_ok=True)
    x = speech()
    good = d / "good.wav"
    shutil.copy(SPEECH, good)
    raw = good.read_bytes()
    out = {"good": good}
    out["empty"] = d / "empty.wav"
    out["empty"].write_bytes(b"")
    out["header_only"] = d / "header_only.wav"
    out["header_only"].write_bytes(raw[:44])
    out["truncated_header"] = d / "truncated_header.wav"
    out["truncated_header"].write_bytes(raw[:30])
    out["truncated_mid"] = d / "truncated_mid.wav"
    out["truncated_mid"].write_bytes(raw[: len(raw) // 2 + 1])   # odd byte count, size says more
    out["truncated_tiny"] = d / "truncated_tiny.wav"
    out["truncated_tiny"].write_bytes(raw[:44 + 100])
    out["short_0_2s"] = _wav(d / "short_0_2s.wav", x[:3200])
    out["short_10ms"] = _wav(d / "short_10ms.wav", x[:160])
    out["one_sample"] = _wav(d / "one_sample.wav", x[:1])
    out["silent"] = _wav(d / "silent.wav", np.zeros(32000))
    out["nan"] = _float_wav(d / "nan.wav", np.full(32000, np.nan))
    out["inf"] = _float_wav(d / "inf.wav", np.full(32000, np.inf))
    mixed = x.copy()
    mixed[::100] = np.nan
    mixed[50::100] = np.inf
    out["some_nan"] = _float_wav(d / "some_nan.wav", mixed)
    out["huge_float"] = _float_wav(d / "huge_float.wav", x * 1e30)
    out["float64"] = _float_wav(d / "float64.wav", x, bits=64)
    out["rate_8k"] = _wav(d / "rate_8k.wav", x[::2], rate=8000)
    out["rate_1hz"] = _wav(d / "rate_1hz.wav", x[:64], rate=1)
    out["rate_7hz"] = _wav(d / "rate_7hz.wav", x[:64], rate=7)
    out["rate_384k"] = _wav(d / "rate_384k.wav", np.repeat(x[:16000], 24), rate=384000)
    out["width8"] = _wav(d / "width8.wav", x, width=1)
    out["width24"] = _wav(d / "width24.wav", x[:16000], width=3)
    out["width32"] = _wav(d / "width32.wav", x, width=4)
    out["stereo"] = _wav(d / "stereo.wav", np.repeat(x, 2), channels=2)
    six = np.repeat(x[:16000], 6)
    out["six_channels"] = _wav(d / "six_channels.wav", six, channels=6)
    zero_rate = bytearray(raw)
    zero_rate[24:28] = (0).to_bytes(4, "little")
    out["rate_zero"] = d / "rate_zero.wav"
    out["rate_zero"].write_bytes(bytes(zero_rate))
    zero_ch = bytearray(raw)
    zero_ch[22:24] = (0).to_bytes(2, "little")
    out["channels_zero"] = d / "channels_zero.wav"
    out["channels_zero"].write_bytes(bytes(zero_ch))
    bad_bits = bytearray(raw)
    bad_bits[34:36] = (13).to_bytes(2, "little")
    out["bits_13"] = d / "bits_13.wav"
    out["bits_13"].write_bytes(bytes(bad_bits))
    out["riff_not_wave"] = d / "riff_not_wave.wav"
    out["riff_not_wave"].write_bytes(b"RIFF" + raw[4:8] + b"AVI " + raw[12:])
    out["wrong_magic"] = d / "wrong_magic.wav"
    out["wrong_magic"].write_bytes(b"RIFX" + raw[4:])
    out["random_bytes"] = d / "random_bytes.wav"
    out["random_bytes"].write_bytes(np.random.default_rng(0).bytes(20000))
    out["text"] = d / "text.wav"
    out["text"].write_text("this is not audio\n" * 100)
    out["mp3_named_text"] = d / "notes.mp3"
    out["mp3_named_text"].write_text("not an mp3 either\n")
    out["png_as_wav"] = d / "picture.wav"
    out["png_as_wav"].write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 200)
    out["unicode"] = d / "ünïcødé spéech ✓.wav"
    shutil.copy(SPEECH, out["unicode"])
    out["no_read"] = d / "no_read.wav"
    shutil.copy(SPEECH, out["no_read"])
    out["no_read"].chmod(0)
    out["folder"] = d / "folder.wav"
    out["folder"].mkdir(exist_ok=True)
    out["missing"] = d / "missing.wav"
    fifo = d / "fifo.wav"
    if not fifo.exists():
        os.mkfifo(fifo)
    out["fifo"] = fifo
    out["hardlink"] = d / "hardlink_to_good.mp4"
    if not out["hardlink"].exists():
        os.link(good, out["hardlink"])
    out["long"] = d / "long_11s.wav"
    shutil.copy(DATA / "audio" / "jfk.wav", out["long"])
    out["dev_zero"] = Path("/dev/zero")
    out["dev_null"] = Path("/dev/null")
    return out


def _damage_npz(src: Path, dst: Path, how: str) -> None:
    raw = src.read_bytes()
    if how == "truncated":
        dst.write_bytes(raw[: len(raw) // 2])
    elif how == "empty":
        dst.write_bytes(b"")
    elif how == "garbage":
        dst.write_bytes(np.random.default_rng(1).bytes(4096))
    elif how == "pickle":
        dst.write_bytes(b"\x80\x04K\x01.")  # a pickle: numpy would advise allow_pickle
    elif how == "text":
        dst.write_text("not an archive")
    else:  # keys missing: a valid npz with one unrelated array
        np.savez(dst.with_suffix(""), unrelated=np.zeros(3))
        Path(str(dst.with_suffix("")) + ".npz").replace(dst)


def make_libraries(d: Path) -> dict[str, Path]:
    """Copies of the default library (symlinked model) with one file damaged each."""
    d.mkdir(parents=True, exist_ok=True)
    out: dict[str, Path] = {}
    manifest = json.loads((DEFAULT_LIBRARY / "manifest.json").read_text())

    def lib(name: str) -> Path:
        f = d / f"lib_{name}"
        f.mkdir(exist_ok=True)
        for item in ("library.npz", "manifest.json", "fgd_extractor.npz"):
            if not (f / item).exists():
                os.symlink(DEFAULT_LIBRARY / item, f / item)
        if not (f / "model").exists():
            os.symlink(DEFAULT_LIBRARY / "model", f / "model")
        out[name] = f
        return f

    for how in ("truncated", "empty", "garbage", "pickle", "text", "keys"):
        f = lib(f"npz_{how}")
        (f / "library.npz").unlink()
        _damage_npz(DEFAULT_LIBRARY / "library.npz", f / "library.npz", how)
    variants = {
        "manifest_list": [1, 2, 3],
        "manifest_no_joints": {k: v for k, v in manifest.items() if k != "joint_names"},
        "manifest_no_clips": {k: v for k, v in manifest.items() if k != "clips"},
        "manifest_wrong_version": dict(manifest, format_version=999),
        "manifest_wrong_format": dict(manifest, format="something else"),
        "manifest_bad_fingerprint": dict(manifest, fingerprint="0" * 16),
        "manifest_clips_string": dict(manifest, clips="oops"),
        "manifest_fps_string": dict(manifest, fps="fast"),
    }
    for name, doc in variants.items():
        f = lib(name)
        (f / "manifest.json").unlink()
        (f / "manifest.json").write_text(json.dumps(doc))
    for name, text in {"manifest_truncated": json.dumps(manifest)[:200],
                       "manifest_empty": "", "manifest_binary": "\x00\x01\x02"}.items():
        f = lib(name)
        (f / "manifest.json").unlink()
        (f / "manifest.json").write_text(text)
    f = lib("no_manifest")
    (f / "manifest.json").unlink()
    f = lib("no_npz")
    (f / "library.npz").unlink()
    return out


def make_models(d: Path) -> dict[str, Path]:
    """Model folders (library default, given with --model) with one file damaged each."""
    d.mkdir(parents=True, exist_ok=True)
    src = DEFAULT_LIBRARY / "model"
    meta = json.loads((src / "model.json").read_text())
    out: dict[str, Path] = {}

    def model(name: str) -> Path:
        f = d / f"model_{name}"
        f.mkdir(exist_ok=True)
        for item in ("model.json", "model.npz", "policy.npz"):
            if not (f / item).exists():
                shutil.copy(src / item, f / item)
        out[name] = f
        return f

    for how in ("truncated", "empty", "garbage", "pickle", "keys"):
        f = model(f"npz_{how}")
        _damage_npz(src / "model.npz", f / "model.npz", how)
    for name, text in {"json_truncated": json.dumps(meta)[:100], "json_list": "[1, 2]",
                       "json_no_settings": json.dumps({k: v for k, v in meta.items()
                                                       if k != "settings"}),
                       "json_bad_version": json.dumps(dict(meta, version="99.0"))}.items():
        f = model(name)
        (f / "model.json").write_text(text)
    f = model("no_json")
    (f / "model.json").unlink()
    for how in ("truncated", "garbage", "keys"):
        f = model(f"policy_{how}")
        _damage_npz(src / "policy.npz", f / "policy.npz", how)
    return out


def _nan_frames(text: str, cut: int) -> str:
    """The BVH with every value of its frames after the tenth replaced by ``nan``."""
    head, motion = text[:cut], text[cut:].splitlines()
    out = motion[:13]
    for line in motion[13:]:
        out.append(" ".join("nan" for _ in line.split()))
    return head + "\n".join(out) + "\n"


def make_motion(d: Path) -> dict[str, Path]:
    """Broken motion capture files (BVH and SMPL-X npz) and a tags file."""
    d.mkdir(parents=True, exist_ok=True)
    text = BVH.read_text()
    out: dict[str, Path] = {"good_bvh": d / "good.bvh"}
    shutil.copy(BVH, out["good_bvh"])
    cut = text.index("MOTION")
    files = {
        "bvh_empty": "",
        "bvh_header_only": text[:cut],
        "bvh_no_frames": text[:cut] + "MOTION\nFrames: 0\nFrame Time: 0.033333\n",
        "bvh_truncated": text[: cut + (len(text) - cut) // 2],
        "bvh_text": "hello world\n",
        "bvh_frame_time_zero": text.replace("Frame Time:", "Frame Time: 0 #", 1),
        "bvh_nan": _nan_frames(text, cut),
    }
    for name, t in files.items():
        out[name] = d / f"{name}.bvh"
        out[name].write_text(t)
    out["bvh_unknown_skeleton"] = d / "unknown_skeleton.bvh"
    out["bvh_unknown_skeleton"].write_text(
        text.replace("JOINT ", "JOINT X").replace("ROOT ", "ROOT X"))
    out["npz_garbage"] = d / "garbage.npz"
    out["npz_garbage"].write_bytes(np.random.default_rng(2).bytes(2048))
    out["npz_empty_archive"] = d / "empty_archive.npz"
    np.savez(d / "empty_archive", nothing=np.zeros(1))
    out["txt_motion"] = d / "motion.txt"
    out["txt_motion"].write_text("not motion")
    out["tags_bad_json"] = d / "tags_bad.json"
    out["tags_bad_json"].write_text("{not json")
    out["tags_list"] = d / "tags_list.json"
    out["tags_list"].write_text("[1, 2]")
    return out


def make_outputs(d: Path) -> dict[str, Path]:
    """Things an output path may collide with."""
    d.mkdir(parents=True, exist_ok=True)
    out = {"dir_mp4": d / "existing_folder.mp4", "dir_json": d / "existing_folder.json",
           "dir_png": d / "existing_folder.png", "file_report": d / "report_file.txt",
           "old_mp4": d / "old.mp4", "old_json": d / "old.json", "old_png": d / "old.png",
           "link_to_input": d / "link_to_input.mp4", "fifo_mp4": d / "fifo.mp4",
           "file_as_folder": d / "plain_file"}
    for k in ("dir_mp4", "dir_json", "dir_png"):
        out[k].mkdir(exist_ok=True)
    out["file_report"].write_text("my notes")
    out["old_mp4"].write_bytes(b"old video")
    out["old_json"].write_text('{"old": true}')
    out["old_png"].write_bytes(b"old picture")
    out["file_as_folder"].write_text("a file where a folder is needed")
    out["demo_dir"] = d / "demo_dir"
    (out["demo_dir"] / "demo_timeline.png").mkdir(parents=True, exist_ok=True)
    if not out["fifo_mp4"].exists():
        os.mkfifo(out["fifo_mp4"])
    return out


def make_inputs(d: Path) -> dict[str, Path]:
    """Good inputs other than the audio (a keyword table, a signals file, a library with real
    files) that no output may replace."""
    d.mkdir(parents=True, exist_ok=True)
    kw = d / "keywords.json"
    kw.write_text((ROOT / "gesture_sim" / "audio" / "keywords_default.json").read_text())
    lib = d / "library"
    lib.mkdir(exist_ok=True)
    for item in ("library.npz", "manifest.json"):
        if not (lib / item).exists():
            shutil.copyfile(DEFAULT_LIBRARY / item, lib / item)
    if not (lib / "model").exists():
        os.symlink(DEFAULT_LIBRARY / "model", lib / "model")
    bvh = d / "take.bvh"
    shutil.copyfile(ROOT / "tests" / "data" / "motion" / "dataset-1_bow_active_001.bvh", bvh)
    holder = d / "holder"
    holder.mkdir(exist_ok=True)
    shutil.copyfile(bvh, holder / "take.bvh")
    return {"keywords": kw, "library": lib, "manifest": lib / "manifest.json",
            "library_npz": lib / "library.npz", "bvh": bvh, "holder": holder,
            "holder_bvh": holder / "take.bvh"}


def make_all(d: Path) -> dict[str, Path]:
    """Every generated file, by name (keys prefixed by their group)."""
    files: dict[str, Path] = {}
    for prefix, maker in (("audio", make_audio), ("lib", make_libraries), ("model", make_models),
                          ("motion", make_motion), ("out", make_outputs), ("in", make_inputs)):
        for k, v in maker(d / prefix).items():
            files[f"{prefix}.{k}"] = v
    link = files["out.link_to_input"]
    if not link.is_symlink():
        os.symlink(files["audio.good"], link)
    files["out.link_to_old_mp4"] = link.with_name("link_to_old.json")
    if not files["out.link_to_old_mp4"].is_symlink():
        os.symlink(files["out.old_mp4"], files["out.link_to_old_mp4"])
    return files
