"""The generated CDR codec of the message classes (``codec._cdr``): for every
bundled message type, a random instance encodes byte for byte as rosbags'
``serialize_cdr`` encodes the same message, and decodes back equal (from the
little-endian payload and from rosbags' big-endian one); the class decoder
and the dict decoder agree on valid and on random payloads; a bad payload
(cut short at any length, bytes left over, bad UTF-8, a string without its
terminator) raises ``DecodeError`` and nothing else; a value that does not
fit raises ``MessageError`` naming the field; arrays are views of the
payload."""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge import DecodeError, MessageError, SchemaError
from ros_mobile_bridge.codec import CodecRegistry, bundled_interface_names
from ros_mobile_bridge.codec._bundled import bundled_interface
from ros_mobile_bridge.codec._cdr import build_class_decoder
from ros_mobile_bridge.codec._cdr_encode import build_class_encoder
from ros_mobile_bridge.codec._cdr_layout import DTYPES
from ros_mobile_bridge.codec._convert import build_builder
from ros_mobile_bridge.codec._interface import interface_definitions
from ros_mobile_bridge.codec._model import ARRAY, INT_RANGES, SCALAR, MsgDef
from ros_mobile_bridge.interfaces import RosMessage
from ros_mobile_bridge.interfaces._base import message_class
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Point, Pose, PoseWithCovariance
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.sensor_msgs.msg import Image, JointState
from ros_mobile_bridge.interfaces.std_msgs.msg import Header, String
from ros_mobile_bridge.interfaces.tf2_msgs.msg import TFMessage

REGISTRY = CodecRegistry()
NO_CDR = frozenset({"example_interfaces/msg/WString"})
"""Types the CDR codecs refuse (``wstring``, as rosbags' CDR code does)."""


def _message_types() -> list[str]:
    names: list[str] = []
    for name in bundled_interface_names():
        interface = bundled_interface(name)
        assert interface is not None
        names += sorted(interface_definitions(name, interface.text))
    return names


MESSAGE_TYPES = [n for n in _message_types() if n not in NO_CDR]


class Codec:
    """One type's codecs: ours, the dict ones and rosbags'."""

    def __init__(self, name: str) -> None:
        key, msgdef = REGISTRY._find_ros(name)
        self.key = key
        self.defs: dict[str, MsgDef] = REGISTRY._closure(key, msgdef)
        self.cls: Any = message_class(key)
        self.decode: Callable[[Any], Any] = build_class_decoder(key, self.defs, message_class)
        self.encode: Callable[[Any], bytes] = build_class_encoder(key, self.defs, message_class)
        self.dict_decode = REGISTRY.dict_decoder(key)
        gen = REGISTRY._prepare(key, msgdef)
        self.store = gen.store
        self.build = build_builder(key, gen.defs, gen.store.types, gen.builders)

    def rosbags(self, message: RosMessage, *, little: bool = True) -> bytes:
        """rosbags' encoding of the message ``message`` is."""
        native = self.build(message.to_dict())
        return bytes(self.store.serialize_cdr(native, self.key, little_endian=little))


@functools.cache
def codec(name: str) -> Codec:
    return Codec(name)


# -- instances drawn from the definitions ----------------------------------------------------

_TEXT = st.text(st.characters(codec="utf-8"), max_size=12)


def _element(base: str, bound: int) -> st.SearchStrategy[Any]:
    if base == "string":
        return st.text(st.characters(codec="utf-8"), max_size=bound) if bound else _TEXT
    if base == "bool":
        return st.booleans()
    if base == "float64":
        return st.floats()
    if base == "float32":
        return st.floats(width=32)
    low, high = (0, 255) if base in ("byte", "char") else INT_RANGES[base]
    return st.integers(low, high)


@functools.cache
def instances(name: str) -> st.SearchStrategy[RosMessage]:
    """Random instances of type ``name``: every field drawn within its type,
    arrays within their length or bound (sequences of at most 3)."""
    c = codec(name)
    return _instances(name, c.defs)


def _instances(name: str, defs: dict[str, MsgDef]) -> st.SearchStrategy[RosMessage]:
    cls = message_class(name)
    fields: dict[str, st.SearchStrategy[Any]] = {}
    for (attr, _type), spec in zip(cls.__ros_fields__, defs[name].visible_fields, strict=True):
        if spec.ref is not None:
            item = _instances(spec.ref, defs)
        else:
            assert spec.base is not None
            item = _element(spec.base, spec.string_bound)
        if spec.cardinality == SCALAR:
            fields[attr] = item
            continue
        if spec.cardinality == ARRAY:
            low = high = spec.size
        else:
            low, high = 0, min(spec.size or 3, 3)
        items = st.lists(item, min_size=low, max_size=high)
        if spec.ref is None and spec.base != "string":
            assert spec.base is not None
            dtype = np.dtype(DTYPES[spec.base])
            items = items.map(functools.partial(np.array, dtype=dtype))
        fields[attr] = items
    return st.builds(cls, **fields)


def same(ours: Any, theirs: Any, path: str = "") -> None:
    """Equal values (NaN equal to NaN, arrays of the same dtype and values)."""
    if isinstance(theirs, np.ndarray):
        assert isinstance(ours, np.ndarray), path
        assert ours.dtype == theirs.dtype and ours.shape == theirs.shape, path
        assert np.array_equal(ours, theirs, equal_nan=ours.dtype.kind == "f"), path
    elif isinstance(theirs, dict):
        assert list(ours) == list(theirs), path
        for key in theirs:
            same(ours[key], theirs[key], f"{path}.{key}")
    elif isinstance(theirs, list):
        assert isinstance(ours, list) and len(ours) == len(theirs), path
        for index, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            same(a, b, f"{path}[{index}]")
    elif isinstance(theirs, float) and math.isnan(theirs):
        assert isinstance(ours, float) and math.isnan(ours), path
    else:
        assert type(ours) is type(theirs) and ours == theirs, (path, ours, theirs)


# -- every bundled type ----------------------------------------------------------------------


def test_every_bundled_message_type_is_covered() -> None:
    assert len(MESSAGE_TYPES) == 263


@pytest.mark.parametrize("name", MESSAGE_TYPES)
def test_round_trip_as_rosbags_encodes(name: str) -> None:
    c = codec(name)

    @settings(
        max_examples=examples(8),
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
        database=None,
    )
    @given(message=instances(name))
    def check(message: RosMessage) -> None:
        payload = c.encode(message)
        assert type(payload) is bytes
        assert payload == c.rosbags(message)
        back = c.decode(payload)
        assert type(back) is c.cls
        same(back.to_dict(), message.to_dict())
        # the dict decoder reads the same payload as the same message
        same(back.to_dict(), c.dict_decode(memoryview(payload)))
        # rosbags' big-endian encoding of it decodes to it too
        same(c.decode(c.rosbags(message, little=False)).to_dict(), message.to_dict())

    check()


@pytest.mark.parametrize("name", MESSAGE_TYPES)
def test_the_zero_message_round_trips(name: str) -> None:
    c = codec(name)
    message = c.cls()
    payload = c.encode(message)
    assert payload == c.rosbags(message)
    assert c.decode(memoryview(payload)) == message


def test_wstring_types_are_refused_when_built() -> None:
    key, msgdef = REGISTRY._find_ros("example_interfaces/msg/WString")
    defs = REGISTRY._closure(key, msgdef)
    with pytest.raises(SchemaError, match="wstring"):
        build_class_decoder(key, defs, message_class)
    with pytest.raises(SchemaError, match="wstring"):
        build_class_encoder(key, defs, message_class)


# -- the two decoders agree ------------------------------------------------------------------

SAMPLE = [
    "std_msgs/msg/String",
    "nav_msgs/msg/Odometry",
    "sensor_msgs/msg/JointState",
    "sensor_msgs/msg/PointCloud2",
    "tf2_msgs/msg/TFMessage",
    "diagnostic_msgs/msg/DiagnosticArray",
    "visualization_msgs/msg/Marker",
    "std_msgs/msg/Empty",
]


def _outcome(decode: Callable[[Any], Any], payload: bytes) -> Any:
    try:
        value = decode(memoryview(payload))
    except DecodeError:
        return DecodeError
    return value.to_dict() if isinstance(value, RosMessage) else value


@pytest.mark.parametrize("name", SAMPLE)
def test_the_class_and_dict_decoders_agree_on_random_payloads(name: str) -> None:
    c = codec(name)

    @settings(max_examples=examples(60), deadline=None, database=None)
    @given(
        base=instances(name),
        cut=st.integers(0, 64),
        noise=st.binary(max_size=64),
        at=st.integers(0, 200),
        big=st.booleans(),
    )
    def check(base: RosMessage, cut: int, noise: bytes, at: int, big: bool) -> None:
        payload = bytearray(c.rosbags(base, little=not big))
        # overwrite some bytes of the body, then maybe cut it short
        at = 4 + at % max(1, len(payload) - 4)
        payload[at : at + len(noise)] = noise
        payload = payload[: max(4, len(payload) - cut)]
        ours = _outcome(c.decode, bytes(payload))
        theirs = _outcome(c.dict_decode, bytes(payload))
        if ours is DecodeError or theirs is DecodeError:
            assert ours is theirs
        else:
            same(ours, theirs)

    check()


# -- bad payloads ----------------------------------------------------------------------------


def _odometry() -> Odometry:
    header = Header(frame_id="odom")
    header.stamp.sec = 7
    return Odometry(
        header=header,
        child_frame_id="base_link",
        pose=PoseWithCovariance(
            pose=Pose(position=Point(x=1.0, y=2.0)), covariance=np.arange(36.0)
        ),
    )


SHAPES = {
    "std_msgs/msg/String": String(data="hello"),
    "nav_msgs/msg/Odometry": _odometry(),
    "sensor_msgs/msg/JointState": JointState(
        name=["a", "bc", "def"], position=[1.0, 2.0, 3.0], effort=[0.5]
    ),
    "tf2_msgs/msg/TFMessage": TFMessage.from_dict(
        {"transforms": [{"child_frame_id": "x"}, {"child_frame_id": "yz"}]}
    ),
    "sensor_msgs/msg/Image": Image(height=2, width=2, encoding="mono8", step=2, data=b"abcd"),
}


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_every_truncation_raises_decode_error(name: str) -> None:
    c = codec(name)
    payload = c.encode(SHAPES[name])
    for size in range(len(payload)):
        # the last 3 bytes may be padding: a payload without them still decodes
        try:
            c.decode(payload[:size])
        except DecodeError:
            continue
        assert size >= len(payload) - 3, size
        assert c.decode(payload[:size]) == SHAPES[name]


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_bytes_left_over_raise(name: str) -> None:
    c = codec(name)
    payload = c.encode(SHAPES[name])
    assert c.decode(payload + b"\0\0\0") == SHAPES[name]  # padding to a multiple of 4
    with pytest.raises(DecodeError, match="left over"):
        c.decode(payload + b"\0" * 4)


def test_bad_strings_raise() -> None:
    c = codec("std_msgs/msg/String")
    good = c.encode(String(data="ab"))
    assert good == b"\0\1\0\0" + struct.pack("<I", 3) + b"ab\0"
    bad = {
        "not UTF-8": b"\0\1\0\0" + struct.pack("<I", 3) + b"\xff\xfe\0",
        "no terminator": b"\0\1\0\0" + struct.pack("<I", 3) + b"abc",
        "length 0": b"\0\1\0\0" + struct.pack("<I", 0),
        "length past the end": b"\0\1\0\0" + struct.pack("<I", 9) + b"ab\0",
        "huge length": b"\0\1\0\0" + struct.pack("<I", 0xFFFFFFFF) + b"ab\0",
    }
    for what, payload in bad.items():
        for form in (payload, memoryview(payload), bytearray(payload)):
            with pytest.raises(DecodeError, match="std_msgs/msg/String"):
                c.decode(form)
            assert what


def test_bad_headers_raise() -> None:
    c = codec("nav_msgs/msg/Odometry")
    payload = c.encode(_odometry())
    for head, match in (
        (b"", "not a CDR payload"),
        (b"\0", "not a CDR payload"),
        (b"\1\1\0\0", "not a CDR payload"),
        (b"\0\2\0\0", "unsupported CDR encapsulation"),
    ):
        with pytest.raises(DecodeError, match=match):
            c.decode(head + payload[len(head) :] if len(head) == 4 else head)


def test_big_endian_payloads_decode_with_native_arrays() -> None:
    c = codec("nav_msgs/msg/Odometry")
    message = _odometry()
    big = c.rosbags(message, little=False)
    assert big[:2] == b"\0\0"
    back = c.decode(big)
    assert back == message
    assert back.pose.covariance.dtype == np.dtype("float64")
    assert back.pose.covariance.dtype.isnative


def test_other_buffers_decode() -> None:
    c = codec("sensor_msgs/msg/JointState")
    message = SHAPES["sensor_msgs/msg/JointState"]
    payload = c.encode(message)
    for form in (
        payload,
        bytearray(payload),
        memoryview(payload),
        memoryview(bytearray(payload)).cast("b"),
        np.frombuffer(payload, np.uint8),
    ):
        assert c.decode(form) == message
    with pytest.raises(DecodeError, match="contiguous"):
        c.decode(memoryview(payload * 2)[::2])
    for junk in ("text", 3, None):
        with pytest.raises(DecodeError, match="byte buffer"):
            c.decode(junk)


def test_arrays_are_views_of_the_payload() -> None:
    c = codec("sensor_msgs/msg/Image")
    data = np.arange(640 * 480 * 3, dtype=np.uint8)
    image = Image(height=480, width=640, encoding="rgb8", step=1920, data=data)
    payload = c.encode(image)
    view = memoryview(payload)
    back = c.decode(view)
    assert np.shares_memory(back.data, np.frombuffer(payload, np.uint8))
    assert not back.data.flags.writeable  # a view of bytes
    writable = bytearray(payload)
    assert c.decode(writable).data.flags.writeable
    assert back == image


# -- encoder errors name the field -----------------------------------------------------------


def _refused(name: str, message: Any, field: str | None, reason: str) -> None:
    with pytest.raises(MessageError, match=reason) as info:
        codec(name).encode(message)
    assert info.value.field == field
    assert info.value.type_name == name


def test_a_fixed_array_of_the_wrong_length_is_refused() -> None:
    message = _odometry()
    message.pose.covariance = np.zeros(35)
    _refused("nav_msgs/msg/Odometry", message, "pose.covariance", "exactly 36")


def test_an_int_out_of_range_is_refused() -> None:
    image = Image()
    image.is_bigendian = 256
    _refused("sensor_msgs/msg/Image", image, "is_bigendian", "out of range for uint8")
    image.is_bigendian = -1
    _refused("sensor_msgs/msg/Image", image, "is_bigendian", "out of range for uint8")
    image.is_bigendian = 1.0  # type: ignore[assignment]
    _refused("sensor_msgs/msg/Image", image, "is_bigendian", "expected an integer")


def test_a_str_in_a_float_field_is_refused() -> None:
    message = _odometry()
    message.pose.pose.position.x = "1.0"  # type: ignore[assignment]
    _refused("nav_msgs/msg/Odometry", message, "pose.pose.position.x", "expected a number")


def test_a_nested_message_of_the_wrong_class_is_refused() -> None:
    message = _odometry()
    message.pose.pose = Point()  # type: ignore[assignment]
    _refused("nav_msgs/msg/Odometry", message, "pose.pose", "expected geometry_msgs/msg/Pose")
    tf = TFMessage.from_dict({"transforms": [{}, {}]})
    tf.transforms[1] = Header()  # type: ignore[call-overload]
    _refused("tf2_msgs/msg/TFMessage", tf, "transforms[1]", "expected geometry_msgs")
    _refused("std_msgs/msg/String", {"data": "x"}, None, "from_dict")


def test_strings_and_bounds_are_checked() -> None:
    _refused("std_msgs/msg/String", String(data=b"x"), "data", "expected a str")  # type: ignore[arg-type]
    _refused("std_msgs/msg/String", String(data="\ud800"), "data", "UTF-8")
    joints = JointState(name=["a"])
    joints.name = "ab"  # type: ignore[assignment]
    _refused("sensor_msgs/msg/JointState", joints, "name", "list of str")
    joints.name = ["a", 3]  # type: ignore[list-item]
    _refused("sensor_msgs/msg/JointState", joints, "name[1]", "expected a str")


def test_what_the_constructor_accepts_encodes_as_it_would() -> None:
    c = codec("sensor_msgs/msg/Image")
    image = Image(height=1, width=4, encoding="mono8", step=4, data=b"abcd")
    expected = c.encode(image)
    image.data = b"abcd"  # type: ignore[assignment]
    assert c.encode(image) == expected
    image.data = [97, 98, 99, 100]  # type: ignore[assignment]
    assert c.encode(image) == expected
    image.data = np.array([[97, 98], [99, 100]], dtype=np.uint8)
    assert c.encode(image) == expected
    image.data = np.arange(97, 105, dtype=np.uint8)[::2]  # not contiguous: a, c, e, g
    assert c.encode(image) == expected.replace(b"abcd", b"aceg")
    odom = codec("nav_msgs/msg/Odometry")
    message = _odometry()
    expected = odom.encode(message)
    message.pose.covariance = tuple(range(36))  # type: ignore[assignment]
    assert odom.encode(message) == expected
    message.pose.covariance = np.arange(72.0)[::2] / 2  # strided
    assert odom.encode(message) == expected
    message.pose.covariance = np.arange(36.0).astype(">f8")  # other byte order
    assert odom.encode(message) == expected
    flag = codec("std_msgs/msg/Bool")
    assert flag.encode(flag.cls(data=np.True_)) == flag.encode(flag.cls(data=True))
    wrong = flag.cls()
    wrong.data = "yes"
    _refused("std_msgs/msg/Bool", wrong, "data", "expected a bool")
