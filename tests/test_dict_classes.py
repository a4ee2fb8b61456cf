"""A JSON bridge's message (nested dicts and lists, ``uint8[]`` as base64
text as rosbridge sends it) becomes the same instance the CDR decoder makes
of the same message; what does not fit raises ``DecodeError`` naming the
type and the field; a type with only a JSON Schema keeps its dict."""

from __future__ import annotations

import base64
import json
from typing import Any

import numpy as np
import pytest

import ros_mobile_bridge as rmb
from ros_mobile_bridge.codec import CodecRegistry
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.sensor_msgs.msg import Image, JointState
from ros_mobile_bridge.interfaces.std_msgs.msg import String
from ros_mobile_bridge.interfaces.tf2_msgs.msg import TFMessage

REG = CodecRegistry()


def _rosbridge_form(value: Any) -> Any:
    """A ``to_dict()`` as rosbridge writes it in JSON: ``uint8[]`` base64,
    other arrays lists."""
    if isinstance(value, dict):
        return {k: _rosbridge_form(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rosbridge_form(v) for v in value]
    if isinstance(value, np.ndarray):
        if value.dtype == np.uint8:
            return base64.b64encode(value.tobytes()).decode()
        return value.tolist()
    return value


def _samples() -> list[Any]:
    odometry = Odometry()
    odometry.header.frame_id = "odom"
    odometry.pose.pose.position.x = 1.5
    odometry.pose.covariance = np.arange(36.0)
    joints = JointState(name=["a", "b"], position=np.array([0.5, -1.0]))
    image = Image(height=2, width=3, encoding="mono8", step=3, data=bytes(range(6)))
    tf = TFMessage.from_dict({"transforms": [{"child_frame_id": "x"}, {"child_frame_id": "y"}]})
    return [String(data="hé"), odometry, joints, image, tf]


@pytest.mark.parametrize("message", _samples(), ids=lambda m: type(m).__name__)
def test_json_gives_the_instance_the_cdr_decoder_gives(message: Any) -> None:
    name = type(message).__ros_type__
    from_cdr = REG.decoder(name, "cdr")(memoryview(REG.encoder(name, "cdr")(message)))
    text = json.dumps(_rosbridge_form(message.to_dict()))
    from_json = REG.decoder(name, "json")(memoryview(text.encode()))
    assert type(from_json) is type(message)
    assert from_json == from_cdr == message
    # what the rosbridge reader hands over (already parsed) converts the same
    convert = REG.dict_converter(name)
    assert convert is not None
    assert convert(json.loads(text)) == message


def test_uint8_arrays_come_as_base64_or_as_lists() -> None:
    convert = REG.dict_converter("sensor_msgs/msg/Image")
    assert convert is not None
    fields = Image(data=bytes([1, 2, 3])).to_dict()
    fields["data"] = [1, 2, 3]
    as_list = convert(fields)
    fields["data"] = base64.b64encode(bytes([1, 2, 3])).decode()
    as_text = convert(fields)
    assert as_list == as_text
    assert as_text.data.dtype == np.uint8 and as_text.data.tolist() == [1, 2, 3]


def test_a_float_field_written_as_an_integer_is_a_float() -> None:
    convert = REG.dict_converter("geometry_msgs/msg/Vector3")
    assert convert is not None
    vector = convert({"x": 0, "y": 1, "z": 2.5})
    assert (vector.x, vector.y, vector.z) == (0.0, 1.0, 2.5)
    assert type(vector.x) is float


@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"height": 1, "bogus": 2}, "unknown field"),
        (
            {**Image().to_dict(), "data": "not base64!"},
            "not base64",
        ),
        ({**Image().to_dict(), "header": "a string"}, "sensor_msgs/msg/Image"),
    ],
)
def test_what_does_not_fit_is_a_decode_error_naming_it(fields: dict[str, Any], words: str) -> None:
    convert = REG.dict_converter("sensor_msgs/msg/Image")
    assert convert is not None
    with pytest.raises(rmb.DecodeError, match=words):
        convert(fields)


def test_a_partial_message_is_completed_with_the_defaults() -> None:
    """A JSON channel may leave out zeros (``{"linear": {"x": 0.5}}``)."""
    convert = REG.dict_converter("geometry_msgs/msg/Twist")
    assert convert is not None
    twist = convert({"linear": {"x": 0.5}, "angular": {"z": -1}})
    assert (twist.linear.x, twist.linear.y, twist.angular.z) == (0.5, 0.0, -1.0)


def test_a_json_schema_type_keeps_its_dict() -> None:
    registry = CodecRegistry()
    registry.add_schema("demo/Status", "jsonschema", '{"type": "object"}')
    assert registry.dict_converter("demo/Status") is None
    assert registry.decoder("demo/Status", "json")(memoryview(b'{"mode": "auto"}')) == {
        "mode": "auto"
    }
    assert registry.dict_converter("nobody/msg/Knows") is None
