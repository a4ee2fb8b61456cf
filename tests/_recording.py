"""Reading a recording back as the standard tools do, for the recording tests:
the MCAP ``ros2`` profile checked channel by channel, the reading recipe of
docs/recording.md run as written (examples/read_recording.py), and rosbags'
MCAP reader (rosbag2's storage plugin, re-implemented) with a typestore built
from the file's own schemas."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import yaml
from mcap.reader import make_reader
from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "read_recording.py"
QOS_KEYS = [
    "history",
    "depth",
    "reliability",
    "durability",
    "deadline",
    "lifespan",
    "liveliness",
    "liveliness_lease_duration",
    "avoid_ros_namespace_conventions",
]


def ros2_profile(path: Path) -> dict[str, dict[str, Any]]:
    """Assert the file follows the MCAP ros2 profile (header profile
    ``ros2``; every channel ``cdr`` with a ``ros2msg`` schema named
    ``pkg/msg/Type`` and the ``offered_qos_profiles`` metadata, a YAML list
    of rosbag2's QoS maps); per topic: its type, QoS list and type hash."""
    out: dict[str, dict[str, Any]] = {}
    with path.open("rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert summary is not None
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "cdr", channel.topic
        assert schema.encoding == "ros2msg", channel.topic
        assert schema.name.count("/") == 2 and "/msg/" in schema.name, schema.name
        qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert isinstance(qos, list) and qos, channel.topic
        for profile in qos:
            assert list(profile) == QOS_KEYS, profile
        out[channel.topic] = {
            "type": schema.name,
            "qos": qos,
            "hash": channel.metadata["topic_type_hash"],
        }
    return out


def read_with_recipe(path: Path) -> dict[str, tuple[str, int]]:
    """Run docs/recording.md's recipe (examples/read_recording.py) as a user
    would: per topic, its type and the number of messages it decoded."""
    done = subprocess.run(
        [sys.executable, str(EXAMPLE), str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    out: dict[str, tuple[str, int]] = {}
    for line in done.stdout.splitlines():
        topic, type_name, count = line.split()
        out[topic] = (type_name, int(count))
    return out


def plain_rosbags(value: Any) -> Any:
    """A rosbags message (a dataclass with ``__msgtype__``) as plain data."""
    if hasattr(value, "__dataclass_fields__"):
        return {
            name: plain_rosbags(getattr(value, name))
            for name in value.__dataclass_fields__
            if name != "__msgtype__"
        }
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, list | tuple):
        return [plain_rosbags(v) for v in value]
    return value


def fields_only(value: Any) -> Any:
    """Plain data without constants (ALL_CAPS keys): mcap_ros2's messages
    carry a type's constants as attributes, rosbags' do not."""
    if isinstance(value, dict):
        return {k: fields_only(v) for k, v in value.items() if not k.isupper()}
    if isinstance(value, list):
        return [fields_only(v) for v in value]
    return value


def read_with_rosbags(path: Path) -> dict[str, list[Any]]:
    """Every message of every channel through rosbags' MCAP reader (it
    refuses a file without the ros2 profile), deserialized with a typestore
    built from the file's ``ros2msg`` schemas; each channel's QoS must parse
    and its ``topic_type_hash``, when written, must be the RIHS01 hash
    rosbags computes from the schema."""
    reader = McapReader(path)
    reader.open()
    try:
        store = get_typestore(Stores.EMPTY)
        types: dict[str, Any] = {}
        for conn in reader.connections:
            types.update(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        store.register(types)
        out: dict[str, list[Any]] = {c.topic: [] for c in reader.connections}
        for conn in reader.connections:
            assert conn.ext.offered_qos_profiles, conn.topic  # type: ignore[union-attr]
        for conn, _t, raw in reader.messages(reader.connections):
            message = store.deserialize_cdr(raw, conn.msgtype)
            out[conn.topic].append(fields_only(plain_rosbags(message)))
    finally:
        reader.close()
    for topic, info in ros2_profile(path).items():
        if info["hash"]:
            assert info["hash"] == store.hash_rihs01(info["type"]), topic
    return out
