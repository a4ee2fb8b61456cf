"""Recording to MCAP (``Client.record``) against real peers: the demo robot
(the official Foxglove SDK server, CDR and JSON channels) and
rosbridge_server_rs on a real ROS 2 graph (JSON messages encoded to CDR by
the library, and cbor-raw CDR). Files are read back with ``mcap``'s own
reader and ``mcap_ros2``'s decoder (the recipe of docs/recording.md, run as
written) and with rosbags; every channel must follow the MCAP ros2 profile,
and every recorded message must equal what a parallel subscription of the
same client received over the same window."""

from __future__ import annotations

import contextlib
import errno
import itertools
import json
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest
from foxglove import Schema
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

import ros_mobile_bridge as rmb
from _recording import fields_only, read_with_recipe, read_with_rosbags, ros2_profile
from _util import rosbridge_options as options
from _util import wait_until
from peers.foxglove_sdk import SdkServer
from peers.rosbridge import RosBridge, RosGraph
from ros_mobile_bridge._cli._app import main, parse
from ros_mobile_bridge._cli._record import default_output, summary_lines
from ros_mobile_bridge.codec import CodecRegistry, type_hash
from ros_mobile_bridge.demo import DemoRobot
from ros_mobile_bridge.interfaces import RosMessage

pytest_plugins = ["peers.ros_fixtures"]

_unique = itertools.count()


@pytest.fixture
def demo() -> Iterator[DemoRobot]:
    """Not conftest's ``robot``: a fresh one per test, at faster rates."""
    with DemoRobot(rate_hz=50.0, camera_hz=10.0) as robot:
        yield robot


def plain(value: Any) -> Any:
    """A decoded message (ours: message instances, or dicts, with numpy
    arrays; mcap_ros2's: objects with slots) as plain lists, dicts and
    scalars."""
    if isinstance(value, RosMessage):
        return plain(value.to_dict())
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, bytes | bytearray | memoryview):
        return list(bytes(value))
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    slots = getattr(type(value), "__slots__", None)
    if slots:
        return {name: plain(getattr(value, name)) for name in slots}
    return value


def read_back(path: Path) -> tuple[dict[str, list[Any]], dict[str, Any]]:
    """Per topic, the JSON messages parsed (CDR ones as raw bytes), and each
    topic's (message encoding, schema)."""
    out: dict[str, list[Any]] = {}
    schemas: dict[str, Any] = {}
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            schemas[channel.topic] = (channel.message_encoding, schema)
            data = json.loads(message.data) if channel.message_encoding == "json" else message.data
            out.setdefault(channel.topic, []).append(data)
    return out, schemas


def decode_all(path: Path) -> dict[str, list[tuple[int, Any]]]:
    out: dict[str, list[tuple[int, Any]]] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, decoded in reader.iter_decoded_messages(
            log_time_order=False
        ):
            out.setdefault(channel.topic, []).append((message.log_time, plain(decoded)))
    return out


async def collect(sub: rmb.Subscription, into: list[rmb.Message]) -> None:
    async for msg in sub:
        into.append(msg)


def same_window(
    recorded: list[tuple[int, Any]], received: list[rmb.Message]
) -> tuple[list[Any], list[Any]]:
    """The parallel subscription's messages received within the recording's
    first..last log time (the recorder logs the frame's receive time), and
    the recorded ones, both as plain data."""
    first, last = recorded[0][0], recorded[-1][0]
    window = [plain(m.data) for m in received if first <= m.receive_time_ns <= last]
    return window, [data for _t, data in recorded]


def same_run(
    recorded: list[tuple[int, Any]], received: list[rmb.Message]
) -> tuple[list[Any], list[Any]]:
    """As :func:`same_window`, for a recording made from another stream of
    the server than the parallel subscription's (rosbridge's cbor-raw beside
    its JSON: the same messages, each stream at its own time): the parallel
    subscription's run of messages that starts with the recording's first."""
    data = [plain(m.data) for m in received]
    mine = [d for _t, d in recorded]
    start = data.index(mine[0]) if mine and mine[0] in data else len(data)
    return data[start : start + len(mine)], mine


async def until_seen(
    path: Path,
    received: dict[str, list[rmb.Message]],
    align: Callable[[list[tuple[int, Any]], list[rmb.Message]], tuple[list[Any], list[Any]]],
) -> None:
    """Until each parallel subscription has received as many messages of the
    finished recording's window (``align``: :func:`same_window` or
    :func:`same_run`) as the recording holds: its consumer task takes them
    some time after the recorder did. At most 10 s: the comparison after it
    says what differs."""
    decoded = decode_all(path)

    def complete() -> bool:
        return all(len(align(decoded[t], received[t])[0]) >= len(decoded[t]) for t in decoded)

    with anyio.move_on_after(10):
        while not complete():
            await anyio.sleep(0.01)


def summary_count(path: Path) -> int:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    return int(summary.statistics.message_count)


# -- arguments ------------------------------------------------------------------------


async def test_bad_arguments_raise_at_once(demo: DemoRobot, tmp_path: Path) -> None:
    async with rmb.connect(demo.url, options=options()) as robot:
        with pytest.raises(TypeError):
            robot.record(42)  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="sequence"):
            robot.record(tmp_path / "x.mcap", topics="/odom")  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="absolute"):
            robot.record(tmp_path / "x.mcap", topics=["odom"])
        with pytest.raises(ValueError, match="at least one"):
            robot.record(tmp_path / "x.mcap", topics=[])
        with pytest.raises(ValueError, match="max_hz"):
            robot.record(tmp_path / "x.mcap", max_hz=0)
        with pytest.raises(ValueError, match="compression"):
            robot.record(tmp_path / "x.mcap", compression="png")  # type: ignore[arg-type]
        with pytest.raises(FileNotFoundError):
            async with robot.record(tmp_path / "no" / "such" / "dir.mcap"):
                pytest.fail("recorded into a missing directory")
    assert not (tmp_path / "x.mcap").exists()


# -- Foxglove (the demo robot) --------------------------------------------------------


async def test_demo_topics_round_trip_through_mcap(demo: DemoRobot, tmp_path: Path) -> None:
    path = tmp_path / "demo.mcap"
    topics = ["/odom", "/battery", "/camera/image/compressed"]
    received: dict[str, list[rmb.Message]] = {t: [] for t in topics}
    async with (
        rmb.connect(demo.url, options=options()) as robot,
        contextlib.AsyncExitStack() as stack,
        anyio.create_task_group() as tg,
    ):
        for topic in topics:
            sub = await stack.enter_async_context(
                robot.subscribe(topic, adaptive=False, buffer=10_000)
            )
            tg.start_soon(collect, sub, received[topic])
        async with robot.record(path, topics=topics, adaptive=False) as rec:
            await wait_until(lambda: all(rec.stats.messages.get(t, 0) >= 3 for t in topics), 10)
        stats = rec.stats
        await until_seen(path, received, same_window)
        tg.cancel_scope.cancel()
    decoded = decode_all(path)
    assert set(decoded) == set(topics)
    for topic in topics:
        window, recorded = same_window(decoded[topic], received[topic])
        assert len(recorded) == stats.messages[topic]
        assert recorded == window, topic
    assert summary_count(path) == stats.total
    _messages, schemas = read_back(path)
    encoding, schema = schemas["/odom"]
    assert (encoding, schema.name, schema.encoding) == ("cdr", "nav_msgs/msg/Odometry", "ros2msg")
    text = schema.data.decode()
    assert "MSG: std_msgs/Header" in text and "MSG: geometry_msgs/PoseWithCovariance" in text
    # the ros2 profile: QoS (Foxglove tells none: the documented default) and the type hash
    profile = ros2_profile(path)
    assert profile["/odom"]["qos"] == [DEFAULT_QOS]
    assert profile["/odom"]["hash"] == type_hash(CodecRegistry(), "nav_msgs/msg/Odometry")
    # rosbags reads every channel, the same values
    by_rosbags = read_with_rosbags(path)
    for topic in topics:
        assert by_rosbags[topic] == fields_only([data for _t, data in decoded[topic]]), topic
    assert stats.reencoded == {}


DEFAULT_QOS = {
    "history": "keep_last",
    "depth": 10,
    "reliability": "reliable",
    "durability": "volatile",
    "deadline": {"sec": 9223372036, "nsec": 854775807},
    "lifespan": {"sec": 9223372036, "nsec": 854775807},
    "liveliness": "automatic",
    "liveliness_lease_duration": {"sec": 9223372036, "nsec": 854775807},
    "avoid_ros_namespace_conventions": False,
}


async def test_every_topic_by_default_a_json_only_topic_is_skipped_and_counted(
    demo: DemoRobot, tmp_path: Path
) -> None:
    """The demo robot's /status is JSON with only a JSON schema: the ros2
    profile has no place for it, so it is counted as skipped, and the
    documented reading recipe reads every channel the file has."""
    path = tmp_path / "all.mcap"
    cdr_topics = {"/odom", "/pose", "/battery", "/camera/image/compressed"}
    async with rmb.connect(demo.url, options=options()) as robot:
        async with robot.record(path) as rec:
            await wait_until(
                lambda: (
                    set(rec.stats.messages) == cdr_topics
                    and rec.stats.skipped.get("/status", 0) >= 2
                ),
                10,
            )
        assert sorted(rec.topics) == sorted(t.name for t in robot.topics)
    stats = rec.stats
    assert set(stats.skipped) == {"/status"}
    assert stats.skip_reasons == {"/status": {"no_ros2_definition": stats.skipped["/status"]}}
    assert set(ros2_profile(path)) == cdr_topics
    recipe = read_with_recipe(path)
    assert {t: n for t, (_type, n) in recipe.items()} == stats.messages
    assert recipe["/odom"][0] == "nav_msgs/msg/Odometry"
    assert summary_count(path) == stats.total
    assert {t: len(v) for t, v in read_with_rosbags(path).items()} == stats.messages


def _publish_until(stop: threading.Event, logs: list[Callable[[int], None]]) -> None:
    n = 0
    while not stop.wait(0.01):
        for log in logs:
            log(n)
        n += 1


async def test_foxglove_json_channels_of_ros_types_are_reencoded_to_cdr(tmp_path: Path) -> None:
    """A Foxglove ``json`` channel of a ROS type (a ros2msg schema, or a JSON
    schema named as a type the client knows) is encoded to CDR into a ros2
    channel; one of a type nobody defines is skipped and counted."""
    path = tmp_path / "json.mcap"
    stop = threading.Event()
    with SdkServer() as server:
        twist = server.channel("/twist_json", "geometry_msgs/msg/Twist", encoding="json")
        vector = server.raw_channel(
            "/vector_json",
            encoding="json",
            schema=Schema(
                name="geometry_msgs/msg/Vector3",
                encoding="jsonschema",
                data=json.dumps({"type": "object"}).encode(),
            ),
        )
        acme = server.raw_channel(
            "/acme",
            encoding="json",
            schema=Schema(name="acme/Status", encoding="jsonschema", data=b'{"type": "object"}'),
        )

        def log_twist(n: int) -> None:
            twist.log(json.dumps({"linear": {"x": float(n)}, "angular": {"z": -1.0}}).encode())

        def log_vector(n: int) -> None:
            vector.log(json.dumps({"x": float(n), "y": 2.0, "z": 3.0}).encode())

        def log_acme(n: int) -> None:
            acme.log(json.dumps({"n": n}).encode())

        publisher = threading.Thread(
            target=_publish_until, args=(stop, [log_twist, log_vector, log_acme]), daemon=True
        )
        publisher.start()
        try:
            async with rmb.connect(server.url, options=options()) as robot:
                topics = ["/twist_json", "/vector_json", "/acme"]
                async with robot.record(path, topics=topics, adaptive=False) as rec:
                    await wait_until(
                        lambda: (
                            min(rec.stats.messages.get(t, 0) for t in topics[:2]) >= 3
                            and rec.stats.skipped.get("/acme", 0) >= 3
                        ),
                        10,
                    )
        finally:
            stop.set()
            publisher.join(5)
    stats = rec.stats
    assert stats.reencoded == stats.messages
    assert set(stats.messages) == {"/twist_json", "/vector_json"}
    assert stats.skip_reasons == {"/acme": {"no_ros2_definition": stats.skipped["/acme"]}}
    profile = ros2_profile(path)
    assert {t: p["type"] for t, p in profile.items()} == {
        "/twist_json": "geometry_msgs/msg/Twist",
        "/vector_json": "geometry_msgs/msg/Vector3",
    }
    decoded = decode_all(path)
    twists = [m for _t, m in decoded["/twist_json"]]
    first = twists[0]["linear"]["x"]
    assert twists == [
        {
            "linear": {"x": first + i, "y": 0.0, "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": -1.0},
        }
        for i in range(len(twists))
    ]
    vectors = [m for _t, m in decoded["/vector_json"]]
    assert vectors[0] == {"x": vectors[0]["x"], "y": 2.0, "z": 3.0}
    assert read_with_rosbags(path) == {t: fields_only([m for _t, m in decoded[t]]) for t in decoded}


async def test_the_file_is_valid_after_cancellation(demo: DemoRobot, tmp_path: Path) -> None:
    path = tmp_path / "cancelled.mcap"
    async with rmb.connect(demo.url, options=options()) as robot:
        with anyio.CancelScope() as scope:
            async with robot.record(path, topics=["/odom", "/pose"]) as rec:
                await wait_until(lambda: rec.stats.total >= 10, 10)
                scope.cancel()
                await anyio.sleep(5)
                pytest.fail("not cancelled")
        assert scope.cancelled_caught
    assert summary_count(path) == rec.stats.total >= 10
    decoded = decode_all(path)
    assert sum(len(v) for v in decoded.values()) == rec.stats.total


async def test_a_refused_topic_is_counted_and_the_others_go_on(
    demo: DemoRobot, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "refused.mcap"
    async with rmb.connect(demo.url, options=options()) as robot:
        router = robot._conn.router  # where the recorder's subscriptions are routed
        add = router.add

        async def refusing(route: Any) -> None:
            if route.sub.topic == "/battery":  # as a bridge refusing the type would
                raise rmb.SchemaError("no definition of sensor_msgs/msg/BatteryState")
            await add(route)

        monkeypatch.setattr(router, "add", refusing)
        async with robot.record(path, topics=["/odom", "/battery", "/pose"]) as rec:
            await wait_until(lambda: "/battery" in rec.stats.failed, 10)
            await wait_until(
                lambda: min(rec.stats.messages.get(t, 0) for t in ("/odom", "/pose")) >= 3, 10
            )
        stats = rec.stats
    assert set(stats.failed) == {"/battery"}
    assert "BatteryState" in stats.failed["/battery"]
    assert set(stats.messages) == {"/odom", "/pose"}
    assert summary_count(path) == stats.total


async def test_a_disk_error_ends_the_recording_with_that_error(
    demo: DemoRobot, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from mcap.writer import Writer

    path = tmp_path / "full.mcap"
    add_message = Writer.add_message
    calls = itertools.count()

    def filling(self: Writer, *args: Any, **kw: Any) -> None:
        if next(calls) >= 5:
            raise OSError(errno.ENOSPC, "No space left on device")
        add_message(self, *args, **kw)

    monkeypatch.setattr(Writer, "add_message", filling)
    async with rmb.connect(demo.url, options=options()) as robot:
        with pytest.raises(OSError, match="No space left") as caught:
            async with robot.record(path, topics=["/odom", "/pose"]) as rec:
                await anyio.sleep(30)
                pytest.fail("the recording went on after the disk error")
        assert type(caught.value) is OSError  # not an exception group
        assert robot.status == "connected"  # the client is fine
    assert rec.stats.total == 5
    assert summary_count(path) == 5  # finished: the file is readable


async def test_max_hz_applies_to_the_recording(demo: DemoRobot, tmp_path: Path) -> None:
    path = tmp_path / "throttled.mcap"
    received: list[rmb.Message] = []
    async with rmb.connect(demo.url, options=options()) as robot, anyio.create_task_group() as tg:
        async with robot.subscribe("/odom", adaptive=False, buffer=10_000) as sub:
            tg.start_soon(collect, sub, received)
            async with robot.record(path, topics=["/odom"], max_hz=5, adaptive=False) as rec:
                await wait_until(lambda: rec.stats.total >= 4, 10)
            tg.cancel_scope.cancel()
    recorded = decode_all(path)["/odom"]
    window, _ = same_window(recorded, received)
    # 50 Hz arriving, at most 5 Hz recorded
    assert len(recorded) * 4 < len(window)


# -- rosbridge_server_rs ---------------------------------------------------------------


@pytest.mark.peer
@pytest.mark.parametrize("compression", [None, "cbor-raw"])
async def test_rosbridge_topics_round_trip_through_mcap(
    rosbridge: RosBridge, ros_graph: RosGraph, tmp_path: Path, compression: str | None
) -> None:
    image = f"/rmb_rec_image_{next(_unique)}"
    await anyio.to_thread.run_sync(
        lambda: ros_graph.command(
            {"cmd": "image", "topic": image, "hz": 10, "width": 8, "height": 4}
        )
    )
    try:
        path = tmp_path / "ros.mcap"
        topics = ["/chatter", "/odom", "/counter", image]
        received: dict[str, list[rmb.Message]] = {t: [] for t in topics}
        async with (
            rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as robot,
            contextlib.AsyncExitStack() as stack,
            anyio.create_task_group() as tg,
        ):
            await wait_until(lambda: image in {t.name for t in robot.topics}, 15)
            for topic in topics:
                sub = await stack.enter_async_context(
                    robot.subscribe(topic, adaptive=False, buffer=10_000)
                )
                tg.start_soon(collect, sub, received[topic])
            async with robot.record(
                path,
                topics=topics,
                adaptive=False,
                compression=compression,  # type: ignore[arg-type]
            ) as rec:
                await wait_until(
                    lambda: all(rec.stats.messages.get(t, 0) >= 10 for t in topics), 15
                )
            stats = rec.stats
            await until_seen(path, received, same_window if compression is None else same_run)
            tg.cancel_scope.cancel()
        assert stats.skipped == {}
        decoded = decode_all(path)
        for topic in topics:
            align = same_window if compression is None else same_run
            window, recorded = align(decoded[topic], received[topic])
            assert len(recorded) == stats.messages[topic]
            assert recorded == window, topic
        # the image's uint8[] (base64 text in rosbridge's JSON) is bytes again
        pixels = decoded[image][0][1]
        assert (pixels["width"], pixels["height"], len(pixels["data"])) == (8, 4, 8 * 4 * 3)
        assert summary_count(path) == stats.total
        _messages, schemas = read_back(path)
        assert schemas["/chatter"][1].name == "std_msgs/msg/String"
        # the bundled std_msgs/msg/String.msg as shipped, its comments included
        text = schemas["/chatter"][1].data.decode()
        assert text.startswith("# This was originally provided as an example message.")
        assert text.rstrip().endswith("\nstring data")
        # JSON (and CBOR) messages are re-encoded to CDR and counted; cbor-raw's
        # are not. The recording switches the bridge's subscription of each
        # topic from JSON to cbor-raw: a JSON message already on its way then
        # is still delivered, and re-encoded (a few of a topic's first)
        if compression == "cbor-raw":
            assert all(stats.reencoded.get(t, 0) <= stats.messages[t] // 2 for t in topics), (
                stats.reencoded
            )
        else:
            assert stats.reencoded == stats.messages
        # the ros2 profile on every channel; the recipe and rosbags read every one
        assert set(ros2_profile(path)) == set(topics)
        recipe = read_with_recipe(path)
        assert {t: n for t, (_type, n) in recipe.items()} == stats.messages
        by_rosbags = read_with_rosbags(path)
        for topic in topics:
            assert by_rosbags[topic] == fields_only([data for _t, data in decoded[topic]]), topic
    finally:
        await anyio.to_thread.run_sync(lambda: ros_graph.command({"cmd": "stop", "topic": image}))


# -- the command line ------------------------------------------------------------------


async def test_the_record_command_writes_a_file_for_its_duration(
    demo: DemoRobot, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "cli.mcap"
    # /battery is 1 Hz: 2.5 s hold at least two of its ticks after the
    # subscription is set up (1 s held one at best, none on a loaded machine)
    verb, args = parse(
        ["record", demo.url, "/odom", "/battery", "-o", str(path), "--duration", "2.5"]
    )
    assert verb.path == ("record",) and verb.run is not None
    assert await verb.run(args) == 0
    decoded = decode_all(path)
    assert set(decoded) == {"/odom", "/battery"}
    total = sum(len(v) for v in decoded.values())
    assert total == summary_count(path) > 0
    err = capsys.readouterr().err
    assert f"{total} messages" in err and "/odom:" in err


def test_the_record_command_refuses_bad_numbers() -> None:
    for bad in (["--duration", "0"], ["--max-hz", "-1"], ["--max-hz", "fast"]):
        with pytest.raises(SystemExit) as caught:
            parse(["record", "localhost:8765", "-o", "x.mcap", *bad])
        assert caught.value.code == 2


async def test_the_record_command_names_the_file_from_the_date_without_o(
    demo: DemoRobot, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    verb, args = parse(["record", demo.url, "/odom", "--duration", "1"])
    assert verb.run is not None
    assert await verb.run(args) == 0
    made = [p.name for p in tmp_path.iterdir()]
    assert len(made) == 1 and re.fullmatch(r"rmb_\d{4}_\d\d_\d\d-\d\d_\d\d_\d\d\.mcap", made[0])
    assert summary_count(tmp_path / made[0]) > 0
    assert default_output(0.0) == time.strftime("rmb_%Y_%m_%d-%H_%M_%S.mcap", time.localtime(0))


async def test_the_record_command_refuses_an_existing_output_unless_overwrite(
    demo: DemoRobot, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "kept.mcap"
    path.write_bytes(b"precious")
    verb, args = parse(["record", demo.url, "/odom", "-o", str(path), "--duration", "1"])
    assert verb.run is not None
    assert await verb.run(args) == 1
    assert path.read_bytes() == b"precious"
    assert "--overwrite" in capsys.readouterr().err
    verb, args = parse(["record", demo.url, "/odom", "-o", str(path), "-f", "--duration", "1"])
    assert verb.run is not None
    assert await verb.run(args) == 0
    assert summary_count(path) > 0


def test_the_record_command_writes_mcap_to_stdout_with_o_dash(
    demo: DemoRobot, tmp_path: Path
) -> None:
    """``-o -``: the MCAP on stdout (no file named ``-``), the summary on
    stderr; the bytes are a complete file the recipe reads."""
    command = ["record", demo.url, "/odom", "-o", "-", "--duration", "1.5"]
    source = str(Path(rmb.__file__).resolve().parents[1])  # this checkout's package
    done = subprocess.run(
        [sys.executable, "-m", "ros_mobile_bridge", *command],
        capture_output=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": source},
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert list(tmp_path.iterdir()) == []
    path = tmp_path / "out.mcap"
    path.write_bytes(done.stdout)
    count = summary_count(path)
    assert read_with_recipe(path) == {"/odom": ("nav_msgs/msg/Odometry", count)}
    assert f"{count} messages" in done.stderr.decode() and "in stdout" in done.stderr.decode()


def test_the_record_summary_says_1_message_and_the_fate_of_every_message() -> None:
    stats = rmb.RecordStats(
        messages={"/a": 1, "/b": 2},
        bytes=1,
        skipped={"/s": 3},
        reencoded={"/b": 2},
        skip_reasons={"/s": {"no_ros2_definition": 3}},
        failed={"/f": "refused"},
    )
    assert summary_lines(stats, "x.mcap") == [
        "  /a: 1 message",
        "  /b: 2 messages (2 re-encoded to CDR)",
        "  /s: 0 messages (3 skipped: no_ros2_definition)",
        "  /f: not recorded: refused",
        "3 messages, 3 skipped, 1 byte of payload in x.mcap",
    ]


# -- rmb bag info ----------------------------------------------------------------------


async def test_bag_info_summarises_a_recording_offline(
    demo: DemoRobot,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    path = tmp_path / "info.mcap"
    async with rmb.connect(demo.url, options=options()) as robot:
        async with robot.record(path, topics=["/odom", "/battery"]) as rec:
            await wait_until(
                lambda: min(rec.stats.messages.get(t, 0) for t in ("/odom", "/battery")) >= 2, 10
            )
    stats = rec.stats
    capsys.readouterr()
    monkeypatch.delenv("RMB_URL", raising=False)  # no robot is needed
    verb, args = parse(["bag", "info", str(path)])
    assert verb.run_sync is not None
    assert verb.run_sync(args) == 0
    text = capsys.readouterr().out
    assert "Files:             info.mcap" in text
    assert f"Messages:          {stats.total}\n" in text
    assert (
        f"Topic: /odom | Type: nav_msgs/msg/Odometry | Count: {stats.messages['/odom']} "
        "| Serialization Format: cdr"
    ) in text
    verb, args = parse(["bag", "info", str(path), "--json"])
    assert verb.run_sync is not None and verb.run_sync(args) == 0
    info = json.loads(capsys.readouterr().out)
    with path.open("rb") as f:
        st = make_reader(f).get_summary().statistics  # type: ignore[union-attr]
    assert info == {
        "files": ["info.mcap"],
        "size": path.stat().st_size,
        "storage_id": "mcap",
        "profile": "ros2",
        "duration_ns": st.message_end_time - st.message_start_time,
        "start_ns": st.message_start_time,
        "end_ns": st.message_end_time,
        "messages": stats.total,
        "complete": True,
        "topics": [
            {
                "name": "/battery",
                "type": "sensor_msgs/msg/BatteryState",
                "count": stats.messages["/battery"],
                "serialization_format": "cdr",
            },
            {
                "name": "/odom",
                "type": "nav_msgs/msg/Odometry",
                "count": stats.messages["/odom"],
                "serialization_format": "cdr",
            },
        ],
    }

    # a recording cut short (no footer: killed, a full disk) is counted record by record
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:-37])
    verb, args = parse(["bag", "info", str(cut), "--json"])
    assert verb.run_sync is not None and verb.run_sync(args) == 0
    partial = json.loads(capsys.readouterr().out)
    assert partial["complete"] is False
    assert (partial["messages"], partial["topics"]) == (info["messages"], info["topics"])
    verb, args = parse(["bag", "info", str(cut)])
    assert verb.run_sync is not None and verb.run_sync(args) == 0
    assert "Incomplete:" in capsys.readouterr().out


def test_bag_info_refuses_what_is_not_a_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    verb, args = parse(["bag", "info", str(bad)])
    assert verb.run_sync is not None and verb.run_sync(args) == 1
    assert "not a readable MCAP file" in capsys.readouterr().err
    bad.write_bytes(b"\x89MC")  # the start of the magic, nothing more
    assert verb.run_sync(args) == 1
    assert "not a readable MCAP file" in capsys.readouterr().err
    assert main(["bag", "info", str(tmp_path / "missing.mcap")]) == 1
