"""Recording over Zenoh against an rmw_zenoh implementation this project did
not write: zenoh-ros2-sdk talkers (``std_msgs/msg/String`` and
``sensor_msgs/msg/Imu``) through a real eclipse-zenoh router, recorded with
``Client.record`` and read back with the ``mcap`` reader and ``mcap_ros2``'s
decoder (the recipe of docs/recording.md, also run as written) and with
rosbags: every message's values, their order and count, each channel's
``ros2msg`` schema with the full text of every type it uses, and the
publishers' QoS from their liveliness tokens as ``offered_qos_profiles``."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest

import ros_mobile_bridge as rmb
from _recording import fields_only, read_with_recipe, read_with_rosbags, ros2_profile
from peers.zenoh_router import ZenohRouter
from peers.zenoh_sdk_node import IMU, SdkNode, imu_fields

pytest_plugins = ["peers.ros_fixtures"]
pytest.importorskip("zenoh_ros2_sdk")
pytest.importorskip("mcap_ros2")

from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402

from _util import routed, wait_until  # noqa: E402
from ros_mobile_bridge.codec import CodecRegistry, type_hash  # noqa: E402
from ros_mobile_bridge.wire import rmw_zenoh as rz  # noqa: E402

STRING = "std_msgs/msg/String"
IMU_QOS = "1:1:1,5:,:,:,,"  # rmw_zenoh's token form
COUNT = 40  # messages per talker


def plain(value: Any) -> Any:
    """An mcap_ros2 message (objects with slots) as plain data."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, bytes | bytearray):
        return list(value)
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    slots = getattr(type(value), "__slots__", None)
    if slots:
        return {name: plain(getattr(value, name)) for name in slots}
    return value


def fields_of(msg_text: str) -> list[str]:
    """The field and constant lines of a ``.msg`` text, comments and blank
    lines dropped, whitespace normalised, a field's default value dropped
    (the recorded schema is generated from the decoding definition, which
    keeps types, names and constants; MCAP readers need no defaults)."""
    out = []
    for line in msg_text.splitlines():
        line = re.sub(r"#.*", "", line).strip()
        if "=" in line:  # a constant: TYPE NAME=VALUE
            kind, _, rest = line.partition(" ")
            name, _, value = rest.partition("=")
            out.append(f"{kind} {name.strip()}={value.strip()}")
        elif line:
            out.append(" ".join(line.split()[:2]))
    return out


def schema_blocks(text: str) -> dict[str, list[str]]:
    """A ros2msg schema (the type's text, then ``=====`` / ``MSG: pkg/Type``
    blocks) as {type name or "": its field lines}."""
    blocks = re.split(r"^={10,}\s*$", text, flags=re.M)
    out = {"": fields_of(blocks[0])}
    for block in blocks[1:]:
        head, _, body = block.strip().partition("\n")
        assert head.startswith("MSG: "), head
        out[head.removeprefix("MSG: ").strip()] = fields_of(body)
    return out


def official(ros_share: Path, type_name: str) -> list[str]:
    parts = type_name.split("/")  # pkg/msg/Type or pkg/Type
    pkg, name = parts[0], parts[-1]
    return fields_of((ros_share / pkg / "msg" / f"{name}.msg").read_text())


async def test_sdk_talkers_are_recorded_and_read_back_with_mcap_ros2(
    sdk: Callable[..., SdkNode],
    zenoh_router: ZenohRouter,
    zenoh_domain: int,
    ros_share: Path,
    tmp_path: Path,
    raw: Any,
) -> None:
    path = tmp_path / "zenoh.mcap"
    topics = {"/chatter": STRING, "/imu": IMU}
    opts = rmb.ClientOptions(domain_id=zenoh_domain)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        async with client.record(path, topics=list(topics), adaptive=False) as rec:
            # the recorder's subscriptions reach the router before the talkers start
            for topic, type_name in topics.items():
                hash_ = type_hash(CodecRegistry(), type_name)
                await routed(raw, rz.format_key(rz.TopicKey(zenoh_domain, topic, type_name, hash_)))
            for topic, type_name in topics.items():
                args = ["--topic", topic, "--type", type_name, "--count", str(COUNT)]
                if topic == "/imu":  # reliable, transient local, keep last 5
                    args += ["--qos", IMU_QOS]
                await anyio.to_thread.run_sync(lambda a=args: sdk("talker", "--rate", "50", *a))
            await wait_until(
                lambda: all(rec.stats.messages.get(t, 0) >= COUNT for t in topics),
                timeout=20.0,
                what="every message",
            )
        stats = rec.stats
        assert client.rejections == {}
    assert stats.skipped == {}
    assert stats.messages == dict.fromkeys(topics, COUNT)

    got: dict[str, list[Any]] = {t: [] for t in topics}
    schemas: dict[str, Any] = {}
    encodings: dict[str, tuple[str, str]] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _message, decoded in reader.iter_decoded_messages(
            log_time_order=False
        ):
            got[channel.topic].append(plain(decoded))
            schemas[channel.topic] = schema
            encodings[channel.topic] = (channel.message_encoding, schema.encoding)
        summary = reader.get_summary()
    # every message, in the order published, none twice
    assert got["/chatter"] == [{"data": f"hello {n}"} for n in range(COUNT)]
    assert got["/imu"] == [imu_fields(n) for n in range(COUNT)]
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 2 * COUNT == stats.total
    assert encodings == dict.fromkeys(topics, ("cdr", "ros2msg"))
    # each schema: the type's fields, then every type it uses, as the
    # official .msg files of the Jazzy wheels have them
    assert {t: s.name for t, s in schemas.items()} == topics
    string = schema_blocks(schemas["/chatter"].data.decode())
    assert string == {"": official(ros_share, STRING)}
    imu = schema_blocks(schemas["/imu"].data.decode())
    assert imu.pop("") == official(ros_share, IMU)
    used = {name.replace("/msg/", "/") for name in imu}
    assert used == {
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Quaternion",
        "geometry_msgs/Vector3",
    }
    for name, lines in imu.items():
        assert lines == official(ros_share, name), name
    # the ros2 profile: each publisher's QoS as its token told it
    profile = ros2_profile(path)
    assert [
        {k: q[k] for k in ("history", "depth", "reliability", "durability")}
        for q in profile["/imu"]["qos"]
    ] == [
        {
            "history": "keep_last",
            "depth": 5,
            "reliability": "reliable",
            "durability": "transient_local",
        }
    ]
    assert profile["/chatter"]["qos"][0]["durability"] == "volatile"
    assert profile["/imu"]["hash"].startswith("RIHS01_")
    # the recipe as written, and rosbags, read every channel
    assert read_with_recipe(path) == {t: (n, COUNT) for t, n in topics.items()}
    by_rosbags = read_with_rosbags(path)
    assert by_rosbags == {t: fields_only(got[t]) for t in topics}
