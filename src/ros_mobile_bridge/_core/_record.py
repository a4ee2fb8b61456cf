"""Recording what a client receives to an MCAP file (``Client.record``).

The recorder is a consumer of ordinary subscriptions (one per topic), so the
throttle (``max_hz``, the adaptive one) and the circuit breaker apply to it
as to any subscription. It takes frames undecoded
(``Subscription._next_frame``) and writes a file that follows the MCAP
``ros2`` profile, whatever the transport: every channel is ``cdr`` with a
``ros2msg`` schema and the ``offered_qos_profiles`` (and ``topic_type_hash``)
metadata rosbag2 writes.

- a CDR payload (Foxglove ``cdr`` channels, Zenoh, rosbridge ``cbor-raw``) is
  written as it came;
- a JSON or CBOR message (rosbridge, a Foxglove ``json`` channel of a ROS
  type) is decoded and encoded to CDR with the connection's codec (the same
  one that encodes what the client publishes), counted in
  ``RecordStats.reencoded``;
- a message of a type with no ROS 2 definition (a Foxglove ``json`` channel
  with only a JSON schema, like the demo robot's ``/status``) is not written:
  the profile has no place for it. It is counted in ``RecordStats.skipped``
  under the reason ``no_ros2_definition``.

Each channel's schema is the full ``ros2msg`` text with its dependencies, as
rosbag2 writes it. The file is finished (summary, indexes) on every exit
path, cancellation included: ``finish()`` is synchronous, so no cancellation
can cut it short (it blocks the event loop while it writes the last chunk
and the indexes). Writing happens on the event loop too: a slow disk adds
lag to everything the client does. A topic the bridge refuses is counted in
``RecordStats.failed`` and the others go on; a disk error (``OSError``) ends
the recording and is raised from the ``record()`` block, after the file was
finished if the disk allowed. The ``mcap`` package is imported here, lazily
(the ``[record]`` extra)."""

from __future__ import annotations

import base64
import contextlib
import io
import logging
import os
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import IO, TYPE_CHECKING, Any, Final, Literal, cast

import anyio
import anyio.abc

from .._checks import check_name
from .._errors import ConnectError, DecodeError, NotConnected, RosBridgeError
from .._types import Compression
from .._version import __version__
from ..codec import normalize_type_name, type_hash
from ._connection import Connection, RouteContext

if TYPE_CHECKING:
    from mcap.writer import Writer

    from ..codec import CodecRegistry
    from ..flow import RawFrame

__all__ = ["DEFAULT_QOS", "OfferedQos", "RecordStats", "Recording", "SkipReason", "open_recording"]

_BYTE_TYPES: Final = frozenset({"uint8", "byte", "char", "int8"})

SkipReason = Literal["no_ros2_definition", "foreign_definition", "undecodable", "unencodable"]
"""Why a message was not written (the keys of ``RecordStats.skip_reasons``):
``no_ros2_definition`` its type has no ROS 2 message definition the client
knows (a JSON-schema-only channel, an unknown type); ``foreign_definition``
CDR from a definition other than the one the client knows by that name (a
Zenoh key with another type hash, a Foxglove schema that does not parse);
``undecodable`` a JSON or CBOR message that did not decode; ``unencodable``
one that decoded but does not fit its type's CDR encoding."""


@dataclass(frozen=True, slots=True)
class OfferedQos:
    """One publisher's QoS as written into a channel's
    ``offered_qos_profiles``. Deadline, lifespan and liveliness lease are
    written as infinite, liveliness as automatic: no transport tells them."""

    reliable: bool = True
    transient_local: bool = False
    keep_all: bool = False
    depth: int = 10


DEFAULT_QOS: Final = OfferedQos()
"""What a channel's ``offered_qos_profiles`` holds when the transport does
not tell the publishers' QoS (Foxglove, rosbridge, a Zenoh topic whose
publisher token is gone): rclcpp's default, reliable, volatile, keep last
10."""

_INFINITE = "\n    sec: 9223372036\n    nsec: 854775807"  # RMW_DURATION_INFINITE


def offered_qos_yaml(profiles: Sequence[OfferedQos]) -> str:
    """``offered_qos_profiles`` as rosbag2 (metadata version 9, Jazzy)
    writes it: a YAML list, one block per publisher, the policies spelled
    as rmw spells them (``keep_last``, ``reliable``, ``transient_local``)."""
    blocks = []
    for qos in profiles or (DEFAULT_QOS,):
        blocks.append(
            f"- history: {'keep_all' if qos.keep_all else 'keep_last'}\n"
            f"  depth: {qos.depth}\n"
            f"  reliability: {'reliable' if qos.reliable else 'best_effort'}\n"
            f"  durability: {'transient_local' if qos.transient_local else 'volatile'}\n"
            f"  deadline:{_INFINITE}\n"
            f"  lifespan:{_INFINITE}\n"
            "  liveliness: automatic\n"
            f"  liveliness_lease_duration:{_INFINITE}\n"
            "  avoid_ros_namespace_conventions: false"
        )
    return "\n".join(blocks)


@dataclass(frozen=True, slots=True)
class RecordStats:
    """What a recording wrote so far (a snapshot). Every message the
    recorder's subscriptions handed it is in exactly one of ``messages``
    and ``skipped``.

    ``messages``: messages written per topic; ``reencoded``: of those, the
    ones encoded to CDR by the client (they came as JSON or CBOR);
    ``bytes``: CDR payload bytes written (before the file's compression);
    ``skipped``: messages per topic that were not written, and
    ``skip_reasons`` the same per topic and :data:`SkipReason` (the first
    skip of each topic and reason is logged); ``failed``: topics not recorded (any
    more) because the bridge or the client refused them, with the reason
    (logged once).
    """

    messages: dict[str, int] = field(default_factory=dict)
    bytes: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    failed: dict[str, str] = field(default_factory=dict)
    reencoded: dict[str, int] = field(default_factory=dict)
    skip_reasons: dict[str, dict[str, int]] = field(default_factory=dict)

    @property
    def total(self) -> int:
        """Messages written, over all topics."""
        return sum(self.messages.values())

    @property
    def total_skipped(self) -> int:
        """Messages not written, over all topics."""
        return sum(self.skipped.values())


def _import_mcap() -> Any:
    try:
        import mcap.writer
    except ImportError as exc:  # pragma: no cover - the [record] extra is missing
        raise RosBridgeError(
            "recording needs the 'mcap' and 'mcap-ros2-support' packages: "
            "pip install 'ros-mobile-bridge[record]'"
        ) from exc
    return mcap.writer


def _fix_bytes(codecs: CodecRegistry, schema: str, value: Any, depth: int = 0) -> Any:
    """rosbridge's JSON carries ``uint8[]`` / ``byte[]`` as base64 text: turn
    such fields back into bytes, through nested messages, so the CDR encoder
    takes them."""
    if not isinstance(value, dict) or depth > 32:
        return value
    out = dict(value)
    for spec in codecs.definition(schema):
        item = out.get(spec.name)
        if item is None:
            continue
        if spec.array and spec.type in _BYTE_TYPES and isinstance(item, str):
            with contextlib.suppress(ValueError):  # else the encoder names the field
                out[spec.name] = base64.b64decode(item, validate=True)
        elif "/" in spec.type:
            if spec.array and isinstance(item, list):
                out[spec.name] = [_fix_bytes(codecs, spec.type, v, depth + 1) for v in item]
            elif not spec.array:
                out[spec.name] = _fix_bytes(codecs, spec.type, item, depth + 1)
    return out


class Recording:
    """A recording in progress, yielded by :meth:`Client.record`. ``path`` is
    the file; :attr:`stats` what was written; :attr:`topics` the topics
    recorded so far."""

    def __init__(self, recorder: _Recorder) -> None:
        self._recorder = recorder
        self.path = recorder.path

    @property
    def stats(self) -> RecordStats:
        return self._recorder.stats

    @property
    def topics(self) -> list[str]:
        return self._recorder.topics


class _Recorder:
    """The engine behind a :class:`Recording`: the writer, the counters and
    one task per topic (started by :meth:`start` in the recording's task
    group). ``disk_error`` is the ``OSError`` that ended it, if one did."""

    def __init__(self, conn: Connection, path: str, writer: Writer, logger: logging.Logger) -> None:
        self._conn = conn
        self.path = path
        self._writer = writer
        self._log = logger
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._messages: dict[str, int] = {}
        self._reencoded: dict[str, int] = {}
        self._skipped: dict[str, dict[str, int]] = {}
        self._bytes = 0
        self._sequence = 0
        self._topics: list[str] = []
        self._failed: dict[str, str] = {}
        self.disk_error: OSError | None = None
        self._stop: anyio.CancelScope | None = None  # the recording's task group

    @property
    def stats(self) -> RecordStats:
        return RecordStats(
            messages=dict(self._messages),
            bytes=self._bytes,
            skipped={topic: sum(why.values()) for topic, why in self._skipped.items()},
            failed=dict(self._failed),
            reencoded=dict(self._reencoded),
            skip_reasons={topic: dict(why) for topic, why in self._skipped.items()},
        )

    @property
    def topics(self) -> list[str]:
        return list(self._topics)

    def start(
        self,
        tg: anyio.abc.TaskGroup,
        topics: Sequence[str] | None,
        max_hz: float | None,
        adaptive: bool,
        compression: Compression | None,
    ) -> None:
        """Record ``topics`` (every topic, now and later, when None) in
        ``tg``, which a disk error cancels."""
        self._stop = tg.cancel_scope
        if topics is None:
            tg.start_soon(self._follow_graph, tg, max_hz, adaptive, compression)
        else:
            for topic in topics:
                tg.start_soon(self._record_topic, topic, max_hz, adaptive, compression)

    # -- writing ---------------------------------------------------------------------
    def _qos(self, topic: str) -> list[OfferedQos]:
        """The topic's publishers' QoS where the adapter knows them (Zenoh's
        liveliness tokens carry them), else :data:`DEFAULT_QOS`."""
        offered: Callable[[str], list[Any]] | None = getattr(
            self._conn.adapter, "offered_qos", None
        )
        if offered is None:
            return [DEFAULT_QOS]
        profiles = [
            OfferedQos(q.reliable, q.transient_local, q.keep_all, q.depth) for q in offered(topic)
        ]
        return profiles or [DEFAULT_QOS]

    def _channel_id(self, topic: str, schema: str) -> int:
        """The ``cdr`` channel of ``topic`` with type ``schema`` (registered
        on its first message, with the ``ros2msg`` schema and the ``ros2``
        profile's metadata); ``DecodeError`` when the type has no ROS 2
        definition to write as the schema."""
        codecs = self._conn.adapter.codecs
        key = (topic, schema)
        channel_id = self._channels.get(key)
        if channel_id is None:
            name = normalize_type_name(schema)
            schema_id = self._schemas.get(name)
            if schema_id is None:
                text = codecs.ros2msg_text(schema).encode()
                schema_id = self._writer.register_schema(name, "ros2msg", text)
                self._schemas[name] = schema_id
            try:
                digest = type_hash(codecs, name)
            except (DecodeError, ValueError):  # a type REP-2011 cannot describe
                digest = ""
            metadata = {
                "offered_qos_profiles": offered_qos_yaml(self._qos(topic)),
                "topic_type_hash": digest,
            }
            channel_id = self._writer.register_channel(topic, "cdr", schema_id, metadata)
            self._channels[key] = channel_id
        return channel_id

    def _skip(self, frame: RawFrame, reason: SkipReason, detail: str) -> None:
        why = self._skipped.setdefault(frame.topic, {})
        count = why.get(reason, 0)
        why[reason] = count + 1
        if count == 0:
            self._log.warning(
                "record: messages on %s are not written (%s): %s (counted in stats.skipped)",
                frame.topic,
                reason,
                detail,
            )

    def _write(self, frame: RawFrame) -> None:
        codecs = self._conn.adapter.codecs
        schema = frame.schema_name
        if frame.decode is None:
            if frame.encoding == "cdr":
                # the sender's definition is not one we can name (Zenoh: the
                # key's hash is not our definition's; Foxglove: its schema did
                # not parse): writing its bytes under our schema would
                # mislabel them
                self._skip(frame, "foreign_definition", f"no decoder for the sender's {schema!r}")
            else:
                self._skip(frame, "no_ros2_definition", f"no decoder for {schema!r}")
            return
        reencoded = frame.encoding != "cdr"
        if reencoded:
            if not schema or not codecs.resolves(schema):
                self._skip(frame, "no_ros2_definition", self._no_ros2(schema, frame.encoding))
                return
            try:
                message = frame.decode(frame.payload)
            except (DecodeError, ValueError) as exc:
                self._skip(frame, "undecodable", f"a message did not decode: {exc}")
                return
            try:
                encode = codecs.encoder(schema, "cdr")
            except (DecodeError, ValueError):  # only a JSON schema by that name
                self._skip(frame, "no_ros2_definition", self._no_ros2(schema, frame.encoding))
                return
            try:
                if frame.encoding == "json":
                    message = _fix_bytes(codecs, schema, message)
                data = encode(message)
            except (DecodeError, ValueError, TypeError) as exc:
                self._skip(frame, "unencodable", f"cannot encode {schema} as CDR: {exc}")
                return
        else:
            data = bytes(frame.payload)
        try:
            channel_id = self._channel_id(frame.topic, schema)
        except (DecodeError, ValueError) as exc:  # no definition to write as the schema
            self._skip(frame, "no_ros2_definition", f"no definition of {schema!r}: {exc}")
            return
        self._add(frame, channel_id, data)
        if reencoded:
            self._reencoded[frame.topic] = self._reencoded.get(frame.topic, 0) + 1

    @staticmethod
    def _no_ros2(schema: str, encoding: str) -> str:
        return (
            f"{schema or 'its type'!r} has no ROS 2 message definition ({encoding}); "
            "the MCAP ros2 profile holds CDR only"
        )

    def _add(self, frame: RawFrame, channel_id: int, data: bytes) -> None:
        self._sequence += 1
        self._writer.add_message(
            channel_id,
            log_time=frame.receive_time_ns,
            data=data,
            publish_time=frame.log_time_ns or frame.receive_time_ns,
            sequence=self._sequence,
        )
        self._messages[frame.topic] = self._messages.get(frame.topic, 0) + 1
        self._bytes += len(data)

    # -- subscribing -----------------------------------------------------------------
    async def _record_topic(
        self,
        topic: str,
        max_hz: float | None,
        adaptive: bool,
        compression: Compression | None,
    ) -> None:
        self._topics.append(topic)
        try:
            route = self._conn.router.route(
                topic,
                max_hz=max_hz,
                adaptive=adaptive,
                dispatch="all",
                schema=None,
                buffer=None,
                compression=compression,
            )
            async with RouteContext(self._conn, route):
                while True:
                    try:
                        frame = await route.queue.next_frame()
                    except StopAsyncIteration:
                        return
                    self._write(frame)
        except (ConnectError, NotConnected) as exc:
            # the client's status says so; the file keeps what came before
            self._log.warning("record: %s stopped: %s", topic, exc)
        except RosBridgeError as exc:  # this topic only: the others go on
            self._failed[topic] = str(exc)
            self._log.error("record: %s is not recorded: %s (see stats.failed)", topic, exc)
        except OSError as exc:  # the disk: the whole recording ends
            if self.disk_error is None:
                self.disk_error = exc
                self._log.error("record: writing %s failed: %s; the recording ends", self.path, exc)
            if self._stop is not None:
                self._stop.cancel()

    async def _follow_graph(
        self,
        tg: anyio.abc.TaskGroup,
        max_hz: float | None,
        adaptive: bool,
        compression: Compression | None,
    ) -> None:
        started: set[str] = set()
        async for topics in self._conn.router.topics.watch():
            for info in topics:
                if info.name not in started:
                    started.add(info.name)
                    tg.start_soon(self._record_topic, info.name, max_hz, adaptive, compression)


@asynccontextmanager
async def open_recording(
    conn: Connection,
    path: str | os.PathLike[str] | IO[bytes],
    topics: Sequence[str] | None,
    max_hz: float | None,
    adaptive: bool,
    compression: Compression | None,
) -> AsyncIterator[Recording]:
    """The body of :meth:`Client.record` (arguments already checked). A
    path is created (or truncated) and closed here; a binary stream (stdout)
    is written and flushed, and left open."""
    mcap_writer = _import_mcap()
    conn.require_connected()
    log = conn.router.logger
    owned = isinstance(path, str | os.PathLike)
    if isinstance(path, str | os.PathLike):
        name = os.fspath(path)
        # the writer needs a blocking file; creating it is one quick system call
        stream: IO[bytes] = open(name, "wb")  # noqa: SIM115, ASYNC230 - closed below
    else:
        label = getattr(path, "name", None)
        name = label if isinstance(label, str) else "<stream>"
        stream = path if _seekable(path) else cast("IO[bytes]", _Counted(path))
    try:
        writer = mcap_writer.Writer(stream, compression=_compression(mcap_writer))
        writer.start(profile="ros2", library=f"ros-mobile-bridge {__version__}")
    except BaseException:
        if owned:
            stream.close()
        raise
    recorder = _Recorder(conn, name, writer, log)
    try:
        async with anyio.create_task_group() as tg:
            recorder.start(tg, topics, max_hz, adaptive, compression)
            try:
                yield Recording(recorder)
            finally:
                tg.cancel_scope.cancel()
    finally:
        # Synchronous, so no cancellation can cut it short: the last chunk,
        # the summary and the indexes (milliseconds: the messages are on disk
        # already, in chunks of 1 MiB).
        try:
            writer.finish()
            stream.flush()
        except OSError as exc:
            if recorder.disk_error is None:
                raise
            log.error("record: %s could not be finished: %s", name, exc)
        finally:
            if owned:
                stream.close()
    if recorder.disk_error is not None:
        # the task group's cancellation ended the body; the disk is the news
        raise recorder.disk_error


def _seekable(stream: IO[bytes]) -> bool:
    try:
        return bool(stream.seekable())
    except (AttributeError, OSError, ValueError):
        return False


class _Counted:
    """A pipe (stdout) for the MCAP writer, which asks ``tell()`` for the
    offsets it writes into the summary: the bytes written so far."""

    def __init__(self, stream: IO[bytes]) -> None:
        self._stream = stream
        self._written = 0

    def write(self, data: Any) -> int:
        view = memoryview(data)
        self._stream.write(view)
        self._written += view.nbytes
        return view.nbytes

    def tell(self) -> int:
        return self._written

    def flush(self) -> None:
        self._stream.flush()


def _compression(mcap_writer: Any) -> Any:
    """zstd when the zstandard package is there, else lz4, else none."""
    kinds = mcap_writer.CompressionType
    try:
        import zstandard  # noqa: F401

        return kinds.ZSTD
    except ImportError:
        pass
    try:
        import lz4  # type: ignore[import-untyped]  # noqa: F401

        return kinds.LZ4
    except ImportError:
        return kinds.NONE


def check_record_args(
    path: object, topics: object, max_hz: object, compression: object
) -> tuple[str | os.PathLike[str] | IO[bytes], list[str] | None]:
    """``Client.record``'s argument checks: ``TypeError`` / ``ValueError``."""
    if isinstance(path, str | os.PathLike):
        if not os.fspath(path):
            raise ValueError("path must not be empty")
    elif not callable(getattr(path, "write", None)) or isinstance(path, io.TextIOBase):
        raise TypeError(
            f"path must be a str, an os.PathLike or a binary file, not {type(path).__name__}"
        )
    wanted: list[str] | None = None
    if topics is not None:
        if isinstance(topics, str) or not isinstance(topics, Sequence | set | frozenset):
            raise TypeError("topics must be a sequence of topic names or None (every topic)")
        wanted = []
        for topic in topics:
            name = check_name("topic", topic)
            if name not in wanted:
                wanted.append(name)
        if not wanted:
            raise ValueError("topics must name at least one topic (None records every topic)")
    if max_hz is not None:
        if isinstance(max_hz, bool) or not isinstance(max_hz, int | float):
            raise TypeError("max_hz must be a number or None")
        if not max_hz > 0 or max_hz == float("inf"):
            raise ValueError(f"max_hz must be positive and finite, got {max_hz!r}")
    if compression is not None and compression not in ("cbor", "cbor-raw"):
        raise ValueError(f"compression must be 'cbor', 'cbor-raw' or None, got {compression!r}")
    return cast("str | os.PathLike[str] | IO[bytes]", path), wanted
