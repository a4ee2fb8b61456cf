"""The generated message classes (``ros_mobile_bridge.interfaces``): every
bundled type has a class at its ROS-shaped path, with the bundle's name and
hash; its defaults are the codec's zero message and its ``to_dict`` is what
the CDR decoder gives, for every type (so later the decoders can build the
classes and the CLI's output stays the same); values go through the codec
and back; and the behaviour a ROS user expects (keyword construction, zero
messages for nested fields, constants, ``repr``, equality, copies,
``replace``, pickling, ``MessageError`` naming the field) holds. Importing
``ros_mobile_bridge`` does not import the classes; each class is in its own
module (as rclpy's), and taking one imports its module and those of the types
it holds, not numpy."""

from __future__ import annotations

import copy
import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import inspect
import pickle
import subprocess
import sys
import types
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from _message_classes import generator
from ros_mobile_bridge import MessageError, SchemaError
from ros_mobile_bridge.codec import CodecRegistry, bundled_hash, bundled_interface_names, type_hash
from ros_mobile_bridge.codec._bundled import bundled_interface
from ros_mobile_bridge.codec._interface import interface_definitions
from ros_mobile_bridge.interfaces import RosAction, RosMessage, RosService
from ros_mobile_bridge.interfaces._base import (
    ARRAY,
    MESSAGE,
    SCALAR,
    STRINGS,
    message_class,
    parse_field,
)
from ros_mobile_bridge.interfaces.builtin_interfaces.msg import Time
from ros_mobile_bridge.interfaces.example_interfaces.action import Fibonacci
from ros_mobile_bridge.interfaces.example_interfaces.srv import AddTwoInts
from ros_mobile_bridge.interfaces.geometry_msgs.msg import (
    Point,
    Pose,
    PoseWithCovariance,
    Twist,
    Vector3,
)
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from ros_mobile_bridge.interfaces.rmw_dds_common.msg import NodeEntitiesInfo
from ros_mobile_bridge.interfaces.sensor_msgs.msg import Image, NavSatStatus
from ros_mobile_bridge.interfaces.shape_msgs.msg import SolidPrimitive
from ros_mobile_bridge.interfaces.std_msgs.msg import Empty, Header
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool
from ros_mobile_bridge.interfaces.visualization_msgs.msg import Marker, MarkerArray

PACKAGE = "ros_mobile_bridge.interfaces"
INTERFACES = bundled_interface_names()


def _message_types() -> list[str]:
    """Every message type the bundle defines: messages, services' requests
    and responses, actions' goals, results, feedbacks and the types rcl
    sends them in."""
    names: list[str] = []
    for name in INTERFACES:
        interface = bundled_interface(name)
        assert interface is not None
        names += sorted(interface_definitions(name, interface.text))
    return names


MESSAGE_TYPES = _message_types()
NAMESPACES = sorted(
    [n for n in INTERFACES if n.split("/")[1] != "msg"]
    + [
        f"{n}_{s}"
        for n in INTERFACES
        if n.split("/")[1] == "action"
        for s in ("SendGoal", "GetResult")
    ]
)
CODEC = CodecRegistry()
NO_CDR = frozenset({"example_interfaces/msg/WString"})
"""Types the CDR codec does not support (``wstring``)."""


def _namespace(type_name: str) -> type:
    pkg, kind, name = type_name.split("/")
    found: Any = importlib.import_module(f"{PACKAGE}.{pkg}.{kind}")
    for part in name.split("_"):
        found = getattr(found, part)
    assert isinstance(found, type)
    return found


def same(ours: Any, theirs: Any, path: str = "") -> None:
    """``ours`` and ``theirs`` are the same data: dicts with the same keys in
    the same order, lists, numpy arrays of the same dtype and values,
    scalars of the same type and value."""
    if isinstance(theirs, np.ndarray):
        assert isinstance(ours, np.ndarray), path
        assert ours.dtype == theirs.dtype, path
        assert ours.shape == theirs.shape, path
        assert np.array_equal(ours, theirs), path
    elif isinstance(theirs, dict):
        assert isinstance(ours, dict), path
        assert list(ours) == list(theirs), path
        for key in theirs:
            same(ours[key], theirs[key], f"{path}.{key}")
    elif isinstance(theirs, list):
        assert isinstance(ours, list), path
        assert len(ours) == len(theirs), path
        for index, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            same(a, b, f"{path}[{index}]")
    else:
        assert type(ours) is type(theirs), (path, ours, theirs)
        assert ours == theirs, path


SAMPLES: dict[str, Any] = {
    "bool": True,
    "byte": 200,
    "char": 65,
    "int8": -5,
    "uint8": 250,
    "int16": -300,
    "uint16": 60000,
    "int32": -70000,
    "uint32": 4_000_000_000,
    "int64": -(2**40),
    "uint64": 2**63 + 5,
    "float32": 1.5,
    "float64": -2.25,
    "string": "hé",
    "wstring": "wide",
}
"""A value that is not the default, for each primitive type."""


def sample(cls: type[RosMessage]) -> RosMessage:
    """An instance of ``cls`` whose every field holds something other than
    its default (arrays: their length, or 2 within their bound)."""
    values: dict[str, Any] = {}
    for name, type_ in cls.__ros_fields__:
        info = parse_field(name, type_)
        count = info.size if info.fixed else min(2, info.size or 2)
        if info.kind in (SCALAR, STRINGS):
            value = SAMPLES[info.element]
            if info.string_bound:
                value = value[: info.string_bound]
            values[name] = value if info.kind == SCALAR else [value] * count
        elif info.kind == ARRAY:
            values[name] = [SAMPLES[info.element]] * count
        elif info.kind == MESSAGE:
            values[name] = sample(message_class(info.element))
        else:
            sub = message_class(info.element)
            values[name] = [sample(sub) for _ in range(count)]
    return cls(**values)


# -- every bundled type ----------------------------------------------------------------------


def test_every_bundled_type_is_listed() -> None:
    # 190 messages, 29 services (2 each), 2 actions (8 each)
    assert len(MESSAGE_TYPES) == 264
    assert len(NAMESPACES) == 29 + 2 + 4


@pytest.mark.parametrize("type_name", MESSAGE_TYPES)
def test_every_type_has_a_class_at_its_ros_path_with_its_name_and_hash(type_name: str) -> None:
    pkg, kind, name = type_name.split("/")
    cls = message_class(type_name)
    module = importlib.import_module(f"{PACKAGE}.{pkg}.{kind}")
    # its own module, named as rclpy names it (geometry_msgs.msg._twist)
    stem = generator().module_stem(name.split("_")[0])
    assert cls.__module__ == f"{module.__name__}.{stem}"
    assert cls.__qualname__ == name.replace("_", ".")
    assert _namespace(type_name) is cls
    assert cls.__qualname__.split(".")[0] in module.__all__
    assert cls.__ros_type__ == type_name
    assert cls.__ros_hash__ == bundled_hash(type_name)
    assert cls.__doc__
    assert f"``{type_name}``" in cls.__doc__.split("\n")[0]
    assert set(cls.__slots__) == {n for n, _ in cls.__ros_fields__}  # type: ignore[attr-defined]


@pytest.mark.parametrize("type_name", NAMESPACES)
def test_services_and_actions_nest_their_messages(type_name: str) -> None:
    cls = _namespace(type_name)
    pkg, kind, name = type_name.split("/")
    stem = generator().module_stem(name.split("_")[0])
    assert cls.__module__ == f"{PACKAGE}.{pkg}.{kind}.{stem}"
    assert cls.__ros_type__ == type_name  # type: ignore[attr-defined]
    assert cls.__ros_hash__ == bundled_hash(type_name)  # type: ignore[attr-defined]
    is_service = kind == "srv" or type_name.endswith(("_SendGoal", "_GetResult"))
    parts = ("Request", "Response") if is_service else ("Goal", "Result", "Feedback")
    assert issubclass(cls, RosService if is_service else RosAction)
    for part in parts:
        member = getattr(cls, part)
        assert member.__qualname__ == f"{cls.__qualname__}.{part}"
        assert member.__module__ == cls.__module__
        assert member.__ros_type__ == f"{type_name}_{part}"
    if not is_service:
        assert cls.SendGoal.Request.__qualname__ == f"{cls.__qualname__}.SendGoal.Request"  # type: ignore[attr-defined]
        assert cls.FeedbackMessage.__ros_type__ == f"{type_name}_FeedbackMessage"  # type: ignore[attr-defined]
    with pytest.raises(TypeError, match="type"):
        cls()


@pytest.mark.parametrize("type_name", MESSAGE_TYPES)
def test_defaults_are_the_zero_message_the_decoder_gives(type_name: str) -> None:
    cls = message_class(type_name)
    message = cls()
    if type_name in NO_CDR:
        assert message.to_dict() == CODEC.template(type_name)
        return
    payload = memoryview(CODEC.encoder(type_name, "cdr")({}))
    zero = CODEC.dict_decoder(type_name)(payload)
    same(message.to_dict(), zero)
    assert CODEC.decoder(type_name, "cdr")(payload) == message
    assert cls.from_dict(zero) == message
    assert cls.from_dict({}) == message


@pytest.mark.parametrize("type_name", MESSAGE_TYPES)
def test_values_go_through_the_codec_and_back(type_name: str) -> None:
    cls = message_class(type_name)
    message = sample(cls)
    data = message.to_dict()
    assert cls.from_dict(data) == message
    if type_name in NO_CDR:
        return
    payload = CODEC.encoder(type_name, "cdr")(data)
    assert CODEC.encoder(type_name, "cdr")(message) == payload
    decoded = CODEC.dict_decoder(type_name)(memoryview(payload))
    same(data, decoded)
    instance = CODEC.decoder(type_name, "cdr")(memoryview(payload))
    assert type(instance) is cls
    assert instance == message
    assert cls.from_dict(decoded) == message
    if message.__ros_fields__:
        assert message != cls()


@pytest.mark.parametrize("type_name", MESSAGE_TYPES)
def test_copies_and_pickles_are_equal(type_name: str) -> None:
    cls = message_class(type_name)
    message = sample(cls)
    for protocol in range(2, pickle.HIGHEST_PROTOCOL + 1):
        back = pickle.loads(pickle.dumps(message, protocol))
        assert type(back) is cls
        assert back == message
    assert copy.copy(message) == message
    assert copy.deepcopy(message) == message
    assert message.replace() == message
    assert repr(message).startswith(f"{type_name.split('/')[0]}.{type_name.split('/')[1]}.")


# -- the common types ----------------------------------------------------------------------------


def test_twist_is_built_like_rclpy() -> None:
    twist = Twist(linear=Vector3(x=0.2))
    assert twist.linear.x == 0.2
    assert twist.angular == Vector3()
    assert twist.to_dict() == {
        "linear": {"x": 0.2, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.0},
    }
    assert Twist.__ros_type__ == "geometry_msgs/msg/Twist"
    assert Twist.__ros_hash__.startswith("RIHS01_")
    assert Twist.get_fields_and_field_types() == {
        "linear": "geometry_msgs/msg/Vector3",
        "angular": "geometry_msgs/msg/Vector3",
    }
    # every instance has its own nested messages
    assert Twist().linear is not Twist().linear
    with pytest.raises(TypeError):
        Twist(Vector3())  # type: ignore[misc]  # keyword-only
    with pytest.raises(TypeError):
        Twist(linar=Vector3())  # type: ignore[call-arg]


def test_odometry_nests_and_its_covariances_are_float64_arrays_of_36() -> None:
    odom = Odometry()
    assert odom.pose.pose.position.x == 0.0
    assert odom.pose.pose.orientation.w == 1.0  # the .msg default
    assert odom.header.stamp == Time(sec=0, nanosec=0)
    for covariance in (odom.pose.covariance, odom.twist.covariance):
        assert isinstance(covariance, np.ndarray)
        assert covariance.dtype == np.float64
        assert covariance.shape == (36,)
        assert not covariance.any()
    assert odom.pose.covariance is not Odometry().pose.covariance
    odom.pose.pose.position.x = 1.5
    assert odom.to_dict()["pose"]["pose"]["position"]["x"] == 1.5
    # a 6x6 matrix is taken flattened, as the codec does
    matrix = np.eye(6)
    assert PoseWithCovariance(covariance=matrix).covariance.shape == (36,)
    listed = PoseWithCovariance(covariance=[float(i) for i in range(36)]).covariance
    assert listed.dtype == np.float64
    assert listed[35] == 35.0


def test_image_data_is_a_uint8_array_and_bytes_are_not_copied() -> None:
    image = Image()
    assert image.data.dtype == np.uint8
    assert image.data.shape == (0,)
    frame = bytes(range(12))
    image = Image(height=2, width=2, encoding="rgb8", step=6, data=frame)
    assert image.data.dtype == np.uint8
    assert not image.data.flags.writeable  # a view of the bytes, as the decoder gives
    assert image.data.tobytes() == frame
    # a numpy array of the right dtype is kept as it is (no copy)
    array = np.frombuffer(frame, np.uint8)
    assert Image(data=array).data is array
    assert Image(data=list(frame)).data.tobytes() == frame


def test_header() -> None:
    header = Header(frame_id="map", stamp=Time(sec=3, nanosec=4))
    assert repr(header) == (
        "std_msgs.msg.Header(stamp=builtin_interfaces.msg.Time(sec=3, nanosec=4), frame_id='map')"
    )
    assert Header.__doc__ is not None
    assert "Standard metadata for higher-level stamped data types." in Header.__doc__
    assert "``frame_id``: Transform frame with which this data is associated." in Header.__doc__
    assert Header.from_dict({"frame_id": "odom"}) == Header(frame_id="odom")


def test_constants_are_class_attributes_and_defaults_follow_the_msg_file() -> None:
    assert NavSatStatus.STATUS_NO_FIX == -1
    assert NavSatStatus.STATUS_GBAS_FIX == 2
    assert NavSatStatus.SERVICE_GALILEO == 8
    assert NavSatStatus().status == NavSatStatus.STATUS_UNKNOWN == -2  # "int8 status -2"
    assert "STATUS_FIX" not in NavSatStatus().to_dict()
    assert NavSatStatus.__doc__ is not None
    assert "``STATUS_NO_FIX``: unable to fix position" in NavSatStatus.__doc__
    assert Marker.ARROW == 0
    assert Marker.DELETEALL == 3
    assert Marker().action == Marker.ADD
    assert ParameterDescriptor().read_only is False


def test_services_and_actions() -> None:
    request = AddTwoInts.Request(a=1, b=2)
    assert request.to_dict() == {"a": 1, "b": 2}
    assert AddTwoInts.Response(sum=3).sum == 3
    assert AddTwoInts.__ros_type__ == "example_interfaces/srv/AddTwoInts"
    assert AddTwoInts.Request.__module__ == f"{PACKAGE}.example_interfaces.srv._add_two_ints"
    assert AddTwoInts.Request.__qualname__ == "AddTwoInts.Request"
    assert repr(request) == "example_interfaces.srv.AddTwoInts.Request(a=1, b=2)"
    assert SetBool.Request(data=True).data is True
    goal = Fibonacci.Goal(order=5)
    send = Fibonacci.SendGoal.Request(goal=goal)
    assert send.goal is goal
    assert send.goal_id.uuid.shape == (16,)
    assert Fibonacci.Result().sequence.dtype == np.int32
    assert Fibonacci.GetResult.Response().result == Fibonacci.Result()
    assert Fibonacci.FeedbackMessage().feedback == Fibonacci.Feedback()


def test_empty_messages_have_no_fields() -> None:
    assert Empty().to_dict() == {}
    assert Empty() == Empty()
    assert repr(Empty()) == "std_msgs.msg.Empty()"
    with pytest.raises(TypeError):
        Empty(x=1)  # type: ignore[call-arg]


# -- the generic behaviour -----------------------------------------------------------------------


def test_repr_names_the_type_as_rclpy_does() -> None:
    assert repr(Vector3()) == "geometry_msgs.msg.Vector3(x=0.0, y=0.0, z=0.0)"
    assert repr(Fibonacci.Result(sequence=[1, 1, 2])) == (
        "example_interfaces.action.Fibonacci.Result(sequence=array([1, 1, 2], dtype=int32))"
    )


def test_equality_compares_classes_and_values() -> None:
    assert Vector3(x=1.0) == Vector3(x=1.0)
    assert Vector3(x=1.0) != Vector3(x=2.0)
    assert Vector3() != Point()  # same fields, another type
    assert Vector3() != {"x": 0.0, "y": 0.0, "z": 0.0}
    # arrays by value, whatever their memory
    a = PoseWithCovariance(covariance=np.arange(36.0))
    b = PoseWithCovariance(covariance=list(np.arange(36.0)))
    assert a == b
    b.covariance[3] = -1.0
    assert a != b
    assert Fibonacci.Result(sequence=[1, 2]) != Fibonacci.Result(sequence=[1, 2, 3])
    assert MarkerArray(markers=[Marker(id=1)]) != MarkerArray(markers=[Marker(id=2)])
    with pytest.raises(TypeError, match="unhashable"):
        hash(Vector3())


def test_copy_shares_deepcopy_and_replace_do_not_touch_the_original() -> None:
    original = PoseWithCovariance(covariance=np.zeros(36))
    shallow = copy.copy(original)
    assert shallow == original
    assert shallow.covariance is original.covariance  # a shallow copy, as for any object
    deep = copy.deepcopy(original)
    assert deep.covariance is not original.covariance
    assert deep.pose is not original.pose
    deep.covariance[0] = 1.0
    deep.pose.position.x = 2.0
    assert original.covariance[0] == 0.0
    assert original.pose.position.x == 0.0
    # a deep copy of a read-only (received) array is writable
    frozen = Image(data=b"\x01\x02")
    thawed = copy.deepcopy(frozen)
    thawed.data[0] = 9
    assert frozen.data[0] == 1
    # replace: a new instance, the constructor's checks, the other fields shared
    moved = original.replace(pose=Pose(position=Point(x=3.0)))
    assert moved.pose.position.x == 3.0
    assert original.pose.position.x == 0.0
    assert moved.covariance is original.covariance
    with pytest.raises(MessageError, match="covariance"):
        original.replace(covariance=[0.0])
    with pytest.raises(TypeError):
        original.replace(nosuch=1)
    if sys.version_info >= (3, 13):
        assert copy.replace(original, pose=Pose()).pose == Pose()  # type: ignore[attr-defined]


def test_pickles_keep_the_class_and_nested_service_classes() -> None:
    request = Fibonacci.SendGoal.Request(goal=Fibonacci.Goal(order=7))
    for protocol in range(2, pickle.HIGHEST_PROTOCOL + 1):
        back = pickle.loads(pickle.dumps(request, protocol))
        assert type(back) is Fibonacci.SendGoal.Request
        assert back.goal.order == 7
        assert back == request
    assert pickle.loads(pickle.dumps(AddTwoInts.Request)) is AddTwoInts.Request


def test_each_class_is_in_its_own_module_and_pickles_from_there() -> None:
    interfaces = PACKAGE
    assert Twist.__module__ == f"{interfaces}.geometry_msgs.msg._twist"
    assert AddTwoInts.Request.__module__ == f"{interfaces}.example_interfaces.srv._add_two_ints"
    assert Fibonacci.Goal.__module__ == f"{interfaces}.example_interfaces.action._fibonacci"
    for message in (
        Twist(linear=Vector3(x=0.5)),
        AddTwoInts.Request(a=1, b=2),
        AddTwoInts.Response(sum=3),
        Fibonacci.Goal(order=4),
        Fibonacci.GetResult.Response(status=4, result=Fibonacci.Result(sequence=[0, 1])),
    ):
        for protocol in range(2, pickle.HIGHEST_PROTOCOL + 1):
            data = pickle.dumps(message, protocol)
            assert type(message).__module__.encode() in data
            back = pickle.loads(data)
            assert type(back) is type(message)
            assert back == message
    # a fresh interpreter finds the class from the pickle alone
    data = pickle.dumps([Fibonacci.Goal(order=9), AddTwoInts.Response(sum=5)])
    code = (
        "import pickle, sys\n"
        "goal, response = pickle.loads(sys.stdin.buffer.read())\n"
        "print(type(goal).__qualname__, goal.order, type(response).__qualname__, response.sum)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], input=data, capture_output=True, check=True
    ).stdout.decode()
    assert out.split() == ["Fibonacci.Goal", "9", "AddTwoInts.Response", "5"]


def test_module_names_follow_rosidl() -> None:
    stem = generator().module_stem
    assert stem("Twist") == "_twist"
    assert stem("TwistWithCovariance") == "_twist_with_covariance"
    assert stem("PointCloud2") == "_point_cloud2"
    assert stem("MultiDOFJointTrajectory") == "_multi_dof_joint_trajectory"
    assert stem("UInt8MultiArray") == "_u_int8_multi_array"
    assert stem("Pose2D") == "_pose2_d"
    assert stem("NavSatFix") == "_nav_sat_fix"


def test_make_builds_an_instance_without_the_constructor() -> None:
    vector = Vector3._make(1.0, 2.0, 3.0)
    assert vector == Vector3(x=1.0, y=2.0, z=3.0)
    assert Vector3._make(1.0, 2.0, 3.0) is not vector
    with pytest.raises(TypeError):
        Vector3._make(1.0)
    empty = Empty._make()
    assert empty == Empty()
    # no checks: a decoder hands over what it read
    assert PoseWithCovariance._make(Pose(), [0.0]).covariance == [0.0]


def test_to_dict_gives_the_decoders_shape() -> None:
    marker = Marker(points=[Point(x=1.0)], text="hi", colors=[])
    data = marker.to_dict()
    assert data["points"] == [{"x": 1.0, "y": 0.0, "z": 0.0}]
    assert data["text"] == "hi"
    assert data["header"] == {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}
    # arrays stay numpy arrays, the same objects (as the decoder's dicts hold them)
    image = Image(data=b"abc")
    assert image.to_dict()["data"] is image.data


def test_from_dict_builds_nested_messages_and_names_the_field_it_refuses() -> None:
    odom = Odometry.from_dict(
        {"pose": {"pose": {"position": {"x": 1.0}}}, "child_frame_id": "base"}
    )
    assert odom.pose.pose.position.x == 1.0
    assert odom.child_frame_id == "base"
    assert Odometry.from_dict({"pose": PoseWithCovariance()}) == Odometry()
    array = MarkerArray.from_dict({"markers": [{"id": 1}, Marker(id=2)]})
    assert [m.id for m in array.markers] == [1, 2]
    with pytest.raises(MessageError) as info:
        Odometry.from_dict({"pose": {"pose": {"positon": {}}}})
    assert info.value.field == "pose.pose.positon"
    assert info.value.type_name == "nav_msgs/msg/Odometry"
    assert "unknown field (geometry_msgs/msg/Pose has: position, orientation)" in str(info.value)
    # built, not sent: the text says the value is invalid, not that encoding failed
    assert str(info.value).startswith("invalid nav_msgs/msg/Odometry: field 'pose.pose.positon'")
    with pytest.raises(MessageError) as info:
        MarkerArray.from_dict({"markers": [{}, {"pose": {"position": {"x": 1.0, "w": 2.0}}}]})
    assert info.value.field == "markers[1].pose.position.w"
    with pytest.raises(MessageError) as info:
        Odometry.from_dict({"pose": {"covariance": [0.0] * 3}})
    assert info.value.field == "pose.covariance"
    assert "expected exactly 36 elements, got 3" in str(info.value)
    with pytest.raises(MessageError) as info:
        Odometry.from_dict({"pose": 3})
    assert info.value.field == "pose"
    with pytest.raises(MessageError, match="expected a mapping"):
        Odometry.from_dict([])  # type: ignore[arg-type]


# -- the constructors' checks --------------------------------------------------------------------


def _refused(build: Any, field: str, reason: str, type_name: str) -> None:
    with pytest.raises(MessageError) as info:
        build()
    assert info.value.field == field
    assert info.value.type_name == type_name
    assert reason in info.value.reason
    assert f"field {field!r}" in str(info.value)


def test_a_fixed_size_array_of_the_wrong_length_is_refused() -> None:
    _refused(
        lambda: PoseWithCovariance(covariance=[0.0] * 35),
        "covariance",
        "expected exactly 36 elements, got 35",
        "geometry_msgs/msg/PoseWithCovariance",
    )


def test_a_bounded_sequence_past_its_bound_is_refused() -> None:
    _refused(
        lambda: SolidPrimitive(dimensions=[1.0, 2.0, 3.0, 4.0]),
        "dimensions",
        "expected at most 3 elements, got 4",
        "shape_msgs/msg/SolidPrimitive",
    )
    assert SolidPrimitive(dimensions=[1.0]).dimensions.dtype == np.float64
    _refused(
        lambda: ParameterDescriptor(floating_point_range=[FloatingPointRange()] * 2),
        "floating_point_range",
        "expected at most 1 elements, got 2",
        "rcl_interfaces/msg/ParameterDescriptor",
    )


def test_a_bounded_string_past_its_bound_is_refused() -> None:
    assert NodeEntitiesInfo(node_name="n" * 256).node_name == "n" * 256
    _refused(
        lambda: NodeEntitiesInfo(node_name="n" * 257),
        "node_name",
        "string longer than its bound 256 (257 characters)",
        "rmw_dds_common/msg/NodeEntitiesInfo",
    )


def test_a_nested_message_of_the_wrong_class_is_refused() -> None:
    _refused(
        lambda: Twist(linear={"x": 1.0}),  # type: ignore[arg-type]
        "linear",
        "expected geometry_msgs/msg/Vector3, got dict (a dict converts with Vector3.from_dict)",
        "geometry_msgs/msg/Twist",
    )
    _refused(
        lambda: Twist(linear=Point()),  # type: ignore[arg-type]
        "linear",
        "expected geometry_msgs/msg/Vector3, got Point",
        "geometry_msgs/msg/Twist",
    )
    _refused(
        lambda: MarkerArray(markers=[Marker(), Point()]),  # type: ignore[list-item]
        "markers[1]",
        "expected visualization_msgs/msg/Marker, got Point",
        "visualization_msgs/msg/MarkerArray",
    )
    _refused(
        lambda: MarkerArray(markers=Marker()),  # type: ignore[arg-type]
        "markers",
        "expected a list of visualization_msgs/msg/Marker, got Marker",
        "visualization_msgs/msg/MarkerArray",
    )


def test_an_array_value_that_does_not_fit_its_dtype_is_refused() -> None:
    _refused(
        lambda: Image(data=[1, 300]),
        "data",
        "array values out of range for uint8",
        "sensor_msgs/msg/Image",
    )
    _refused(
        lambda: Fibonacci.Result(sequence=[1.5]),  # type: ignore[list-item]
        "sequence",
        "expected integers (int32), got an array of float64",
        "example_interfaces/action/Fibonacci_Result",
    )
    _refused(
        lambda: Fibonacci.Result(sequence="12"),
        "sequence",
        "expected an array of int32, got str",
        "example_interfaces/action/Fibonacci_Result",
    )
    _refused(
        lambda: Fibonacci.Result(sequence=b"12"),
        "sequence",
        "bytes are only accepted for 8-bit integer arrays",
        "example_interfaces/action/Fibonacci_Result",
    )
    # a numpy array of another dtype is converted when its values fit
    converted = Fibonacci.Result(sequence=np.array([1, 2], np.int64)).sequence
    assert converted.dtype == np.int32


def test_a_string_for_a_list_of_strings_is_refused() -> None:
    from ros_mobile_bridge.interfaces.sensor_msgs.msg import JointState

    assert JointState(name=("a", "b")).name == ["a", "b"]
    _refused(
        lambda: JointState(name="joint"),
        "name",
        "expected a list of str, got str",
        "sensor_msgs/msg/JointState",
    )


# -- a definition of every kind, through the generator ---------------------------------------

KINDS_TEXT = """\
# Every kind of field the generator writes.
# A second line of the header.

int32 COUNT=3          # an int constant
float64 RATIO=0.5
bool ENABLED=True
string GREETING="hello"
byte OCTET=200
char LETTER=65

bool flag true            # a bool with a default
byte octet
char letter
int8 small -5
uint64 big 18446744073709551615
float32 ratio 1.5
float64 gain 2
string name "robot #1"
string<=4 code
bool[] flags
byte[] octets
char[2] letters
int8[] smalls
uint8[<=3] bounded_bytes
int16[] i16
uint16[] u16
int32[3] fixed [1, 2, 3]
uint32[] u32
int64[] i64
uint64[] u64
float32[] f32
float64[<=2] f64 [0.5]
string[] tags ["a", "b"]
string<=3[<=2] codes
string[2] pair
# a field's own comment
geometry_msgs/Point point
geometry_msgs/Point[2] corners
geometry_msgs/Point[<=2] few
builtin_interfaces/Time[] stamps
Other other
"""
TEST_INTERFACES = {
    "test_msgs/msg/Kinds": KINDS_TEXT,
    "test_msgs/msg/Other": "float64 value\nstring[] notes\n",
    "test_msgs/msg/Wide": "wstring wide\nwstring[] wides\n",  # not for the CDR codec
}


class _Generated(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports the generated files of one package from memory."""

    def __init__(self, files: dict[str, str]) -> None:
        self.files = files

    def find_spec(
        self, fullname: str, path: object = None, target: object = None
    ) -> importlib.machinery.ModuleSpec | None:
        rel = fullname.removeprefix(PACKAGE + ".").replace(".", "/")
        if fullname.startswith(PACKAGE + ".") and f"{rel}/__init__.py" in self.files:
            return importlib.util.spec_from_loader(fullname, self, is_package=True)
        if fullname.startswith(PACKAGE + ".") and f"{rel}.py" in self.files:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> None:
        return None

    def exec_module(self, module: types.ModuleType) -> None:
        rel = module.__name__.removeprefix(PACKAGE + ".").replace(".", "/")
        text = self.files.get(f"{rel}.py") or self.files[f"{rel}/__init__.py"]
        exec(compile(text, f"<generated {module.__name__}>", "exec"), module.__dict__)


@pytest.fixture(scope="module")
def test_msgs() -> Iterator[types.ModuleType]:
    """``ros_mobile_bridge.interfaces.test_msgs.msg``, generated from
    :data:`TEST_INTERFACES` and imported from memory."""
    registry = CodecRegistry()
    for name, text in TEST_INTERFACES.items():
        registry.add_schema(name, "ros2msg", text)
    files = generator().generate_from(
        TEST_INTERFACES, {"test_msgs": "test"}, lambda name: type_hash(registry, name)
    )
    assert sorted(files) == [
        "test_msgs/__init__.py",
        "test_msgs/msg/__init__.py",
        "test_msgs/msg/_kinds.py",
        "test_msgs/msg/_other.py",
        "test_msgs/msg/_wide.py",
    ]
    assert "from ._other import Other\n" in files["test_msgs/msg/_kinds.py"]
    package = f"{PACKAGE}.test_msgs"
    finder = _Generated(files)
    sys.meta_path.insert(0, finder)
    try:
        module = importlib.import_module(f"{package}.msg")
        module.__dict__["_registry"] = registry
        yield module
    finally:
        sys.meta_path.remove(finder)
        for name in [n for n in sys.modules if n == package or n.startswith(package + ".")]:
            del sys.modules[name]


def test_every_field_kind_of_a_generated_class(test_msgs: types.ModuleType) -> None:
    kinds = test_msgs.Kinds()
    assert kinds.flag is True
    assert (kinds.small, kinds.big, kinds.ratio, kinds.gain) == (-5, 2**64 - 1, 1.5, 2.0)
    assert type(kinds.gain) is float
    assert kinds.name == "robot #1"
    assert kinds.tags == ["a", "b"]
    assert kinds.tags is not test_msgs.Kinds().tags
    assert kinds.pair == ["", ""]
    assert kinds.fixed.tolist() == [1, 2, 3]
    assert kinds.f64.tolist() == [0.5]
    assert kinds.corners == [Point(), Point()]
    assert kinds.few == []
    assert kinds.other == test_msgs.Other()
    assert test_msgs.Wide().wide == ""
    assert test_msgs.Wide().wides == []
    dtypes = {
        "flags": np.bool_,
        "octets": np.uint8,
        "letters": np.uint8,
        "smalls": np.int8,
        "bounded_bytes": np.uint8,
        "i16": np.int16,
        "u16": np.uint16,
        "fixed": np.int32,
        "u32": np.uint32,
        "i64": np.int64,
        "u64": np.uint64,
        "f32": np.float32,
        "f64": np.float64,
    }
    for name, dtype in dtypes.items():
        assert getattr(kinds, name).dtype == dtype, name
    assert kinds.letters.shape == (2,)
    # constants, with their types
    assert test_msgs.Kinds.COUNT == 3
    assert test_msgs.Kinds.RATIO == 0.5
    assert test_msgs.Kinds.ENABLED is True
    assert test_msgs.Kinds.GREETING == "hello"
    assert (test_msgs.Kinds.OCTET, test_msgs.Kinds.LETTER) == (200, 65)
    # the comments
    doc = inspect.getdoc(test_msgs.Kinds)  # (3.13 dedents __doc__ itself, older ones do not)
    assert doc is not None
    assert "Every kind of field the generator writes.\nA second line of the header." in doc
    assert "``COUNT``: an int constant" in doc
    assert "``point``: a field's own comment" in doc
    registry = test_msgs.__dict__["_registry"]
    assert test_msgs.Kinds.__ros_hash__ == type_hash(registry, "test_msgs/msg/Kinds")


def test_a_generated_class_checks_its_bounds(test_msgs: types.ModuleType) -> None:
    kinds_type = "test_msgs/msg/Kinds"
    _refused(
        lambda: test_msgs.Kinds(code="abcde"),
        "code",
        "string longer than its bound 4 (5 characters)",
        kinds_type,
    )
    _refused(
        lambda: test_msgs.Kinds(codes=["abc", "abcd"]),
        "codes[1]",
        "string longer than its bound 3 (4 characters)",
        kinds_type,
    )
    _refused(
        lambda: test_msgs.Kinds(codes=["a", "b", "c"]),
        "codes",
        "expected at most 2 elements, got 3",
        kinds_type,
    )
    _refused(
        lambda: test_msgs.Kinds(pair=["a"]),
        "pair",
        "expected exactly 2 elements, got 1",
        kinds_type,
    )
    _refused(
        lambda: test_msgs.Kinds(corners=[Point()]),
        "corners",
        "expected exactly 2 elements, got 1",
        kinds_type,
    )
    _refused(
        lambda: test_msgs.Kinds(few=[Point()] * 3),
        "few",
        "expected at most 2 elements, got 3",
        kinds_type,
    )
    _refused(
        lambda: test_msgs.Kinds(bounded_bytes=b"1234"),
        "bounded_bytes",
        "expected at most 3 elements, got 4",
        kinds_type,
    )
    _refused(lambda: test_msgs.Kinds(flags=[0, 2]), "flags", "expected bools", kinds_type)
    assert test_msgs.Kinds(flags=[0, 1]).flags.tolist() == [False, True]
    _refused(
        lambda: test_msgs.Kinds(f32=[1e300]),
        "f32",
        "array values out of range for float32",
        kinds_type,
    )
    _refused(
        lambda: test_msgs.Kinds.from_dict({"other": {"value": 1.0, "values": [1.0]}}),
        "other.values",
        "unknown field (test_msgs/msg/Other has: value, notes)",
        kinds_type,
    )


def test_a_generated_class_round_trips_through_the_codec(test_msgs: types.ModuleType) -> None:
    registry = test_msgs.__dict__["_registry"]
    kinds = sample(test_msgs.Kinds)
    assert test_msgs.Kinds.__module__ == f"{test_msgs.__name__}._kinds"
    payload = registry.encoder("test_msgs/msg/Kinds", "cdr")(kinds.to_dict())
    decoded = registry.dict_decoder("test_msgs/msg/Kinds")(memoryview(payload))
    assert test_msgs.Kinds.from_dict(decoded) == kinds
    same(kinds.to_dict(), decoded)
    assert pickle.loads(pickle.dumps(kinds)) == kinds


def test_the_generator_refuses_a_field_named_like_a_method() -> None:
    with pytest.raises(SystemExit, match="cannot name a field 'replace'"):
        generator().generate_from(
            {"test_msgs/msg/Bad": "int32 replace\n"}, {"test_msgs": "test"}, lambda _: "RIHS01_"
        )


# -- what importing costs ------------------------------------------------------------------------


def _run(code: str) -> list[str]:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split("\n")


def test_importing_the_library_does_not_import_the_classes_nor_them_numpy() -> None:
    code = (
        "import sys\n"
        "import ros_mobile_bridge\n"
        "print('ros_mobile_bridge.interfaces' in sys.modules)\n"
        "from ros_mobile_bridge.interfaces.geometry_msgs.msg import PoseStamped, PoseWithCovariance\n"
        "print(sorted(m for m in ('numpy', 'rosbags', 'ros_mobile_bridge.codec',\n"
        "    'ros_mobile_bridge.interfaces.std_msgs.msg') if m in sys.modules))\n"
        "PoseStamped()\n"
        "print('numpy' in sys.modules, 'ros_mobile_bridge.interfaces.std_msgs.msg' in sys.modules)\n"
        "PoseWithCovariance()\n"
        "print('numpy' in sys.modules)\n"
    )
    out = _run(code)
    # the library alone: no classes; geometry_msgs: no numpy, no codec, not even std_msgs
    # (Header loads when a message needs it); numpy loads with the first array
    assert out[:4] == ["False", "[]", "False True", "True"]


def test_taking_one_class_imports_only_its_module_and_those_it_refers_to() -> None:
    code = (
        "import sys\n"
        "import ros_mobile_bridge\n"
        "before = set(sys.modules)\n"
        "from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist\n"
        "print(' '.join(sorted(set(sys.modules) - before)))\n"
        "Twist()\n"
        "print(' '.join(sorted(set(sys.modules) - before)))\n"
        "from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry\n"
        "before = set(sys.modules)\n"
        "Odometry()\n"
        "print(' '.join(sorted(set(sys.modules) - before)))\n"
    )
    out = _run(code)
    base = "ros_mobile_bridge.interfaces"
    twist = [
        base,
        f"{base}._base",
        f"{base}.geometry_msgs",
        f"{base}.geometry_msgs.msg",
        f"{base}.geometry_msgs.msg._twist",
        f"{base}.geometry_msgs.msg._vector3",
    ]
    for line in out[:2]:  # building one needs nothing more
        loaded = line.split()
        assert [m for m in loaded if m.startswith(base)] == twist
        assert [
            m for m in loaded if m.startswith(("numpy", "rosbags", "ros_mobile_bridge.codec"))
        ] == []
    # building an Odometry loads the types it refers to (other packages' on first use),
    # and no others (Twist and Vector3 are there already)
    assert [m for m in out[2].split() if m.startswith(base)] == [
        f"{base}.builtin_interfaces",
        f"{base}.builtin_interfaces.msg",
        f"{base}.builtin_interfaces.msg._time",
        *(
            f"{base}.geometry_msgs.msg.{stem}"
            for stem in (
                "_point",
                "_pose",
                "_pose_with_covariance",
                "_quaternion",
                "_twist_with_covariance",
            )
        ),
        f"{base}.std_msgs.msg",
        f"{base}.std_msgs.msg._header",
    ]


def test_message_class_finds_derived_types_and_refuses_the_rest() -> None:
    assert message_class("example_interfaces/srv/AddTwoInts_Request") is AddTwoInts.Request
    assert message_class("example_interfaces/action/Fibonacci_SendGoal_Response") is (
        Fibonacci.SendGoal.Response
    )
    for name in (
        "nosuch_msgs/msg/Thing",
        "geometry_msgs/msg/Nope",
        "geometry_msgs/Twist",
        "example_interfaces/srv/AddTwoInts",  # a service, not a message
        "geometry_msgs/_base/Twist",
    ):
        with pytest.raises(SchemaError, match="no message class"):
            message_class(name)
