"""rmb.jsonable: a decoded message as data strict JSON accepts."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

import ros_mobile_bridge as rmb


def strict(value: Any) -> Any:
    def refuse(name: str) -> Any:
        raise ValueError(f"not JSON: {name}")

    return json.loads(json.dumps(value, allow_nan=False), parse_constant=refuse)


def test_every_kind_of_field_becomes_strict_json() -> None:
    data = {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "odom"},
        "position": np.array([1.0, 2.5, math.nan]),
        "covariance": (0.1, math.inf, -math.inf),
        "data": b"\x00\xff",
        "view": memoryview(bytearray(b"ab")),
        "scalar": np.float32(0.5),
        "count": np.int64(7),
        "flag": True,
        "items": [{"x": math.nan}],
        3: "int key",
    }
    out = strict(rmb.jsonable(data))
    assert out == {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "odom"},
        "position": [1.0, 2.5, None],
        "covariance": [0.1, None, None],
        "data": "AP8=",
        "view": "YWI=",
        "scalar": 0.5,
        "count": 7,
        "flag": True,
        "items": [{"x": None}],
        "3": "int key",
    }
    assert type(out["count"]) is int and out["flag"] is True


def test_the_input_is_not_modified() -> None:
    data = {"a": [math.nan], "b": {"c": b"x"}}
    rmb.jsonable(data)
    assert math.isnan(data["a"][0]) and data["b"] == {"c": b"x"}
