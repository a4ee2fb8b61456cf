"""Message classes for types learnt at run time (``codec._classes.class_for``):
the bundled class for the bundled definitions, else a class made from the
definitions by the emitter the generated modules come from, behaving as a
generated class, cached per type and exact definitions."""

from __future__ import annotations

import copy
import os
import pickle
import subprocess
import sys
import threading
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pytest

from ros_mobile_bridge import MessageError, SchemaError
from ros_mobile_bridge.codec import CodecRegistry, _classes, type_hash
from ros_mobile_bridge.codec._bundled import bundled_definition
from ros_mobile_bridge.codec._classes import RUNTIME_CLASSES, class_for
from ros_mobile_bridge.codec._interface import interface_definitions
from ros_mobile_bridge.codec._lru import LruCache
from ros_mobile_bridge.codec._model import MsgDef
from ros_mobile_bridge.codec._parse import parse_ros2msg
from ros_mobile_bridge.codec._typehash import definitions_hash
from ros_mobile_bridge.interfaces import RosMessage
from ros_mobile_bridge.interfaces.example_interfaces.action import Fibonacci
from ros_mobile_bridge.interfaces.example_interfaces.srv import AddTwoInts
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Point, Twist
from ros_mobile_bridge.interfaces.unique_identifier_msgs.msg import UUID

RUNTIME = "ros_mobile_bridge.interfaces._runtime"

STATUS = """\
# A robot's status.
uint8 IDLE=0
uint8 BUSY=1
string NAME="status #1"
float64 LIMIT=2.5
uint8 state 1
float64 speed 0.5
string<=4 code "ab"
string[<=2] tags ["a", "b"]
int32[3] pair [1, 2, 3]
float32[] gains
uint8[<=4] raw
geometry_msgs/Point[2] corners
geometry_msgs/Point[<=2] few
my_msgs/Part part
"""
PART = "float64 value\nstring[] notes\n"


def with_bundled(defs: Mapping[str, MsgDef]) -> dict[str, MsgDef]:
    """``defs`` and the bundled definition of every type they use that they lack."""
    out = dict(defs)
    stack = list(out.values())
    while stack:
        for ref in stack.pop().refs():
            if ref not in out:
                found = bundled_definition(ref)
                assert found is not None, ref
                out[ref] = found
                stack.append(found)
    return out


def parsed(name: str, text: str, **more: str) -> dict[str, MsgDef]:
    """The definitions of the ``.msg`` ``text`` of ``name`` and of ``more``
    (name with ``/`` as ``__``), and the bundled ones they use."""
    defs = parse_ros2msg(name, text)[1]
    for other, other_text in more.items():
        defs.update(parse_ros2msg(other.replace("__", "/"), other_text)[1])
    return with_bundled(defs)


def status_defs(package: str = "my_msgs") -> dict[str, MsgDef]:
    status = STATUS.replace("my_msgs/", f"{package}/")
    return parsed(f"{package}/msg/Status", status, **{f"{package}__msg__Part": PART})


def registry_hash(name: str, texts: Mapping[str, str]) -> str:
    registry = CodecRegistry()
    for type_name, text in texts.items():
        registry.add_schema(type_name, "ros2msg", text)
    return type_hash(registry, name)


# -- the bundled classes ---------------------------------------------------------------------


def test_the_bundled_definitions_give_the_bundled_classes() -> None:
    twist = with_bundled({"geometry_msgs/msg/Twist": bundled_definition("geometry_msgs/msg/Twist")})
    assert class_for("geometry_msgs/msg/Twist", twist) is Twist
    # other entries are ignored; derived types of services and actions too
    assert class_for("geometry_msgs/msg/Vector3", twist).__module__.endswith("._vector3")
    # comments are no part of a definition: the text without them is the bundled one
    text = "int64 a\nint64 b\n---\nint64 sum\n"
    srv = interface_definitions("example_interfaces/srv/AddTwoInts", text)
    assert class_for("example_interfaces/srv/AddTwoInts_Request", srv) is AddTwoInts.Request
    assert class_for("example_interfaces/srv/AddTwoInts_Response", srv) is AddTwoInts.Response
    srv = interface_definitions("example_interfaces/srv/AddTwoInts", "int32 a\nint64 b\n---\n")
    assert class_for("example_interfaces/srv/AddTwoInts_Request", srv) is not AddTwoInts.Request
    name = "example_interfaces/action/Fibonacci_FeedbackMessage"
    feedback = with_bundled({name: bundled_definition(name)})  # type: ignore[dict-item]
    assert class_for(name, feedback) is Fibonacci.FeedbackMessage


def test_a_changed_definition_gives_a_class_made_at_run_time() -> None:
    defs = parsed(
        "geometry_msgs/msg/Twist",
        "Vector3 linear\nVector3 angular\n",
        geometry_msgs__msg__Vector3="float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
    )
    cls = class_for("geometry_msgs/msg/Twist", defs)
    assert cls is not Twist and issubclass(cls, RosMessage)
    assert cls.__module__ == RUNTIME
    assert cls.__qualname__ == cls.__name__ == "Twist"
    assert cls.__ros_type__ == "geometry_msgs/msg/Twist"
    assert cls.__ros_hash__ != Twist.__ros_hash__
    assert cls.__ros_hash__ == registry_hash(
        "geometry_msgs/msg/Twist",
        {
            "geometry_msgs/msg/Twist": "Vector3 linear\nVector3 angular\n",
            "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
        },
    )
    twist = cls()
    vector = class_for("geometry_msgs/msg/Vector3", defs)
    assert type(twist.linear) is vector  # the nested class is class_for's for its closure
    assert vector.__ros_fields__[-1] == ("w", "float64")
    assert repr(twist) == (
        "geometry_msgs.msg.Twist(linear=geometry_msgs.msg.Vector3(x=0.0, y=0.0, z=0.0, w=0.0), "
        "angular=geometry_msgs.msg.Vector3(x=0.0, y=0.0, z=0.0, w=0.0))"
    )
    # the same definitions, parsed again: the same class object
    again = parsed(
        "geometry_msgs/msg/Twist",
        "Vector3 linear\nVector3 angular\n",
        geometry_msgs__msg__Vector3="float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
    )
    assert class_for("geometry_msgs/msg/Twist", again) is cls
    # a bundled type it uses stays the bundled class
    pose = parsed("my_msgs/msg/Spot", "geometry_msgs/Point where\nint8 level\n")
    assert type(class_for("my_msgs/msg/Spot", pose)().where) is Point


def test_a_run_time_class_is_shaped_as_a_generated_one() -> None:
    cls = class_for("my_msgs/msg/Status", status_defs())
    assert cls.__slots__ == (  # type: ignore[attr-defined]
        "code",
        "corners",
        "few",
        "gains",
        "pair",
        "part",
        "raw",
        "speed",
        "state",
        "tags",
    )
    assert cls.__ros_fields__ == (
        ("state", "uint8"),
        ("speed", "float64"),
        ("code", "string<=4"),
        ("tags", "string[<=2]"),
        ("pair", "int32[3]"),
        ("gains", "float32[]"),
        ("raw", "uint8[<=4]"),
        ("corners", "geometry_msgs/msg/Point[2]"),
        ("few", "geometry_msgs/msg/Point[<=2]"),
        ("part", "my_msgs/msg/Part"),
    )
    assert cls.get_fields_and_field_types()["pair"] == "int32[3]"
    assert cls.__ros_hash__ == registry_hash(
        "my_msgs/msg/Status", {"my_msgs/msg/Status": STATUS, "my_msgs/msg/Part": PART}
    )
    assert cls.__ros_hash__ == definitions_hash("my_msgs/msg/Status", status_defs())
    # the constants, with their types
    assert (cls.IDLE, cls.BUSY, cls.NAME, cls.LIMIT) == (0, 1, "status #1", 2.5)  # type: ignore[attr-defined]
    assert type(cls.LIMIT) is float  # type: ignore[attr-defined]
    # the defaults
    status = cls()
    assert not hasattr(status, "__dict__")
    assert (status.state, status.speed, status.code) == (1, 0.5, "ab")  # type: ignore[attr-defined]
    assert status.tags == ["a", "b"]  # type: ignore[attr-defined]
    assert status.tags is not cls().tags  # type: ignore[attr-defined]
    assert status.pair.tolist() == [1, 2, 3] and status.pair.dtype == np.int32  # type: ignore[attr-defined]
    assert status.gains.dtype == np.float32 and status.gains.shape == (0,)  # type: ignore[attr-defined]
    assert status.corners == [Point(), Point()] and status.few == []  # type: ignore[attr-defined]
    part = class_for("my_msgs/msg/Part", status_defs())
    assert status.part == part() and type(status.part) is part  # type: ignore[attr-defined]
    assert repr(part()) == "my_msgs.msg.Part(value=0.0, notes=[])"
    with pytest.raises(TypeError):
        cls(nope=1)
    with pytest.raises(TypeError):
        cls(1)


def _refused(call: object, field: str, reason: str) -> None:
    with pytest.raises(MessageError) as info:
        call()  # type: ignore[operator]
    assert info.value.field == field
    assert reason in info.value.reason


def test_the_constructor_checks_as_a_generated_one_does() -> None:
    cls = class_for("my_msgs/msg/Status", status_defs())
    part = class_for("my_msgs/msg/Part", status_defs())
    _refused(lambda: cls(code="abcde"), "code", "string longer than its bound 4")
    _refused(lambda: cls(tags=["a", "b", "c"]), "tags", "expected at most 2 elements, got 3")
    _refused(lambda: cls(pair=[1, 2]), "pair", "expected exactly 3 elements, got 2")
    _refused(lambda: cls(raw=b"12345"), "raw", "expected at most 4 elements, got 5")
    _refused(lambda: cls(corners=[Point()]), "corners", "expected exactly 2 elements, got 1")
    _refused(lambda: cls(few=[Point()] * 3), "few", "expected at most 2 elements, got 3")
    _refused(lambda: cls(pair=[1, 2, 2**40]), "pair", "out of range for int32")
    _refused(lambda: cls(part={"value": 1.0}), "part", "a dict converts with Part.from_dict")
    # a message of another class of the same type (other definitions) is refused
    other = class_for("my_msgs/msg/Part", parsed("my_msgs/msg/Part", "float32 value\n"))
    assert other is not part
    _refused(lambda: cls(part=other()), "part", "expected my_msgs/msg/Part, got Part")
    _refused(
        lambda: cls.from_dict({"part": {"value": 1.0, "nope": 2}}),
        "part.nope",
        "unknown field (my_msgs/msg/Part has: value, notes)",
    )
    with pytest.raises(MessageError) as info:
        cls(code="abcde")
    assert info.value.type_name == "my_msgs/msg/Status"  # type: ignore[attr-defined]


def test_equality_copies_replace_and_dicts() -> None:
    cls = class_for("my_msgs/msg/Status", status_defs())
    part = class_for("my_msgs/msg/Part", status_defs())
    status = cls(speed=2.0, gains=[1.5], few=[Point(x=1.0)], part=part(value=3.0, notes=["n"]))
    assert status == cls(
        speed=2.0, gains=[1.5], few=[Point(x=1.0)], part=part(value=3.0, notes=["n"])
    )
    assert status != cls()
    assert status != Twist()
    shallow = copy.copy(status)
    assert shallow == status and shallow.part is status.part  # type: ignore[attr-defined]
    deep = copy.deepcopy(status)
    assert deep == status and deep.part is not status.part  # type: ignore[attr-defined]
    changed = status.replace(speed=3.0)
    assert changed.speed == 3.0 and changed.part is status.part  # type: ignore[attr-defined]
    with pytest.raises(MessageError):
        status.replace(code="toolong")
    data = status.to_dict()
    assert data["part"] == {"value": 3.0, "notes": ["n"]}
    assert data["few"] == [{"x": 1.0, "y": 0.0, "z": 0.0}]
    assert data["gains"].dtype == np.float32
    assert cls.from_dict(data) == status
    assert cls.from_dict({"part": {"value": 3.0}}).part == part(value=3.0)  # type: ignore[attr-defined]
    assert type(cls.from_dict({"part": {}}).part) is part  # type: ignore[attr-defined]
    made = cls._make(*(getattr(status, name) for name, _ in cls.__ros_fields__))
    assert made == status


def test_services_and_actions_derived_types() -> None:
    srv = with_bundled(
        interface_definitions("my_msgs/srv/SetSpeed", "float64 speed\n---\nbool ok\n")
    )
    request = class_for("my_msgs/srv/SetSpeed_Request", srv)
    response = class_for("my_msgs/srv/SetSpeed_Response", srv)
    assert request.__qualname__ == "SetSpeed.Request"
    assert repr(request(speed=1.0)) == "my_msgs.srv.SetSpeed.Request(speed=1.0)"
    assert response().ok is False  # type: ignore[attr-defined]
    registry = CodecRegistry()
    registry.add_schema("my_msgs/srv/SetSpeed", "ros2msg", "float64 speed\n---\nbool ok\n")
    assert request.__ros_hash__ == type_hash(registry, "my_msgs/srv/SetSpeed_Request")

    text = "int32 order\n---\nint32[] sequence\n---\nint32[] partial\n"
    action = with_bundled(interface_definitions("my_msgs/action/Count", text))
    send = class_for("my_msgs/action/Count_SendGoal_Request", action)
    goal = class_for("my_msgs/action/Count_Goal", action)
    assert send.__qualname__ == "Count.SendGoal.Request"
    message = send(goal=goal(order=3))
    assert type(message.goal_id) is UUID  # type: ignore[attr-defined]
    assert repr(message).startswith("my_msgs.action.Count.SendGoal.Request(goal_id=")
    feedback = class_for("my_msgs/action/Count_FeedbackMessage", action)
    assert feedback.__qualname__ == "Count.FeedbackMessage"
    assert feedback().feedback.partial.dtype == np.int32  # type: ignore[attr-defined]
    registry.add_schema("my_msgs/action/Count", "ros2action", text)
    for name in ("Count_SendGoal_Request", "Count_FeedbackMessage", "Count_GetResult_Response"):
        got = class_for(f"my_msgs/action/{name}", action)
        assert got.__ros_hash__ == type_hash(registry, f"my_msgs/action/{name}"), name


def test_an_empty_message() -> None:
    defs = parsed("my_msgs/msg/Nothing", "# nothing at all\n")
    cls = class_for("my_msgs/msg/Nothing", defs)
    assert cls.__ros_fields__ == () and cls.__slots__ == ()  # type: ignore[attr-defined]
    assert cls() == cls() and cls().to_dict() == {}
    assert repr(cls()) == "my_msgs.msg.Nothing()"
    assert cls.__ros_hash__ == registry_hash("my_msgs/msg/Nothing", {"my_msgs/msg/Nothing": ""})
    assert pickle.loads(pickle.dumps(cls())) == cls()


def test_what_a_class_cannot_express_is_a_schema_error() -> None:
    with pytest.raises(SchemaError, match="cannot name a field 'from'"):
        class_for("my_msgs/msg/Bad", parsed("my_msgs/msg/Bad", "int32 from\n"))
    with pytest.raises(SchemaError, match="cannot name a field 'replace'"):
        class_for("my_msgs/msg/Bad", parsed("my_msgs/msg/Bad", "int32 replace\n"))
    defs = parse_ros2msg("my_msgs/msg/Uses", "my_msgs/Missing thing\n")[1]
    with pytest.raises(SchemaError, match="my_msgs/msg/Missing"):
        class_for("my_msgs/msg/Uses", defs)
    with pytest.raises(SchemaError, match="no definition of 'my_msgs/msg/Other'"):
        class_for("my_msgs/msg/Other", defs)


# -- pickling --------------------------------------------------------------------------------


def test_messages_pickle_with_their_definitions_the_class_does_not() -> None:
    cls = class_for("my_msgs/msg/Status", status_defs())
    part = class_for("my_msgs/msg/Part", status_defs())
    status = cls(speed=4.0, part=part(value=1.0), pair=[3, 2, 1])
    for protocol in range(2, pickle.HIGHEST_PROTOCOL + 1):
        back = pickle.loads(pickle.dumps(status, protocol))
        assert type(back) is cls and back == status
        assert type(back.part) is part
    with pytest.raises((pickle.PicklingError, AttributeError)):
        pickle.dumps(cls)


def test_a_pickled_message_unpickles_in_another_process() -> None:
    cls = class_for("my_msgs/msg/Status", status_defs())
    payload = pickle.dumps(cls(speed=4.0, tags=["x"]))
    code = (
        "import pickle, sys\n"
        "msg = pickle.loads(sys.stdin.buffer.read())\n"
        "print(type(msg).__module__, msg.__ros_hash__, msg.speed, msg.tags)\n"
    )
    src = str(Path(__file__).resolve().parent.parent / "src")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run(
        [sys.executable, "-c", code], input=payload, capture_output=True, check=True, env=env
    )
    assert result.stdout.decode().split() == [RUNTIME, cls.__ros_hash__, "4.0", "['x']"]


# -- the cache -------------------------------------------------------------------------------


def test_threads_asking_for_one_new_type_get_one_class() -> None:
    defs = status_defs("threaded_msgs")
    barrier = threading.Barrier(16)
    got: list[type[RosMessage]] = []
    lock = threading.Lock()

    def ask() -> None:
        barrier.wait()
        found = class_for("threaded_msgs/msg/Status", dict(defs))
        with lock:
            got.append(found)

    threads = [threading.Thread(target=ask) for _ in range(16)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(got) == 16
    assert len({id(cls) for cls in got}) == 1
    assert type(got[0]().part) is class_for("threaded_msgs/msg/Part", defs)  # type: ignore[attr-defined]


def test_the_cache_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    assert RUNTIME_CLASSES.max_entries == _classes.RUNTIME_CLASSES_MAX
    small: LruCache[object, type[RosMessage]] = LruCache(2)
    monkeypatch.setattr(_classes, "RUNTIME_CLASSES", small)
    first_defs = parsed("bound_msgs/msg/A", "int32 a\n")
    first = class_for("bound_msgs/msg/A", first_defs)
    assert class_for("bound_msgs/msg/A", first_defs) is first
    class_for("bound_msgs/msg/B", parsed("bound_msgs/msg/B", "int32 b\n"))
    class_for("bound_msgs/msg/C", parsed("bound_msgs/msg/C", "int32 c\n"))
    assert len(small) == 2 and small.evicted == 1
    again = class_for("bound_msgs/msg/A", first_defs)
    assert again is not first  # dropped for the bound: made anew
    assert again.__ros_hash__ == first.__ros_hash__
    assert first(a=1) == first(a=1)  # the old class keeps working for whoever holds it
