"""Recording what a client receives to an MCAP file (``Client.record``).

The recorder is a consumer of ordinary subscriptions (one per topic), so the
throttle (``max_hz``, the adaptive one) and the circuit breaker apply to it
as to any subscription. It takes frames undecoded
(``Subscription._next_frame``) and writes ROS 2 CDR with the ``ros2``
profile, whatever the transport:

- a CDR payload (Foxglove ``cdr`` channels, Zenoh, rosbridge ``cbor-raw``) is
  written as it came;
- a JSON or CBOR message (rosbridge) is decoded and encoded to CDR with the
  connection's codec (the same one that encodes what the client publishes);
- a message of a type with no ROS definition (a Foxglove ``json`` channel with
  a JSON schema) is written as ``json`` with its ``jsonschema``.

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
import json
import logging
import os
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import IO, TYPE_CHECKING, Any, Final

import anyio
import anyio.abc

from ._checks import check_name
from ._connection import Connection, RouteContext
from ._errors import ConnectError, DecodeError, NotConnected, RosBridgeError
from ._types import Compression
from ._version import __version__

if TYPE_CHECKING:
    from mcap.writer import Writer

    from .codec import CodecRegistry
    from .flow import RawFrame

__all__ = ["RecordStats", "Recording", "open_recording"]

_BYTE_TYPES: Final = frozenset({"uint8", "byte", "char", "int8"})


@dataclass(frozen=True, slots=True)
class RecordStats:
    """What a recording wrote so far (a snapshot).

    ``messages``: messages written per topic; ``bytes``: payload bytes
    written (CDR or JSON, before the file's compression); ``skipped``:
    messages per topic that could not be written (no definition to encode
    them with, or data that does not fit it; each topic's first is logged);
    ``failed``: topics not recorded (any more) because the bridge or the
    client refused them, with the reason (logged once).
    """

    messages: dict[str, int] = field(default_factory=dict)
    bytes: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    failed: dict[str, str] = field(default_factory=dict)

    @property
    def total(self) -> int:
        """Messages written, over all topics."""
        return sum(self.messages.values())


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
        self._schemas: dict[tuple[str, str], int] = {}
        self._channels: dict[tuple[str, str, str], int] = {}
        self._messages: dict[str, int] = {}
        self._skipped: dict[str, int] = {}
        self._bytes = 0
        self._sequence = 0
        self._topics: list[str] = []
        self._failed: dict[str, str] = {}
        self.disk_error: OSError | None = None
        self._stop: anyio.CancelScope | None = None  # the recording's task group

    @property
    def stats(self) -> RecordStats:
        return RecordStats(
            dict(self._messages), self._bytes, dict(self._skipped), dict(self._failed)
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
    def _schema_id(self, name: str, encoding: str, data: bytes) -> int:
        key = (name, encoding)
        schema_id = self._schemas.get(key)
        if schema_id is None:
            schema_id = self._writer.register_schema(name, encoding, data)
            self._schemas[key] = schema_id
        return schema_id

    def _channel_id(self, topic: str, schema: str, encoding: str, make_schema: Any) -> int:
        key = (topic, schema, encoding)
        channel_id = self._channels.get(key)
        if channel_id is None:
            schema_id = make_schema()
            channel_id = self._writer.register_channel(topic, encoding, schema_id)
            self._channels[key] = channel_id
        return channel_id

    def _skip(self, frame: RawFrame, reason: str) -> None:
        count = self._skipped.get(frame.topic, 0)
        self._skipped[frame.topic] = count + 1
        if count == 0:
            self._log.warning(
                "record: messages on %s are not written: %s (counted in stats.skipped)",
                frame.topic,
                reason,
            )

    def _write(self, frame: RawFrame) -> None:
        codecs = self._conn.adapter.codecs
        topic, schema = frame.topic, frame.schema_name
        if frame.encoding == "cdr":
            if frame.decode is None:
                # the sender's definition is not one we can name (Zenoh: the
                # key's hash is not our definition's; Foxglove: its schema did
                # not parse): writing its bytes under our schema would
                # mislabel them
                self._skip(frame, f"no decoder for the sender's definition of {schema!r}")
                return
            data = bytes(frame.payload)
        else:
            if frame.decode is None:
                self._skip(frame, f"no decoder for {schema!r} ({frame.encoding})")
                return
            try:
                message = frame.decode(frame.payload)
            except (DecodeError, ValueError) as exc:
                self._skip(frame, f"a message did not decode: {exc}")
                return
            if schema and codecs.resolves(schema) and codecs.jsonschema(schema) is None:
                try:
                    if frame.encoding == "json":
                        message = _fix_bytes(codecs, schema, message)
                    data = codecs.encoder(schema, "cdr")(message)
                except DecodeError as exc:  # SchemaError included
                    self._skip(frame, f"cannot encode {schema} as CDR: {exc}")
                    return
            else:
                self._write_json(frame, message, codecs)
                return
        try:
            channel_id = self._channel_id(
                topic,
                schema,
                "cdr",
                lambda: self._schema_id(schema, "ros2msg", codecs.ros2msg_text(schema).encode()),
            )
        except DecodeError as exc:  # no definition to write as the schema
            self._skip(frame, f"no definition of {schema!r}: {exc}")
            return
        self._add(frame, channel_id, data)

    def _write_json(self, frame: RawFrame, message: Any, codecs: CodecRegistry) -> None:
        try:
            data = json.dumps(message, separators=(",", ":"), default=_jsonable).encode()
        except (TypeError, ValueError) as exc:
            self._skip(frame, f"not JSON: {exc}")
            return
        schema = frame.schema_name

        def make_schema() -> int:
            definition = codecs.jsonschema(schema) if schema else None
            if definition is None:
                return 0  # schemaless JSON
            return self._schema_id(schema, "jsonschema", json.dumps(definition).encode())

        channel_id = self._channel_id(frame.topic, schema, "json", make_schema)
        self._add(frame, channel_id, data)

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
                    try:
                        self._write(frame)
                    except (DecodeError, ValueError, TypeError) as exc:
                        self._skip(frame, str(exc))
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


def _jsonable(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, bytes | bytearray | memoryview):
        return list(bytes(value))
    raise TypeError(f"{type(value).__name__} is not JSON")


@asynccontextmanager
async def open_recording(
    conn: Connection,
    path: str | os.PathLike[str],
    topics: Sequence[str] | None,
    max_hz: float | None,
    adaptive: bool,
    compression: Compression | None,
) -> AsyncIterator[Recording]:
    """The body of :meth:`Client.record` (arguments already checked)."""
    mcap_writer = _import_mcap()
    conn.require_connected()
    log = conn.router.logger
    name = os.fspath(path)
    # the writer needs a blocking file; creating it is one quick system call
    stream: IO[bytes] = open(name, "wb")  # noqa: SIM115, ASYNC230 - closed in the finally below
    try:
        writer = mcap_writer.Writer(stream, compression=_compression(mcap_writer))
        writer.start(profile="ros2", library=f"ros-mobile-bridge {__version__}")
    except BaseException:
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
        except OSError as exc:
            if recorder.disk_error is None:
                raise
            log.error("record: %s could not be finished: %s", name, exc)
        finally:
            stream.close()
    if recorder.disk_error is not None:
        # the task group's cancellation ended the body; the disk is the news
        raise recorder.disk_error


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
) -> tuple[str | os.PathLike[str], list[str] | None]:
    """``Client.record``'s argument checks: ``TypeError`` / ``ValueError``."""
    if not isinstance(path, str | os.PathLike):
        raise TypeError(f"path must be a str or os.PathLike, not {type(path).__name__}")
    if not os.fspath(path):
        raise ValueError("path must not be empty")
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
    return path, wanted
