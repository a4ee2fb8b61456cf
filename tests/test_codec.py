"""Tests of ros_mobile_bridge.codec: schemas, CDR/JSON decoders and encoders, templates."""

from __future__ import annotations

import json
import math
import struct
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge._errors import DecodeError, SchemaError
from ros_mobile_bridge.codec import CodecRegistry, FieldDef, normalize_type_name, same_type_name

SEP = "=" * 80

# A custom message with dependencies in the concatenated ros2msg form, using
# both dependency spellings (pkg/Type and pkg/msg/Type).
ROBOT_STATE = f"""\
# Custom robot state
std_msgs/Header header
my_robot/WheelState[2] wheels
my_robot/msg/Battery battery
float64[9] covariance
uint8[16] id
string<=8 name
int32[<=4] codes
string[] tags
================================================================================
MSG: my_robot/WheelState
float64 velocity
int32 ticks
string label "wheel"
================================================================================
MSG: my_robot/msg/Battery
uint8 STATUS_OK=0
float32 voltage 12.5
bool charging
{SEP}
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
"""

IDL_SCHEMA = """\
// generated from rosidl_adapter/resource/msg.idl.em
#include "builtin_interfaces/msg/Time.idl"

module my_robot {
  module msg {
    module Pose2D_Constants {
      const int32 MAX_SPEED = 3;
    };
    struct Pose2D {
      double x;
      double y;
      double theta;
      builtin_interfaces::msg::Time stamp;
      sequence<int16, 5> samples;
      string<16> frame;
      float gains[3];
    };
  };
};
"""

IDL_MULTI = f"""\
{SEP}
IDL: my_robot/msg/Outer
#include "my_robot/msg/Inner.idl"
module my_robot {{ module msg {{ struct Outer {{ my_robot::msg::Inner inner; uint32 count; }}; }}; }};
{SEP}
IDL: my_robot/msg/Inner
module my_robot {{ module msg {{ struct Inner {{ int64 value; string text; }}; }}; }};
"""


def roundtrip(reg: CodecRegistry, name: str, data: dict[str, Any]) -> dict[str, Any]:
    payload = reg.encoder(name, "cdr")(data)
    assert isinstance(payload, bytes)
    assert payload[:4] == b"\x00\x01\x00\x00"
    result = reg.dict_decoder(name)(memoryview(payload))
    assert isinstance(result, dict)
    return result


def plain(value: Any) -> Any:
    """Decoded value with numpy arrays as lists, for equality checks."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def string_payload(text: str, *, big_endian: bool = False) -> bytes:
    raw = text.encode() + b"\x00"
    fmt = ">I" if big_endian else "<I"
    header = b"\x00\x00\x00\x00" if big_endian else b"\x00\x01\x00\x00"
    return header + struct.pack(fmt, len(raw)) + raw


@pytest.fixture
def reg() -> CodecRegistry:
    return CodecRegistry()


# --------------------------------------------------------------------------- names


@pytest.mark.parametrize(
    ("name", "kind", "expected"),
    [
        ("std_msgs/String", "msg", "std_msgs/msg/String"),
        ("std_msgs/msg/String", "msg", "std_msgs/msg/String"),
        ("  std_msgs/msg/String\n", "msg", "std_msgs/msg/String"),
        ("std_srvs/SetBool", "srv", "std_srvs/srv/SetBool"),
        ("std_srvs/srv/SetBool_Request", "msg", "std_srvs/srv/SetBool_Request"),
        ("std_msgs::msg::String", "msg", "std_msgs/msg/String"),
        ("std_msgs::msg::dds_::String_", "msg", "std_msgs/msg/String"),
        ("/geometry_msgs/Twist", "msg", "geometry_msgs/msg/Twist"),
    ],
)
def test_normalize_type_name(name: str, kind: str, expected: str) -> None:
    assert normalize_type_name(name, kind) == expected


@pytest.mark.parametrize("bad", ["", "   ", "::", "/"])
def test_normalize_type_name_rejects_empty(bad: str) -> None:
    with pytest.raises(ValueError, match=r"."):
        normalize_type_name(bad)


def test_same_type_name() -> None:
    assert same_type_name("std_msgs/String", "std_msgs/msg/String")
    assert same_type_name("std_srvs/SetBool", "std_srvs/srv/SetBool")
    assert same_type_name("std_msgs::msg::dds_::String_", "std_msgs/String")
    assert not same_type_name("std_msgs/msg/String", "std_msgs/srv/String")
    assert not same_type_name("std_msgs/msg/String", "std_msgs/msg/Int32")
    assert not same_type_name("", "std_msgs/msg/String")


def test_service_type_names() -> None:
    expected = ("std_srvs/srv/SetBool_Request", "std_srvs/srv/SetBool_Response")
    assert CodecRegistry.service_type_names("std_srvs/srv/SetBool") == expected
    assert CodecRegistry.service_type_names("std_srvs/SetBool") == expected


def test_tolerant_lookups(reg: CodecRegistry) -> None:
    assert reg.has_schema("std_msgs/String")
    assert reg.has_schema("std_msgs/msg/String")
    assert reg.has_schema("std_msgs::msg::dds_::String_")
    assert reg.has_schema("std_srvs/SetBool_Request")
    assert not reg.has_schema("nope_msgs/msg/Nothing")
    assert not reg.has_schema("")
    payload = reg.encoder("std_msgs/String", "cdr")({"data": "hi"})
    assert reg.dict_decoder("std_msgs/msg/String")(memoryview(payload)) == {"data": "hi"}
    assert reg.template("geometry_msgs/Vector3") == {"x": 0.0, "y": 0.0, "z": 0.0}
    reg.add_schema("my_robot/WheelState", "ros2msg", "float64 velocity\n")
    assert reg.has_schema("my_robot/msg/WheelState")
    assert [f.name for f in reg.definition("my_robot/msg/WheelState")] == ["velocity"]


# --------------------------------------------------------------------------- round trips


def test_twist_roundtrip_and_partial(reg: CodecRegistry) -> None:
    decoded = roundtrip(reg, "geometry_msgs/msg/Twist", {"linear": {"x": 0.2}})
    assert decoded == {
        "linear": {"x": 0.2, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.0},
    }
    full = {"linear": {"x": 1.0, "y": -2.0, "z": 3.5}, "angular": {"x": 0.1, "y": 0.2, "z": 0.3}}
    assert roundtrip(reg, "geometry_msgs/Twist", full) == full
    # a partial dict encodes to the same bytes as the full template with the change applied
    template = reg.template("geometry_msgs/msg/Twist")
    template["angular"]["z"] = 0.5
    enc = reg.encoder("geometry_msgs/msg/Twist", "cdr")
    assert enc({"angular": {"z": 0.5}}) == enc(template)
    assert enc({}) == enc(reg.template("geometry_msgs/msg/Twist"))


def test_twist_stamped_roundtrip(reg: CodecRegistry) -> None:
    msg = {
        "header": {
            "stamp": {"sec": 1_700_000_000, "nanosec": 123_456_789},
            "frame_id": "base_link",
        },
        "twist": {
            "linear": {"x": 0.5, "y": 0.0, "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": -1.25},
        },
    }
    assert roundtrip(reg, "geometry_msgs/msg/TwistStamped", msg) == msg


def test_odometry_roundtrip(reg: CodecRegistry) -> None:
    cov = np.arange(36, dtype=np.float64) / 10
    msg: dict[str, Any] = {
        "header": {"stamp": {"sec": 5, "nanosec": 6}, "frame_id": "odom"},
        "child_frame_id": "base_link",
        "pose": {
            "pose": {
                "position": {"x": 1.0, "y": 2.0, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.7071, "w": 0.7071},
            },
            "covariance": cov,
        },
        "twist": {"twist": {"linear": {"x": 0.3}}, "covariance": list(range(36))},
    }
    decoded = roundtrip(reg, "nav_msgs/msg/Odometry", msg)
    assert decoded["header"] == msg["header"]
    assert decoded["child_frame_id"] == "base_link"
    assert decoded["pose"]["pose"] == msg["pose"]["pose"]
    assert isinstance(decoded["pose"]["covariance"], np.ndarray)
    np.testing.assert_array_equal(decoded["pose"]["covariance"], cov)
    np.testing.assert_array_equal(decoded["twist"]["covariance"], np.arange(36.0))
    assert decoded["twist"]["twist"]["linear"] == {"x": 0.3, "y": 0.0, "z": 0.0}


def test_image_roundtrip_zero_copy(reg: CodecRegistry) -> None:
    data = np.random.default_rng(1).integers(0, 256, size=(48, 64, 3), dtype=np.uint8)
    msg = {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "camera"},
        "height": 48,
        "width": 64,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": 64 * 3,
        "data": data,  # any shape: flattened in C order
    }
    payload = reg.encoder("sensor_msgs/msg/Image", "cdr")(msg)
    view = memoryview(payload)
    decoded = reg.dict_decoder("sensor_msgs/msg/Image")(view)
    assert decoded["encoding"] == "rgb8"
    assert decoded["height"] == 48
    assert decoded["data"].dtype == np.uint8
    np.testing.assert_array_equal(decoded["data"].reshape(48, 64, 3), data)
    # the pixel array is a view of the payload, not a copy
    assert np.shares_memory(decoded["data"], np.frombuffer(payload, dtype=np.uint8))
    # bytes and lists are accepted for uint8[] too
    enc = reg.encoder("sensor_msgs/msg/Image", "cdr")
    assert enc({**msg, "data": data.tobytes()}) == payload
    assert enc({**msg, "data": data.reshape(-1).tolist()}) == payload


def test_string_roundtrip(reg: CodecRegistry) -> None:
    for text in ["", "hello", "ünïcödé ✓", "x" * 1000]:
        assert roundtrip(reg, "std_msgs/msg/String", {"data": text}) == {"data": text}
    assert reg.encoder("std_msgs/msg/String", "cdr")({"data": "hi"}) == string_payload("hi")


def test_big_endian_payload(reg: CodecRegistry) -> None:
    dec = reg.dict_decoder("std_msgs/msg/String")
    assert dec(memoryview(string_payload("big", big_endian=True))) == {"data": "big"}
    # a bytes object (not a memoryview) is accepted too
    assert dec(string_payload("le")) == {"data": "le"}  # type: ignore[arg-type]


def test_custom_ros2msg_with_dependencies(reg: CodecRegistry) -> None:
    reg.add_schema("my_robot/msg/RobotState", "ros2msg", ROBOT_STATE)
    template = reg.template("my_robot/msg/RobotState")
    assert template["wheels"] == [{"velocity": 0.0, "ticks": 0, "label": "wheel"}] * 2
    assert template["battery"] == {"voltage": 12.5, "charging": False}
    assert template["covariance"] == [0.0] * 9
    assert template["id"] == [0] * 16
    assert template["codes"] == []
    assert template["tags"] == []
    msg = {
        "header": {"stamp": {"sec": 3, "nanosec": 4}, "frame_id": "map"},
        "wheels": [
            {"velocity": 1.5, "ticks": -7},
            {"velocity": -1.5, "ticks": 7, "label": "right"},
        ],
        "battery": {"charging": True},
        "covariance": np.eye(3).reshape(-1),
        "id": bytes(range(16)),
        "name": "robot",
        "codes": [1, -2, 3],
        "tags": ["a", "b"],
    }
    decoded = plain(roundtrip(reg, "my_robot/RobotState", msg))
    assert decoded["wheels"] == [
        {"velocity": 1.5, "ticks": -7, "label": "wheel"},
        {"velocity": -1.5, "ticks": 7, "label": "right"},
    ]
    assert decoded["battery"] == {"voltage": 12.5, "charging": True}
    assert decoded["covariance"] == np.eye(3).reshape(-1).tolist()
    assert decoded["id"] == list(range(16))
    assert decoded["name"] == "robot"
    assert decoded["codes"] == [1, -2, 3]
    assert decoded["tags"] == ["a", "b"]
    # the embedded dependencies are usable on their own
    assert reg.has_schema("my_robot/msg/WheelState")
    assert roundtrip(reg, "my_robot/msg/Battery", {"voltage": 11.0}) == {
        "voltage": 11.0,
        "charging": False,
    }
    # bounds are enforced when encoding
    enc = reg.encoder("my_robot/msg/RobotState", "cdr")
    with pytest.raises(DecodeError, match="name"):
        enc({"name": "far too long"})
    with pytest.raises(DecodeError, match="codes"):
        enc({"codes": [1, 2, 3, 4, 5]})
    with pytest.raises(DecodeError, match="wheels"):
        enc({"wheels": [{}]})


def test_definition(reg: CodecRegistry) -> None:
    reg.add_schema("my_robot/msg/RobotState", "ros2msg", ROBOT_STATE)
    fields = {f.name: f for f in reg.definition("my_robot/msg/RobotState")}
    assert list(fields) == [
        "header",
        "wheels",
        "battery",
        "covariance",
        "id",
        "name",
        "codes",
        "tags",
    ]
    assert fields["header"] == FieldDef("header", "std_msgs/msg/Header", False, None, None)
    assert fields["wheels"] == FieldDef("wheels", "my_robot/msg/WheelState", True, 2, None)
    assert fields["covariance"] == FieldDef("covariance", "float64", True, 9, None)
    assert fields["id"] == FieldDef("id", "uint8", True, 16, None)
    assert fields["name"] == FieldDef("name", "string", False, None, 8)
    assert fields["codes"] == FieldDef("codes", "int32", True, None, 4)
    assert fields["tags"] == FieldDef("tags", "string", True, None, None)
    wheel = reg.definition("my_robot/WheelState")
    assert wheel[2] == FieldDef("label", "string", False, None, None, "wheel")
    twist = reg.definition("geometry_msgs/Twist")
    assert [(f.name, f.type) for f in twist] == [
        ("linear", "geometry_msgs/msg/Vector3"),
        ("angular", "geometry_msgs/msg/Vector3"),
    ]
    with pytest.raises(SchemaError):
        reg.definition("nope_msgs/msg/Nothing")


def test_idl_schema_roundtrip(reg: CodecRegistry) -> None:
    reg.add_schema("my_robot/msg/Pose2D", "ros2idl", IDL_SCHEMA)
    assert reg.template("my_robot/msg/Pose2D") == {
        "x": 0.0,
        "y": 0.0,
        "theta": 0.0,
        "stamp": {"sec": 0, "nanosec": 0},
        "samples": [],
        "frame": "",
        "gains": [0.0, 0.0, 0.0],
    }
    msg = {"x": 1.0, "theta": -0.5, "samples": [1, -2, 300], "frame": "odom", "gains": [1, 2, 3]}
    decoded = plain(roundtrip(reg, "my_robot/Pose2D", msg))
    assert decoded["samples"] == [1, -2, 300]
    assert decoded["gains"] == [1.0, 2.0, 3.0]
    assert decoded["frame"] == "odom"
    assert decoded["theta"] == -0.5


def test_idl_multi_block(reg: CodecRegistry) -> None:
    reg.add_schema("my_robot/msg/Outer", "ros2idl", IDL_MULTI)
    msg = {"inner": {"value": -(2**40), "text": "deep"}, "count": 7}
    assert roundtrip(reg, "my_robot/msg/Outer", msg) == msg


def test_service_request_types(reg: CodecRegistry) -> None:
    # built in, no server schema
    assert reg.has_schema("std_srvs/srv/SetBool_Request")
    assert reg.has_schema("std_srvs/srv/SetBool_Response")
    assert roundtrip(reg, "std_srvs/srv/SetBool_Request", {"data": True}) == {"data": True}
    assert roundtrip(reg, "std_srvs/srv/Trigger_Response", {"success": True, "message": "ok"}) == {
        "success": True,
        "message": "ok",
    }
    assert roundtrip(reg, "std_srvs/srv/Empty_Request", {}) == {}
    assert reg.encoder("std_srvs/srv/Empty_Request", "cdr")({}) == b"\x00\x01\x00\x00\x00"
    for srv in (
        "rcl_interfaces/srv/GetParameters",
        "rcl_interfaces/srv/SetParameters",
        "rcl_interfaces/srv/ListParameters",
        "rcl_interfaces/srv/DescribeParameters",
        "rcl_interfaces/srv/GetParameterTypes",
        "rcl_interfaces/srv/SetParametersAtomically",
        "action_msgs/srv/CancelGoal",
    ):
        for part in CodecRegistry.service_type_names(srv):
            assert reg.has_schema(part), part
            roundtrip(reg, part, {})
    request = {
        "parameters": [
            {"name": "max_speed", "value": {"type": 3, "double_value": 1.5}},
            {"name": "blob", "value": {"type": 5, "byte_array_value": b"\xff\x00\x80"}},
        ]
    }
    decoded = roundtrip(reg, "rcl_interfaces/srv/SetParameters_Request", request)
    assert decoded["parameters"][0]["value"]["double_value"] == 1.5
    assert decoded["parameters"][1]["value"]["byte_array_value"].tolist() == [255, 0, 128]
    # a server-sent request schema under a srv name
    reg.add_schema(
        "my_srvs/srv/Move_Request", "ros2msg", "geometry_msgs/Point target\nfloat32 speed 0.5\n"
    )
    assert reg.template("my_srvs/srv/Move_Request") == {
        "target": {"x": 0.0, "y": 0.0, "z": 0.0},
        "speed": 0.5,
    }
    assert roundtrip(reg, "my_srvs/srv/Move_Request", {"target": {"x": 2.0}}) == {
        "target": {"x": 2.0, "y": 0.0, "z": 0.0},
        "speed": 0.5,
    }
    assert reg.has_schema("my_srvs/Move_Request")


def test_srv_text_registered_under_service_name(reg: CodecRegistry) -> None:
    reg.add_schema("my_srvs/srv/Add", "ros2msg", "int64 a\nint64 b\n---\nint64 sum\n")
    request, response = CodecRegistry.service_type_names("my_srvs/Add")
    assert roundtrip(reg, request, {"a": 2, "b": 3}) == {"a": 2, "b": 3}
    assert roundtrip(reg, response, {"sum": 5}) == {"sum": 5}


def test_byte_and_char_fields(reg: CodecRegistry) -> None:
    assert roundtrip(reg, "std_msgs/msg/Byte", {"data": 200}) == {"data": 200}
    assert roundtrip(reg, "std_msgs/msg/Char", {"data": 65}) == {"data": 65}
    decoded = roundtrip(reg, "std_msgs/msg/ByteMultiArray", {"data": b"\x00\x7f\x80\xff"})
    assert decoded["data"].dtype == np.uint8
    assert decoded["data"].tolist() == [0, 127, 128, 255]


# --------------------------------------------------------------------------- templates


def test_fixed_array_templates(reg: CodecRegistry) -> None:
    reg.add_schema(
        "my_robot/msg/Fixed", "ros2msg", "uint8[16] uuid\nfloat64[9] k\nstring[2] names\n"
    )
    template = reg.template("my_robot/msg/Fixed")
    assert template == {"uuid": [0] * 16, "k": [0.0] * 9, "names": ["", ""]}
    assert all(type(v) is float for v in template["k"])
    # templates are fresh copies
    template["uuid"][0] = 9
    assert reg.template("my_robot/msg/Fixed")["uuid"][0] == 0
    # built-in fixed arrays
    camera = reg.template("sensor_msgs/msg/CameraInfo")
    assert camera["k"] == [0.0] * 9
    assert camera["p"] == [0.0] * 12
    assert camera["d"] == []
    assert reg.template("unique_identifier_msgs/msg/UUID") == {"uuid": [0] * 16}
    assert reg.template("geometry_msgs/msg/Quaternion") == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


def test_jsonschema_template(reg: CodecRegistry) -> None:
    schema = {
        "type": "object",
        "properties": {
            "uuid": {"type": "array", "items": {"type": "integer"}, "minItems": 16, "maxItems": 16},
            "k": {"type": "array", "items": {"type": "number"}, "minItems": 9, "maxItems": 9},
            "points": {
                "type": "array",
                "items": {"type": "object", "properties": {"x": {"type": "number"}}},
                "minItems": 2,
                "maxItems": 2,
            },
            "free": {"type": "array", "items": {"type": "number"}, "maxItems": 4},
            "name": {"type": "string"},
            "count": {"type": "integer"},
            "ratio": {"type": "number"},
            "flag": {"type": "boolean"},
            "mode": {"enum": ["auto", "manual"]},
            "version": {"const": 2},
            "speed": {"type": "number", "default": 1.5},
            "nested": {"$ref": "#/$defs/Vec"},
            "optional": {"type": ["null", "string"]},
        },
        "$defs": {"Vec": {"type": "object", "properties": {"x": {"type": "number"}}}},
    }
    reg.add_schema("my_json/Thing", "jsonschema", json.dumps(schema))
    assert reg.has_schema("my_json/Thing")
    assert reg.template("my_json/Thing") == {
        "uuid": [0] * 16,
        "k": [0] * 9,
        "points": [{"x": 0}, {"x": 0}],
        "free": [],
        "name": "",
        "count": 0,
        "ratio": 0,
        "flag": False,
        "mode": "auto",
        "version": 2,
        "speed": 1.5,
        "nested": {"x": 0},
        "optional": "",
    }
    fields = {f.name: f for f in reg.definition("my_json/Thing")}
    assert fields["uuid"] == FieldDef("uuid", "int64", True, 16, None)
    assert fields["free"] == FieldDef("free", "float64", True, None, 4)
    assert fields["speed"] == FieldDef("speed", "float64", False, None, None, 1.5)
    enc = reg.encoder("my_json/Thing", "json")
    decoded = json.loads(enc({"name": "x", "k": np.arange(9.0), "extra": 1}))
    assert decoded["name"] == "x"
    assert decoded["k"] == list(range(9))
    assert decoded["extra"] == 1
    assert decoded["mode"] == "auto"


# --------------------------------------------------------------------------- JSON


def test_json_codecs(reg: CodecRegistry) -> None:
    dec = reg.decoder("anything/msg/Unknown", "json")
    assert dec(memoryview(b'{"a": [1, 2], "b": "c"}')) == {"a": [1, 2], "b": "c"}
    with pytest.raises(DecodeError):
        dec(memoryview(b"{not json"))
    with pytest.raises(DecodeError):
        dec(memoryview(b"\xff\xfe"))
    enc = reg.encoder("geometry_msgs/Twist", "json")
    assert json.loads(enc({"linear": {"x": 0.2}})) == {
        "linear": {"x": 0.2, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.0},
    }
    assert b" " not in enc({})
    with pytest.raises(DecodeError, match=r"linear\.w"):
        enc({"linear": {"w": 1.0}})
    raw = reg.encoder("unknown_pkg/msg/Unknown", "json")(
        {"data": b"\x01\x02", "arr": np.array([1.5])}
    )
    assert json.loads(raw) == {"data": [1, 2], "arr": [1.5]}
    image = reg.encoder("sensor_msgs/msg/Image", "json")({"data": np.arange(4, dtype=np.uint8)})
    assert json.loads(image)["data"] == [0, 1, 2, 3]


# --------------------------------------------------------------------------- errors


def test_unknown_field_is_decode_error(reg: CodecRegistry) -> None:
    enc = reg.encoder("geometry_msgs/msg/Twist", "cdr")
    with pytest.raises(DecodeError, match="linea"):
        enc({"linea": {"x": 1.0}})
    with pytest.raises(DecodeError, match=r"linear\.w"):
        enc({"linear": {"w": 1.0}})
    odom = reg.encoder("geometry_msgs/msg/PoseArray", "cdr")
    with pytest.raises(DecodeError, match=r"poses\[1\]\.position\.q"):
        odom({"poses": [{}, {"position": {"q": 1}}]})


@pytest.mark.parametrize(
    ("name", "data", "field"),
    [
        ("geometry_msgs/msg/Twist", {"linear": {"x": "fast"}}, "linear.x"),
        ("geometry_msgs/msg/Twist", {"linear": 3}, "linear"),
        ("std_msgs/msg/String", {"data": 5}, "data"),
        ("std_msgs/msg/Int32", {"data": 1.5}, "data"),
        ("std_msgs/msg/Int32", {"data": 2**31}, "data"),
        ("std_msgs/msg/UInt8", {"data": -1}, "data"),
        ("std_msgs/msg/Bool", {"data": "yes"}, "data"),
        ("std_msgs/msg/Float32", {"data": 1e300}, "data"),
        ("sensor_msgs/msg/Image", {"data": [1, 2, 256]}, "data"),
        ("sensor_msgs/msg/Image", {"data": [1.5]}, "data"),
        ("sensor_msgs/msg/Image", {"data": "abc"}, "data"),
        ("geometry_msgs/msg/PoseWithCovariance", {"covariance": [0.0] * 35}, "covariance"),
        ("geometry_msgs/msg/PoseWithCovariance", {"covariance": ["x"] * 36}, "covariance"),
        ("std_msgs/msg/Float64MultiArray", {"data": np.array([1, 2], dtype=object)}, "data"),
    ],
)
def test_wrong_value_is_decode_error(
    reg: CodecRegistry, name: str, data: dict[str, Any], field: str
) -> None:
    with pytest.raises(DecodeError, match=field.replace(".", r"\.")):
        reg.encoder(name, "cdr")(data)


def test_not_a_mapping_is_decode_error(reg: CodecRegistry) -> None:
    with pytest.raises(DecodeError):
        reg.encoder("std_msgs/msg/String", "cdr")("hello")  # type: ignore[arg-type]


def test_truncated_payload_is_decode_error(reg: CodecRegistry) -> None:
    msg = {
        "header": {"frame_id": "camera"},
        "height": 2,
        "width": 2,
        "encoding": "mono8",
        "step": 2,
        "data": b"\x01\x02\x03\x04",
    }
    payload = reg.encoder("sensor_msgs/msg/Image", "cdr")(msg)
    dec = reg.dict_decoder("sensor_msgs/msg/Image")
    for cut in range(len(payload)):
        with pytest.raises(DecodeError):
            dec(memoryview(payload[:cut]))
    # trailing garbage beyond CDR padding is an error too
    with pytest.raises(DecodeError):
        dec(memoryview(payload + b"\x00" * 8))
    # unsupported encapsulation (XCDR2)
    with pytest.raises(DecodeError, match="encapsulation"):
        dec(memoryview(b"\x00\x07" + payload[2:]))


@settings(max_examples=examples(200), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(garbage=st.binary(max_size=200))
def test_decoder_raises_only_decode_error(reg: CodecRegistry, garbage: bytes) -> None:
    for name in ("nav_msgs/msg/Odometry", "sensor_msgs/msg/Image", "std_msgs/msg/String"):
        dec = reg.dict_decoder(name)
        try:
            result = dec(memoryview(b"\x00\x01\x00\x00" + garbage))
        except DecodeError:
            continue
        assert isinstance(result, dict)


@pytest.mark.parametrize(
    ("encoding", "text"),
    [
        ("ros2msg", "float64 x\nthis is not a field\n"),
        ("ros2msg", "int32 x abc\n"),
        ("ros2msg", "uint8 x 300\n"),
        ("ros2msg", "float64[2] x [1.0, 2.0, 3.0]\n"),
        ("ros2msg", "float64[ x\n"),
        ("ros2msg", f"float64 x\n{SEP}\nnot a header\nint32 y\n"),
        ("ros2idl", "module my_robot { struct Broken { double x } };"),
        ("ros2idl", "module other { module msg { struct Something { double x; }; }; };"),
        ("jsonschema", "{not json"),
        ("jsonschema", "[1, 2]"),
    ],
)
def test_bad_schema_is_schema_error(reg: CodecRegistry, encoding: str, text: str) -> None:
    with pytest.raises(SchemaError, match="my_robot/msg/Broken"):
        reg.add_schema("my_robot/msg/Broken", encoding, text)
    assert not reg.has_schema("my_robot/msg/Broken")


def test_schema_error_is_decode_error() -> None:
    assert issubclass(SchemaError, DecodeError)


def test_unknown_type_and_encoding(reg: CodecRegistry) -> None:
    with pytest.raises(SchemaError):
        reg.dict_decoder("nope_msgs/msg/Nothing")
    with pytest.raises(SchemaError):
        reg.encoder("nope_msgs/msg/Nothing", "cdr")
    with pytest.raises(SchemaError):
        reg.template("nope_msgs/msg/Nothing")
    with pytest.raises(SchemaError, match="protobuf"):
        reg.decoder("std_msgs/msg/String", "protobuf")
    with pytest.raises(SchemaError, match="protobuf"):
        reg.encoder("std_msgs/msg/String", "protobuf")
    # a dependency nobody defines
    reg.add_schema("my_robot/msg/Orphan", "ros2msg", "missing_pkg/Thing thing\n")
    with pytest.raises(SchemaError, match="missing_pkg/msg/Thing"):
        reg.dict_decoder("my_robot/msg/Orphan")


def test_no_schema_changes_nothing(reg: CodecRegistry) -> None:
    reg.add_schema("std_msgs/msg/String", "", "")
    reg.add_schema("my_robot/msg/Opaque", "protobuf", b"\x00")
    assert reg.has_schema("std_msgs/msg/String")
    assert not reg.has_schema("my_robot/msg/Opaque")
    assert roundtrip(reg, "std_msgs/msg/String", {"data": "x"}) == {"data": "x"}


# --------------------------------------------------------------------------- redefinition


def test_server_definition_wins_over_builtin(reg: CodecRegistry) -> None:
    before = reg.dict_decoder("std_msgs/msg/String")
    reg.add_schema("std_msgs/msg/String", "ros2msg", "string data\nint32 extra 7\n")
    assert reg.template("std_msgs/msg/String") == {"data": "", "extra": 7}
    assert [f.name for f in reg.definition("std_msgs/String")] == ["data", "extra"]
    payload = reg.encoder("std_msgs/String", "cdr")({"data": "hi"})
    assert reg.dict_decoder("std_msgs/msg/String")(memoryview(payload)) == {
        "data": "hi",
        "extra": 7,
    }
    # the decoder made before the redefinition still has the built-in definition
    assert before(memoryview(string_payload("old"))) == {"data": "old"}


def test_earlier_decoder_keeps_captured_definition(reg: CodecRegistry) -> None:
    reg.add_schema("my_robot/msg/Versioned", "ros2msg", "int32 a\n")
    old_dec = reg.dict_decoder("my_robot/msg/Versioned")
    old_enc = reg.encoder("my_robot/msg/Versioned", "cdr")
    old_payload = old_enc({"a": 5})
    reg.add_schema("my_robot/msg/Versioned", "ros2msg", "int32 a\nfloat64 b\nstring c\n")
    new_dec = reg.dict_decoder("my_robot/msg/Versioned")
    new_payload = reg.encoder("my_robot/msg/Versioned", "cdr")({"a": 1, "b": 2.5, "c": "x"})
    assert new_dec(memoryview(new_payload)) == {"a": 1, "b": 2.5, "c": "x"}
    assert old_dec(memoryview(old_payload)) == {"a": 5}
    assert old_enc({"a": 6}) == old_payload[:4] + struct.pack("<i", 6)
    with pytest.raises(DecodeError):
        old_enc({"b": 1.0})
    with pytest.raises(DecodeError):
        new_dec(memoryview(old_payload))
    # re-registering the same definition reuses the codecs
    reg.add_schema("my_robot/msg/Versioned", "ros2msg", "int32 a\nfloat64 b\nstring c\n")
    assert reg.dict_decoder("my_robot/msg/Versioned") is new_dec


def test_redefined_dependency(reg: CodecRegistry) -> None:
    reg.add_schema(
        "my_robot/msg/Outer", "ros2msg", f"Inner inner\n{SEP}\nMSG: my_robot/Inner\nint32 v\n"
    )
    old = reg.dict_decoder("my_robot/msg/Outer")
    old_payload = reg.encoder("my_robot/msg/Outer", "cdr")({"inner": {"v": 3}})
    reg.add_schema("my_robot/msg/Inner", "ros2msg", "int32 v\nint32 w\n")
    payload = reg.encoder("my_robot/msg/Outer", "cdr")({"inner": {"v": 3, "w": 4}})
    assert reg.dict_decoder("my_robot/msg/Outer")(memoryview(payload)) == {
        "inner": {"v": 3, "w": 4}
    }
    assert old(memoryview(old_payload)) == {"inner": {"v": 3}}


def test_registries_are_independent() -> None:
    a, b = CodecRegistry(), CodecRegistry()
    a.add_schema("std_msgs/msg/String", "ros2msg", "int64 data\n")
    assert a.template("std_msgs/msg/String") == {"data": 0}
    assert b.template("std_msgs/msg/String") == {"data": ""}
    assert roundtrip(b, "std_msgs/msg/String", {"data": "x"}) == {"data": "x"}
    assert roundtrip(a, "std_msgs/msg/String", {"data": 5}) == {"data": 5}


# --------------------------------------------------------------------------- property


CUSTOM = f"""\
float64 x
int32 n
string s
float64[] xs
int32[3] ns
string[] ss
my_props/Item[] items
{SEP}
MSG: my_props/Item
float64 value
string label
"""

finite = st.floats(allow_nan=False, allow_infinity=True)
int32 = st.integers(-(2**31), 2**31 - 1)
text = st.text(alphabet=st.characters(codec="utf-8", exclude_characters="\x00"))


@settings(max_examples=examples(150), deadline=None)
@given(
    x=st.floats(allow_nan=True),
    n=int32,
    s=text,
    xs=st.lists(finite, max_size=8),
    ns=st.lists(int32, min_size=3, max_size=3),
    ss=st.lists(text, max_size=4),
    items=st.lists(st.fixed_dictionaries({"value": finite, "label": text}), max_size=3),
)
def test_hypothesis_roundtrip(
    x: float,
    n: int,
    s: str,
    xs: list[float],
    ns: list[int],
    ss: list[str],
    items: list[dict[str, Any]],
) -> None:
    reg = CodecRegistry()
    reg.add_schema("my_props/msg/Custom", "ros2msg", CUSTOM)
    msg = {"x": x, "n": n, "s": s, "xs": xs, "ns": ns, "ss": ss, "items": items}
    decoded = roundtrip(reg, "my_props/msg/Custom", msg)
    if math.isnan(x):
        assert math.isnan(decoded["x"])
    else:
        assert decoded["x"] == x
    assert decoded["n"] == n
    assert decoded["s"] == s
    assert decoded["xs"].tolist() == xs
    assert decoded["ns"].tolist() == ns
    assert decoded["ss"] == ss
    assert decoded["items"] == items
    # JSON round trip of the same data (where JSON can carry it)
    if all(math.isfinite(v) for v in [x, *xs, *(i["value"] for i in items)]):
        again = json.loads(reg.encoder("my_props/msg/Custom", "json")(msg))
        assert again == msg


# --------------------------------------------------------------------------- buffers


def test_large_messages_do_not_leak_old_bytes_into_padding() -> None:
    schema = "string s\nfloat64 x\nuint8[] blob\nstring t\nint64 y\n"
    big = np.full(100_000, 0xAB, dtype=np.uint8)
    messages = [
        {"s": "a" * n, "x": 1.5, "blob": big[: 70_000 + n], "t": "z" * n, "y": -1}
        for n in (1, 8, 3, 0, 6, 2)
    ]
    reg = CodecRegistry()
    reg.add_schema("my_robot/msg/Blob", "ros2msg", schema)
    enc = reg.encoder("my_robot/msg/Blob", "cdr")
    dec = reg.dict_decoder("my_robot/msg/Blob")
    for msg in messages:
        fresh = CodecRegistry()
        fresh.add_schema("my_robot/msg/Blob", "ros2msg", schema)
        expected = fresh.encoder("my_robot/msg/Blob", "cdr")(msg)
        payload = enc(msg)
        assert payload == expected
        decoded = dec(memoryview(payload))
        assert decoded["s"] == msg["s"]
        assert decoded["t"] == msg["t"]
        assert decoded["y"] == -1
        np.testing.assert_array_equal(decoded["blob"], msg["blob"])


def test_decode_from_a_slice_of_a_larger_frame(reg: CodecRegistry) -> None:
    payload = reg.encoder("std_msgs/msg/Float64MultiArray", "cdr")({"data": [1.0, 2.0, 3.0]})
    frame = bytearray(b"\x01" + b"HEADER__" * 3 + payload + b"TRAILER")
    start = 1 + 24
    view = memoryview(frame)[start : start + len(payload)]
    decoded = reg.dict_decoder("std_msgs/msg/Float64MultiArray")(view)
    assert decoded["data"].tolist() == [1.0, 2.0, 3.0]
    assert np.shares_memory(decoded["data"], np.frombuffer(frame, dtype=np.uint8))


POSE_STAMPED_FOXGLOVE = f"""\
# A Pose with reference coordinate frame and timestamp

std_msgs/Header header
Pose pose

{SEP}
MSG: std_msgs/Header
# Standard metadata for higher-level stamped data types.
# This is generally used to communicate timestamped data
# in a particular coordinate frame.

# Two-integer timestamp that is expressed as seconds and nanoseconds.
builtin_interfaces/Time stamp

# Transform frame with which this data is associated.
string frame_id

{SEP}
MSG: builtin_interfaces/Time
# This message communicates ROS Time defined here:
# https://design.ros2.org/articles/clock_and_time.html

# The seconds component, valid over all int32 values.
int32 sec

# The nanoseconds component, valid in the range [0, 1e9).
uint32 nanosec

{SEP}
MSG: geometry_msgs/Pose
# A representation of pose in free space, composed of position and orientation.

Point position
Quaternion orientation

{SEP}
MSG: geometry_msgs/Point
# This contains the position of a point in free space
float64 x
float64 y
float64 z

{SEP}
MSG: geometry_msgs/Quaternion
# This represents an orientation in free space in quaternion form.

float64 x 0
float64 y 0
float64 z 0
float64 w 1
"""


def test_server_schema_identical_to_builtin_reuses_codecs(reg: CodecRegistry) -> None:
    dec = reg.dict_decoder("geometry_msgs/msg/PoseStamped")
    enc = reg.encoder("geometry_msgs/msg/PoseStamped", "cdr")
    reg.add_schema("geometry_msgs/msg/PoseStamped", "ros2msg", POSE_STAMPED_FOXGLOVE)
    assert reg.dict_decoder("geometry_msgs/msg/PoseStamped") is dec
    assert reg.encoder("geometry_msgs/msg/PoseStamped", "cdr") is enc
    decoded = dec(memoryview(enc({"pose": {"position": {"x": 1.0}}})))
    assert decoded["pose"]["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert decoded["header"] == {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}


# -- limits ---------------------------------------------------------------------


def test_schema_over_max_schema_fields_is_refused_before_codegen() -> None:
    from ros_mobile_bridge.codec import SchemaTooLarge

    reg = CodecRegistry(max_schema_fields=10)
    reg.add_schema("x/msg/Ok", "ros2msg", "".join(f"float64 f{i}\n" for i in range(10)))
    assert reg.dict_decoder("x/msg/Ok") is not None
    big = "".join(f"float64 f{i}\n" for i in range(6))
    # fields are summed over every definition the schema holds
    with pytest.raises(SchemaTooLarge, match="12 fields in 2 types"):
        reg.add_schema("x/msg/Big", "ros2msg", big + "=" * 80 + "\nMSG: x/msg/Dep\n" + big)
    assert not reg.has_schema("x/msg/Big") and not reg.has_schema("x/msg/Dep")


def test_schema_over_max_schema_size_is_refused_unparsed() -> None:
    from ros_mobile_bridge.codec import SchemaTooLarge

    reg = CodecRegistry(max_schema_size=100)
    with pytest.raises(SchemaTooLarge, match="max_schema_size=100"):
        reg.add_schema("x/msg/Big", "ros2msg", "string data\n" + "#" * 100)
    assert isinstance(SchemaTooLarge("x"), SchemaError)  # callers catching SchemaError see it


@pytest.mark.parametrize(
    ("schema", "body"),
    [
        ("std_msgs/msg/String", struct.pack("<I", 0xFFFF_FFF0)),
        ("std_msgs/msg/Float64MultiArray", struct.pack("<III", 0, 0, 0x1FFF_FFFF)),
        ("geometry_msgs/msg/Polygon", struct.pack("<I", 0x7FFF_FFFF) + bytes(12 * 100)),
        ("visualization_msgs/msg/MarkerArray", struct.pack("<I", 0x7FFF_FFFF) + bytes(1000)),
    ],
)
def test_cdr_sequence_length_beyond_the_payload_is_refused_before_allocating(
    schema: str, body: bytes
) -> None:
    """A length prefix of billions in a payload of a few bytes is a
    DecodeError at once: no allocation of its size (checked with
    tracemalloc), no MemoryError."""
    import tracemalloc

    decode = CodecRegistry().dict_decoder(schema)
    payload = memoryview(b"\x00\x01\x00\x00" + body)
    tracemalloc.start()
    try:
        with pytest.raises(DecodeError, match="length"):
            decode(payload)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000


# -- codecs shared between registries (many connections, one build) -------------------------
def test_registries_with_the_same_definitions_share_built_codecs() -> None:
    from ros_mobile_bridge.codec import _registry

    a, b = CodecRegistry(), CodecRegistry()
    for reg in (a, b):
        reg.add_schema("demo_pkg/msg/Shared", "ros2msg", "string name\nint32 count")
    assert a.dict_decoder("demo_pkg/msg/Shared") is b.dict_decoder("demo_pkg/msg/Shared")
    assert a.encoder("demo_pkg/msg/Shared", "cdr") is b.encoder("demo_pkg/msg/Shared", "cdr")
    # another definition under the same name is another codec, never the shared one
    c = CodecRegistry()
    c.add_schema("demo_pkg/msg/Shared", "ros2msg", "float64 count")
    decode_c = c.dict_decoder("demo_pkg/msg/Shared")
    assert decode_c is not a.dict_decoder("demo_pkg/msg/Shared")
    payload = c.encoder("demo_pkg/msg/Shared", "cdr")({"count": 2.5})
    assert decode_c(memoryview(payload)) == {"count": 2.5}
    assert a.dict_decoder("demo_pkg/msg/Shared")(
        memoryview(a.encoder("demo_pkg/msg/Shared", "cdr")({"name": "x", "count": 3}))
    ) == {"name": "x", "count": 3}
    assert len(_registry._SHARED) <= _registry.SHARED_CODECS_MAX


def test_the_shared_codec_cache_is_bounded_and_counts_evictions() -> None:
    from ros_mobile_bridge.codec._registry import _SharedCodecs

    cache = _SharedCodecs(max_entries=3)
    for i in range(5):
        cache.put(("k", i), f"codec {i}")
    assert len(cache) == 3
    assert cache.evicted == 2
    assert cache.get(("k", 0)) is None  # the oldest went first
    assert cache.get(("k", 2)) == "codec 2"
    cache.put(("k", 5), "codec 5")  # ("k", 3) is now the least recently used
    assert cache.get(("k", 3)) is None
    assert cache.get(("k", 2)) == "codec 2"
    assert cache.hits == 2
