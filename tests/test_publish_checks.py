"""``publish`` checks the type before anything is advertised or sent: an
unknown type, a type that contradicts the graph, and anything but a Twist on a
velocity topic raise ``SchemaError`` naming it. Against the official Foxglove
SDK server (in-process, recording what clients send) and a real rosbridge
with a ROS 2 graph behind it."""

from __future__ import annotations

import itertools
from functools import partial

import anyio
import pytest
from foxglove import Schema
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

import ros_mobile_bridge as rmb
from _util import fast_options, rosbridge_options, wait_until
from peers.foxglove_sdk import SdkServer, decode
from peers.rosbridge import RosBridge, RosGraph

pytest_plugins = ["peers.ros_fixtures"]

_unique = itertools.count()

THING = "float64 speed\nstring label\ngeometry_msgs/Vector3 direction\n"


options = partial(fast_options, reconnect=None)


# -- unknown types ----------------------------------------------------------------------


@pytest.mark.parametrize("topic", ["/cmd_vel", "/note"])
@pytest.mark.parametrize("priority", ["control", "data"])
async def test_a_misspelled_type_is_refused_before_anything_is_sent(
    server: SdkServer, topic: str, priority: rmb.Priority
) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        with pytest.raises(rmb.SchemaError, match=r"geometry_msgs/msg/Twst"):
            await robot.publish(
                topic, "geometry_msgs/msg/Twst", {"linear": {"x": 0.3}}, priority=priority
            )
        assert robot.status == "connected"  # a caller's mistake, not a lost connection
        await robot.publish("/note", "std_msgs/msg/String", {"data": "after"})
        await wait_until(lambda: server.messages("/note"))
    # nothing about the bad type ever reached the server
    assert [a[1:] for a in server.recorder.advertised] == [("/note", "cdr", "std_msgs/msg/String")]
    assert [decode("std_msgs/msg/String", m.data).data for m in server.messages()] == ["after"]


async def test_an_explicit_wrong_kind_does_not_resolve(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        with pytest.raises(rmb.SchemaError, match=r"geometry_msgs/srv/Twist"):
            await robot.publish("/note", "geometry_msgs/srv/Twist", {})
        await robot.publish("/note", "std_msgs/String", {"data": "x"})  # kind left out: fine
    assert [a[1:] for a in server.recorder.advertised] == [("/note", "cdr", "std_msgs/String")]


async def test_a_type_the_server_advertises_needs_no_registration(server: SdkServer) -> None:
    server.raw_channel(
        "/custom",
        encoding="cdr",
        schema=Schema(name="my_pkg/msg/Other", encoding="ros2msg", data=b"int32 n\n"),
    )
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        await wait_until(lambda: any(t.name == "/custom" for t in robot.topics))
        await robot.publish("/custom_in", "my_pkg/msg/Other", {"n": 7})
        await wait_until(lambda: server.messages("/custom_in"))
        with pytest.raises(rmb.SchemaError, match="my_pkg/msg/Nothing"):
            await robot.publish("/custom_in2", "my_pkg/msg/Nothing", {"n": 7})


# -- user-registered types -----------------------------------------------------------------


async def test_a_registered_type_is_published_as_cdr(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        with pytest.raises(rmb.SchemaError, match="my_pkg/msg/Thing"):
            await robot.publish("/thing", "my_pkg/msg/Thing", {"speed": 1.5})
        robot.register_type("my_pkg/msg/Thing", THING)
        assert robot.schema_template("my_pkg/msg/Thing")["direction"] == {
            "x": 0.0,
            "y": 0.0,
            "z": 0.0,
        }
        await robot.publish(
            "/thing", "my_pkg/msg/Thing", {"speed": 1.5, "label": "a", "direction": {"z": 1.0}}
        )
        await wait_until(lambda: server.messages("/thing"))
    (msg,) = server.messages("/thing")
    assert msg.encoding == "cdr" and msg.schema_name == "my_pkg/msg/Thing"
    store = Typestore()
    store.register(get_types_from_msg(THING, "my_pkg/msg/Thing"))
    store.register(
        get_types_from_msg("float64 x\nfloat64 y\nfloat64 z\n", "geometry_msgs/msg/Vector3")
    )
    thing = store.deserialize_cdr(msg.data, "my_pkg/msg/Thing")
    assert (thing.speed, thing.label, thing.direction.z) == (1.5, "a", 1.0)


async def test_register_type_accepts_idl(server: SdkServer) -> None:
    idl = (
        "module my_pkg {\n  module msg {\n    struct Blob {\n      int32 count;\n"
        "      string name;\n    };\n  };\n};\n"
    )
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        robot.register_type("my_pkg/msg/Blob", idl, encoding="ros2idl")
        await robot.publish("/blob", "my_pkg/msg/Blob", {"count": 3, "name": "b"})
        await wait_until(lambda: server.messages("/blob"))
    assert server.messages("/blob")[0].data[4:8] == (3).to_bytes(4, "little")


async def test_register_type_checks_its_arguments_at_once(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        with pytest.raises(rmb.SchemaError, match="my_pkg/msg/Bad"):
            robot.register_type("my_pkg/msg/Bad", "float64 speed extra words [\n")
        with pytest.raises(rmb.SchemaError, match="my_pkg/msg/Missing"):
            robot.register_type("my_pkg/msg/Uses", "my_pkg/Missing inner\n")
        with pytest.raises(ValueError, match="encoding"):
            robot.register_type("my_pkg/msg/T", "int32 n\n", encoding="jsonschema")
        with pytest.raises(ValueError, match="ROS type"):
            robot.register_type("not a type", "int32 n\n")
        with pytest.raises(TypeError):
            robot.register_type("my_pkg/msg/T", 5)  # type: ignore[arg-type]
        # a failed registration leaves nothing behind
        with pytest.raises(rmb.SchemaError, match="my_pkg/msg/Uses"):
            await robot.publish("/uses", "my_pkg/msg/Uses", {})
        # a later type may use an earlier registered one
        robot.register_type("my_pkg/msg/Missing", "int32 n\n")
        robot.register_type("my_pkg/msg/Uses", "my_pkg/Missing inner\n")
        await robot.publish("/uses", "my_pkg/msg/Uses", {"inner": {"n": 2}})
        await wait_until(lambda: server.messages("/uses"))


# -- the graph's type ---------------------------------------------------------------------


async def test_a_type_contradicting_the_graph_is_refused(server: SdkServer) -> None:
    server.channel("/odom", "nav_msgs/msg/Odometry")
    server.channel("/chatter", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        await wait_until(lambda: len(robot.topics) == 2)
        with pytest.raises(rmb.SchemaError, match=r"/odom.*nav_msgs/msg/Odometry"):
            await robot.publish("/odom", "geometry_msgs/msg/Twist", {})
        await robot.publish("/chatter", "std_msgs/String", {"data": "same type, other spelling"})
        await wait_until(lambda: server.messages("/chatter"))
    assert [a[1] for a in server.recorder.advertised] == ["/chatter"]


# -- velocity topics ----------------------------------------------------------------------


@pytest.mark.parametrize("topic", ["/cmd_vel", "/robot1/cmd_vel", "/emergency"])
async def test_only_a_twist_goes_to_a_velocity_topic(server: SdkServer, topic: str) -> None:
    opts = options(stop_topics=("/emergency",))
    async with rmb.connect(server.url, options=opts) as robot:
        with pytest.raises(rmb.SchemaError, match=r"std_msgs/msg/String.*check_velocity"):
            await robot.publish(topic, "std_msgs/msg/String", {"data": "go"})
        assert not server.recorder.advertised
        await robot.publish(
            topic, "geometry_msgs/msg/TwistStamped", {"twist": {"linear": {"x": 0.2}}}
        )
    # the teardown's own zero (TwistStamped here) still goes out, last
    await wait_until(lambda: len(server.messages(topic)) == 2)
    last = decode("geometry_msgs/msg/TwistStamped", server.messages(topic)[-1].data)
    assert last.twist.linear.x == 0.0 and last.header.stamp.sec > 0


async def test_the_velocity_check_can_be_turned_off_explicitly(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        with pytest.raises(TypeError, match="check_velocity"):
            await robot.publish("/cmd_vel", "std_msgs/msg/String", {}, check_velocity=0)  # type: ignore[arg-type]
        await robot.publish("/cmd_vel", "std_msgs/msg/String", {"data": "go"}, check_velocity=False)
        await wait_until(lambda: server.messages("/cmd_vel"))
    assert decode("std_msgs/msg/String", server.messages("/cmd_vel")[0].data).data == "go"


async def test_publish_zero_twist_passes_the_checks(server: SdkServer) -> None:
    opts = options(stop_topics=("/stop_here",), zero_twist_on_exit=False)
    async with rmb.connect(server.url, options=opts) as robot:
        await robot.publish_zero_twist()
        await robot.publish_zero_twist("/stop_here", "geometry_msgs/msg/TwistStamped")
        await wait_until(lambda: server.messages("/cmd_vel") and server.messages("/stop_here"))


# -- rosbridge ---------------------------------------------------------------------------


async def test_rosbridge_refuses_bad_types_before_advertising(
    rosbridge: RosBridge, ros_graph: RosGraph
) -> None:
    await anyio.to_thread.run_sync(ros_graph.command, {"cmd": "clear", "topic": "/cmd_vel"})
    topic = f"/rmb_checked_{next(_unique)}"
    async with rmb.connect(
        rosbridge.url, protocol="rosbridge", options=rosbridge_options()
    ) as robot:
        await wait_until(lambda: any(t.name == "/chatter" for t in robot.topics), 10)
        # unknown to the bundled definitions, the graph and the bridge's rosapi
        with pytest.raises(rmb.SchemaError, match="unknown type 'std_msgs/msg/Strng'"):
            await robot.publish(topic, "std_msgs/msg/Strng", {"data": "x"})
        with pytest.raises(rmb.SchemaError, match="std_msgs/msg/String"):
            await robot.publish("/cmd_vel", "std_msgs/msg/String", {"data": "go"})
        with pytest.raises(rmb.SchemaError, match=r"/chatter.*String"):
            await robot.publish("/chatter", "geometry_msgs/msg/Twist", {})
        assert dict(robot._conn.adapter.publishing()) == {}  # nothing was advertised
    received = await anyio.to_thread.run_sync(
        ros_graph.command, {"cmd": "received", "topic": "/cmd_vel"}
    )
    assert received == []


async def test_rosbridge_resolves_a_type_through_rosapi(
    rosbridge: RosBridge, ros_graph: RosGraph
) -> None:
    """``test_msgs/msg/Builtins`` is neither bundled nor on the graph: the
    bridge's ``/rosapi/message_details`` knows it."""
    topic = f"/rmb_builtins_{next(_unique)}"
    async with rmb.connect(
        rosbridge.url, protocol="rosbridge", options=rosbridge_options()
    ) as robot:
        await robot.publish(topic, "test_msgs/msg/Builtins", {})
        assert robot._conn.adapter.codecs.resolves("test_msgs/msg/Builtins")
