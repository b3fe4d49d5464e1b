"""The one JSON sanitiser (fileio.jsonable) and the one style-dial conversion (control.style)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from gesture_sim.control.style import clip_style, dial_from_style
from gesture_sim.fileio import jsonable


def test_jsonable_turns_numpy_paths_and_nan_into_plain_json() -> None:
    doc = {"a": np.float32(0.5), "b": np.int64(3), "c": np.bool_(True), "d": [1.0, math.nan],
           "e": (np.inf, 2), "f": np.array([[1, 2], [3, 4]]), "g": Path("x/y.wav"),
           np.int64(7): "key", "h": {"i": -math.inf}, "s": "text", "n": None}
    out = jsonable(doc)
    assert out == {"a": 0.5, "b": 3, "c": True, "d": [1.0, None], "e": [None, 2],
                   "f": [[1, 2], [3, 4]], "g": "x/y.wav", "7": "key", "h": {"i": None},
                   "s": "text", "n": None}
    assert type(out["a"]) is float and type(out["b"]) is int and type(out["c"]) is bool
    text = json.dumps(out, allow_nan=False)           # strict JSON
    assert json.loads(text) == out


def test_jsonable_can_keep_non_finite_floats() -> None:
    out = jsonable({"x": np.array([np.nan, 1.0]), "y": np.float64(np.inf)}, finite=False)
    assert math.isnan(out["x"][0]) and out["x"][1] == 1.0 and out["y"] == math.inf
    back = json.loads(json.dumps(out))
    assert math.isnan(back["x"][0]) and back["y"] == math.inf


def test_jsonable_leaves_unknown_objects_to_json() -> None:
    marker = object()
    assert jsonable([marker])[0] is marker
    with pytest.raises(TypeError):
        json.dumps(jsonable({"o": marker}))


@pytest.mark.parametrize(("style", "offset", "dial"), [
    (0.0, 0.0, -1.0), (0.5, 0.0, 0.0), (1.0, 0.0, 1.0), (0.75, 0.0, 0.5),
    (0.5, 0.3, 0.3), (0.9, 0.5, 1.0), (0.1, -0.5, -1.0),
])
def test_style_setting_to_dial(style: float, offset: float, dial: float) -> None:
    assert dial_from_style(style, offset) == pytest.approx(dial)


def test_style_setting_is_clipped_to_the_user_range() -> None:
    assert clip_style(-0.2) == 0.0 and clip_style(1.7) == 1.0 and clip_style(0.25) == 0.25
