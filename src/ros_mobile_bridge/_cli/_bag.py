"""``rmb bag info FILE [--json]``: what a recording holds, as ``ros2 bag info``
prints it (files, size, duration, start, end, messages, and per topic its
type, count and serialization format). It reads the file alone, with no
robot and no ``$RMB_URL``: the MCAP summary section when the file has one
(every file ``rmb record`` finished), else it counts the messages, up to
the first damaged record of a file that was cut short (a recording killed
with SIGKILL, a full disk): what it reports is then marked incomplete."""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import dataclass, field
from typing import Any

from ._common import out, warn
from ._verb import Verb

__all__ = ["VERBS", "BagInfo", "TopicCount", "bag_info"]


@dataclass(frozen=True, slots=True)
class TopicCount:
    """One topic of a recording: its name, type, message count and the
    serialization format (the channel's message encoding)."""

    name: str
    type: str
    count: int
    serialization_format: str


@dataclass(frozen=True, slots=True)
class BagInfo:
    """What ``rmb bag info`` reports; times in nanoseconds since the epoch
    (0 when the file holds no message). ``complete`` is False for a file
    cut short: the counts are those of the records before the damage."""

    path: str
    size: int
    profile: str
    messages: int
    start_ns: int
    end_ns: int
    topics: list[TopicCount] = field(default_factory=list)
    complete: bool = True

    @property
    def duration_ns(self) -> int:
        return self.end_ns - self.start_ns

    def as_json(self) -> dict[str, Any]:
        """The ``--json`` object; its field names are stable."""
        return {
            "files": [os.path.basename(self.path)],
            "size": self.size,
            "storage_id": "mcap",
            "profile": self.profile,
            "duration_ns": self.duration_ns,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "messages": self.messages,
            "complete": self.complete,
            "topics": [
                {
                    "name": t.name,
                    "type": t.type,
                    "count": t.count,
                    "serialization_format": t.serialization_format,
                }
                for t in self.topics
            ],
        }


def bag_info(path: str) -> BagInfo:
    """Read ``path``'s summary (or count its messages when it has none, or
    when it was cut short). ``OSError`` when the file cannot be read,
    ``ValueError`` when it is not an MCAP file; ``RuntimeError`` without the
    ``mcap`` package."""
    try:
        from mcap.reader import make_reader
    except ImportError as exc:  # pragma: no cover - the [record] extra is missing
        raise RuntimeError(
            "reading recordings needs the 'mcap' package: pip install 'ros-mobile-bridge[record]'"
        ) from exc
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        try:
            reader = make_reader(f)
            profile = reader.get_header().profile
            summary = reader.get_summary()
        except Exception:  # no footer, a cut summary: _scan says what is left
            summary = None
        stats = summary.statistics if summary is not None else None
        if summary is None or stats is None:
            f.seek(0)
            return _scan(path, size, f)
    topics = [
        TopicCount(
            channel.topic,
            summary.schemas[channel.schema_id].name if channel.schema_id in summary.schemas else "",
            stats.channel_message_counts.get(channel_id, 0),
            channel.message_encoding,
        )
        for channel_id, channel in sorted(summary.channels.items(), key=lambda kv: kv[1].topic)
    ]
    total = stats.message_count
    start, end = (stats.message_start_time, stats.message_end_time) if total else (0, 0)
    return BagInfo(path, size, profile, total, start, end, topics)


def _scan(path: str, size: int, f: Any) -> BagInfo:
    """Count the messages record by record, up to the first damaged one."""
    from mcap.records import Channel, Header, Message, Schema
    from mcap.stream_reader import StreamReader

    profile, complete, seen_header = "", True, False
    schemas: dict[int, str] = {}
    channels: dict[int, Channel] = {}
    counts: dict[int, int] = {}
    total = start = end = 0
    try:
        for record in StreamReader(f).records:
            if isinstance(record, Header):
                profile, seen_header = record.profile, True
            elif isinstance(record, Schema):
                schemas[record.id] = record.name
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                start = record.log_time if total == 0 else min(start, record.log_time)
                end = max(end, record.log_time)
                total += 1
    except Exception as exc:  # a cut chunk fails in its decompressor, whatever it raises
        if not seen_header:
            raise ValueError(
                f"{path} is not a readable MCAP file: {exc or type(exc).__name__}"
            ) from None
        complete = False
    topics = [
        TopicCount(
            channel.topic,
            schemas.get(channel.schema_id, ""),
            counts.get(channel_id, 0),
            channel.message_encoding,
        )
        for channel_id, channel in sorted(channels.items(), key=lambda kv: kv[1].topic)
    ]
    return BagInfo(path, size, profile, total, start, end, topics, complete)


def _size(n: int) -> str:
    """``24.4 KiB``, as ros2 bag info writes sizes."""
    value = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if value < 1024 or unit == "GiB":
            return f"{n} B" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    raise AssertionError("unreachable")


def _stamp(ns: int) -> str:
    """``Nov 25 2026 21:52:36.123456789 (1764107556.123456789)``, local time."""
    sec, nsec = divmod(ns, 1_000_000_000)
    local = time.strftime("%b %d %Y %H:%M:%S", time.localtime(sec))
    return f"{local}.{nsec:09d} ({sec}.{nsec:09d})"


def render(info: BagInfo) -> list[str]:
    """The lines ``rmb bag info`` prints, in ``ros2 bag info``'s layout."""
    duration = info.duration_ns
    lines = [
        f"Files:             {os.path.basename(info.path)}",
        f"Bag size:          {_size(info.size)}",
        "Storage id:        mcap",
        f"Profile:           {info.profile or '(none)'}",
        f"Duration:          {duration // 1_000_000_000}.{duration % 1_000_000_000:09d}s",
        f"Start:             {_stamp(info.start_ns)}",
        f"End:               {_stamp(info.end_ns)}",
        f"Messages:          {info.messages}",
    ]
    if not info.complete:
        lines.append(
            "Incomplete:        the file was cut short; counted up to the first damaged record"
        )
    label = "Topic information: "
    if not info.topics:
        lines.append(label.rstrip())
    for i, t in enumerate(info.topics):
        lines.append(
            (label if i == 0 else " " * len(label))
            + f"Topic: {t.name} | Type: {t.type} | Count: {t.count} | "
            f"Serialization Format: {t.serialization_format}"
        )
    return lines


def _build_info(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="one JSON object (stable field names)")


def _info(ns: argparse.Namespace) -> int:
    try:
        info = bag_info(ns.file)
    except (ValueError, RuntimeError) as exc:
        warn(str(exc))
        return 1
    if ns.json:
        out(json.dumps(info.as_json()))
    else:
        for line in render(info):
            out(line)
    return 0


VERBS = [
    Verb(
        ("bag", "info"),
        "summarise a recording as ros2 bag info does (no robot needed)",
        ("FILE",),
        _build_info,
        run_sync=_info,
        graph_names=False,
    ),
]
