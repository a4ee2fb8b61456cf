"""A Zenoh session for the Zenoh adapter: eclipse-zenoh in *client* mode,
with everything its threads hand over funnelled into one :class:`Inbox` that
the event loop drains in batches.

Zenoh calls back on its own threads, one call per reply or liveliness
change. A thread hop per item costs 12-15 us, so the callbacks do not hop:
they copy what they need out of the zenoh objects, append it to the inbox
under a lock and wake the event loop only when none is pending (one
wake-up per batch, however many items it holds). The adapter's reader task
takes the whole batch at once.

Data samples, the hot path, take no callback: each data subscriber has a
zenoh FIFO channel (:data:`PUMP_CHANNEL_CAPACITY` samples) and a thread of
its own, its pump (:func:`_pump`), that waits on the channel without the
GIL and hands what waits there to the inbox as one ``Samples`` item, so a
burst costs one lock and one wake-up per batch instead of a Python call
(and a GIL hand-over) per sample. A pump ends when its subscriber is
undeclared or the session closes; :meth:`ZenohSession.aclose` joins them.

Data samples are bounded (``max_items`` samples and ``max_bytes`` payload
bytes waiting); past either bound a sample is dropped and counted
(:attr:`Inbox.overflowed`), never queued without limit. Replies, liveliness
changes and the end of a query are never dropped: they are small and bounded
by the graph and the pending-request limits.

Queries to a queryable (calls to a service this client serves) arrive as
``Request`` items; the zenoh query object stays in the session, keyed by the
item's query id, until :meth:`ZenohSession.reply` or
:meth:`ZenohSession.reply_error` answers it. At most ``max_open_queries``
(default :data:`DEFAULT_MAX_OPEN_QUERIES`) wait unanswered; a query past
that is answered with an error reply at once, in zenoh's thread, and counted
(:attr:`ZenohSession.refused_queries`). A query still open when its
queryable is undeclared or the session closes is answered with an error
reply then: none is left without an answer.

Lifecycle: every subscriber, liveliness subscriber, queryable and token
declared here is undeclared (ending the pumps), and the session closed, by
:meth:`ZenohSession.aclose` (the adapter calls it on every exit path,
shielded). A callback still declared at interpreter exit would hang the
process for 20 s or more.

eclipse-zenoh is an optional dependency (the ``[zenoh]`` extra); it is
imported only when a Zenoh session is opened."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

import anyio
import anyio.to_thread
import sniffio

from .._errors import ConnectError
from .._zenoh_options import ZenohSecurity
from ..wire.rmw_zenoh import (
    InboxItem,
    LivelinessChange,
    QueryDone,
    Reply,
    Request,
    SampleData,
    Samples,
    SessionLost,
)
from ._zenoh_link import (
    LinkSettings,
    explain_open_failure,
    load_zenoh,
    probe_link,
    session_config,
)

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "DEFAULT_MAX_OPEN_QUERIES",
    "Inbox",
    "ZenohSession",
    "load_zenoh",
]

DEFAULT_MAX_OPEN_QUERIES: Final = 256
"""Queries to this session's queryables that may wait unanswered at once."""
PUMP_CHANNEL_CAPACITY: Final = 256
"""Samples zenoh holds for one data subscriber until its pump takes them
(past it zenoh's receiving thread waits, as it does for a callback)."""
PUMP_BATCH: Final = 512
"""The most samples a pump hands to the inbox at once."""
_PUMP_JOIN_TIMEOUT: Final = 5.0
"""Seconds :meth:`ZenohSession.aclose` waits for the pumps, all together."""
HEARTBEAT_PERIOD: Final = 0.5
"""Seconds between a reliable cached publisher's sporadic heartbeats (sent
only when it published since the last): rmw_zenoh's 500 ms."""


def _threadsafe_caller() -> Callable[[Callable[[], None]], None]:
    """A function that schedules a callback on the current event loop from
    any thread, without waiting (asyncio or trio)."""
    if sniffio.current_async_library() == "trio":
        import trio

        token = trio.lowlevel.current_trio_token()
        return token.run_sync_soon
    import asyncio

    loop = asyncio.get_running_loop()

    def call(fn: Callable[[], None]) -> None:
        loop.call_soon_threadsafe(fn)

    return call


class Inbox:
    """Items from zenoh's threads to the event loop, taken in batches.

    ``push`` and ``push_samples`` may be called from any thread;
    :meth:`get_batch` only from the event loop that built the inbox.

    Data samples are bounded: at most ``max_items`` samples and
    ``max_bytes`` payload bytes wait (a sample larger than ``max_bytes``
    still passes when nothing else waits); past either bound a sample is
    dropped and counted (:attr:`overflowed`, :attr:`overflowed_by_tag`)."""

    def __init__(self, max_items: int, max_bytes: int) -> None:
        self._lock = threading.Lock()
        self._items: list[InboxItem] = []
        self._samples = 0  # data samples waiting (bounded)
        self._controls = 0  # other items waiting (never dropped)
        self._bytes = 0
        self._max_items = max_items
        self._max_bytes = max_bytes
        self._wake_pending = False
        self._event = anyio.Event()
        self._call_soon = _threadsafe_caller()
        self._closed = False
        self.overflowed = 0
        """Data samples dropped because the inbox was full."""
        self.overflowed_by_tag: dict[int, int] = {}
        self.bytes_received = 0
        """Payload bytes of the data samples zenoh handed over (dropped ones
        included); counted per batch taken."""
        self.items_received = 0
        """Data samples and other items taken by :meth:`get_batch`, plus
        data samples dropped."""

    @property
    def waiting(self) -> tuple[int, int]:
        """The data samples and their payload bytes waiting now."""
        return self._samples, self._bytes

    def _wake(self) -> None:  # in the event loop
        self._event.set()

    def _schedule_wake(self) -> None:  # with the lock held
        if not self._wake_pending and not self._closed:
            self._wake_pending = True
            try:
                self._call_soon(self._wake)
            except Exception:  # the loop is gone: nobody will read any more
                self._closed = True

    def push(self, item: InboxItem) -> None:
        """Queue a control item (never dropped while the inbox is open)."""
        with self._lock:
            if self._closed:
                return
            self._items.append(item)
            self._controls += 1
            self._schedule_wake()

    def push_samples(
        self, tag: int, samples: list[SampleData], size: int, receive_time_ns: int
    ) -> int:
        """Queue the data ``samples`` of the subscriber ``tag`` (``size``: the
        sum of their payloads' lengths) as one item, oldest first; those past
        the bounds are dropped and counted. Returns how many were queued."""
        with self._lock:
            if self._closed:
                return 0
            count = len(samples)
            if self._samples + count > self._max_items or self._bytes + size > self._max_bytes:
                samples, size = self._fit(tag, samples)
                count = len(samples)
                if not count:
                    return 0
            self._items.append(Samples(tag, samples, receive_time_ns))
            self._samples += count
            self._bytes += size
            self._schedule_wake()
            return count

    def _fit(self, tag: int, samples: list[SampleData]) -> tuple[list[SampleData], int]:
        """The samples that fit, sample by sample (with the lock held); the
        others are counted as overflowed."""
        kept: list[SampleData] = []
        waiting, waiting_bytes, size = self._samples, self._bytes, 0
        for sample in samples:
            length = len(sample[1])
            total = waiting_bytes + size
            if waiting + len(kept) >= self._max_items or (
                total and total + length > self._max_bytes
            ):
                continue
            kept.append(sample)
            size += length
        dropped = len(samples) - len(kept)
        if dropped:
            self.overflowed += dropped
            self.overflowed_by_tag[tag] = self.overflowed_by_tag.get(tag, 0) + dropped
            self.items_received += dropped
            self.bytes_received += sum(len(sample[1]) for sample in samples) - size
        return kept, size

    async def get_batch(self) -> list[InboxItem]:
        """Everything queued, oldest first; waits until there is something."""
        while True:
            with self._lock:
                self._wake_pending = False
                if self._items:
                    items, self._items = self._items, []
                    self.bytes_received += self._bytes
                    self.items_received += self._samples + self._controls
                    self._samples = 0
                    self._controls = 0
                    self._bytes = 0
                    return items
            await self._event.wait()
            self._event = anyio.Event()

    def close(self) -> None:
        """Drop what waits and take nothing more (the session is closing)."""
        with self._lock:
            self._closed = True
            self._items.clear()
            self._samples = 0
            self._controls = 0
            self._bytes = 0


def client_config(endpoint: str, *, connect_timeout: float, shared_memory: bool) -> Any:
    """A ``zenoh.Config`` for a *client* session to one router, with the
    library's keys only (see :func:`~._zenoh_link.session_config`)."""
    return session_config(endpoint, connect_timeout=connect_timeout, shared_memory=shared_memory)


class ZenohSession:
    """One zenoh client session and the inbox its callbacks fill.

    Open with :meth:`open`; close with :meth:`aclose` (idempotent, never
    raises). Declarations are plain method calls (zenoh's declare calls do
    not block on the network)."""

    def __init__(
        self,
        session: zenoh.Session,
        inbox: Inbox,
        *,
        max_open_queries: int = DEFAULT_MAX_OPEN_QUERIES,
    ) -> None:
        self._session = session
        self.inbox = inbox
        self._declared: dict[int, Any] = {}  # handle -> subscriber, queryable or token
        self._pumps: list[threading.Thread] = []  # the data subscribers' pump threads
        self._handles = 0
        self._queries = 0
        self._closed = False
        self.zid: str = str(session.zid())
        # queries to our queryables, shared with zenoh's threads (under the lock)
        self._served_lock = threading.Lock()
        self._open: dict[int, tuple[int, Any]] = {}  # query id -> (tag, zenoh Query)
        self._queryable_tags: dict[int, int] = {}  # handle -> tag of a queryable
        self._live_tags: set[int] = set()  # tags of the queryables declared now
        self._incoming = 0  # ids of incoming queries (their own sequence)
        self.max_open_queries = max_open_queries
        self.refused_queries = 0
        """Queries answered with an error at once: ``max_open_queries`` waited."""

    @classmethod
    async def open(
        cls,
        endpoint: str,
        *,
        connect_timeout: float,
        shared_memory: bool = False,
        max_items: int,
        max_bytes: int,
        max_open_queries: int = DEFAULT_MAX_OPEN_QUERIES,
        security: ZenohSecurity | None = None,
        config: str | os.PathLike[str] | None = None,
        logger: logging.Logger | None = None,
    ) -> ZenohSession:
        """Open a client session to the router at ``endpoint``
        (``tcp/host:port`` or ``tls/host:port``), starting from the
        configuration ``config`` (a file or JSON5 text) with ``security``
        on top (:func:`~._zenoh_link.session_config`). A ``tls/`` link, or
        one with user/password, is probed first (:func:`~._zenoh_link.probe_link`).
        ``ConnectError`` naming the cause (refused, unreachable, an invalid
        configuration, an untrusted certificate, a client certificate
        missing or refused, a refused password), all within
        ``connect_timeout``: client mode fails fast, and zenoh's retries of
        a refused handshake end at ``connect/timeout_ms``. Each step is
        logged at DEBUG on ``logger`` (never a password nor a key)."""
        if isinstance(max_open_queries, bool) or not (
            isinstance(max_open_queries, int) and max_open_queries >= 1
        ):
            raise ValueError(f"max_open_queries must be an int >= 1, got {max_open_queries!r}")
        z = load_zenoh()
        deadline = anyio.current_time() + connect_timeout
        built = session_config(
            endpoint,
            connect_timeout=connect_timeout,
            shared_memory=shared_memory,
            security=security,
            source=config,
        )
        link = LinkSettings.read(endpoint, built)
        log = logger or logging.getLogger("ros_mobile_bridge")
        log.debug(
            "zenoh: opening a client session to %s (%s)",
            endpoint,
            link.describe() if link is not None else "an endpoint of zenoh's own form",
        )
        try:
            return await cls._open_checked(
                z, endpoint, built, link, deadline, connect_timeout, max_items, max_bytes,
                max_open_queries,
            )  # fmt: skip
        except ConnectError as exc:
            log.debug("zenoh: no session with %s: %s", endpoint, exc)
            raise

    @classmethod
    async def _open_checked(
        cls,
        z: Any,
        endpoint: str,
        built: Any,
        link: LinkSettings | None,
        deadline: float,
        connect_timeout: float,
        max_items: int,
        max_bytes: int,
        max_open_queries: int,
    ) -> ZenohSession:
        """:meth:`open` after the configuration is built: the probe, then
        zenoh's ``open`` with the time left."""
        if link is not None and link.probed:
            # bounded by its socket timeouts (the remaining time), not abandoned
            await anyio.to_thread.run_sync(probe_link, link, endpoint, connect_timeout)
            left = deadline - anyio.current_time()
            if left <= 0:
                raise ConnectError(f"zenoh: no session with {endpoint} within the timeout")
            built.insert_json5("connect/timeout_ms", json.dumps(max(int(left * 1000), 1)))
        inbox = Inbox(max_items, max_bytes)
        try:
            # zenoh.open blocks (it connects); it is bounded by connect/timeout_ms.
            # Not abandoned on cancellation: a session opened by an abandoned
            # thread would never be closed.
            with anyio.fail_after(connect_timeout + 5.0):
                session = await anyio.to_thread.run_sync(z.open, built)
        except TimeoutError as exc:
            raise ConnectError(f"zenoh: no session with {endpoint} within the timeout") from exc
        except z.ZError as exc:
            raise ConnectError(explain_open_failure(link, endpoint, str(exc))) from exc
        return cls(session, inbox, max_open_queries=max_open_queries)

    @property
    def closed(self) -> bool:
        return self._closed or self._session.is_closed()

    def routers(self) -> list[str]:
        """The zids of the routers this session is connected to now."""
        return [str(z) for z in self._session.info.routers_zid()]

    def _keep(self, declared: Any) -> int:
        self._handles += 1
        self._declared[self._handles] = declared
        return self._handles

    def undeclare(self, handle: int) -> None:
        """Undeclare what ``handle`` names (a no-op for an unknown handle).
        Zenoh may still call a callback once after this: the adapter ignores
        items whose tag it no longer knows."""
        tag = self._queryable_tags.pop(handle, None)
        if tag is not None:
            with self._served_lock:  # queries from now on are refused
                self._live_tags.discard(tag)
        declared = self._declared.pop(handle, None)
        if tag is not None:
            self._finish_open(tag, "the service is no longer served")
        if declared is not None and not self._closed:
            with contextlib.suppress(Exception):  # a closed session: nothing to undeclare
                declared.undeclare()

    # -- declarations ----------------------------------------------------------
    def subscribe(self, key_expr: str, tag: int) -> int:
        """Declare a data subscriber; its samples arrive as
        :class:`~ros_mobile_bridge.wire.rmw_zenoh.Samples` items tagged
        ``tag``, in batches (see :func:`_pump`). Returns a handle for
        :meth:`undeclare`."""
        z = load_zenoh()
        subscriber: Any = self._session.declare_subscriber(
            key_expr, z.handlers.FifoChannel(PUMP_CHANNEL_CAPACITY)
        )
        pump = threading.Thread(
            target=_pump,
            args=(subscriber.handler, tag, self.inbox, z.ZError),
            name=f"rmb-zenoh-pump-{tag}",
            daemon=True,  # it ends when the subscriber is undeclared (aclose joins it)
        )
        try:
            pump.start()
        except BaseException:
            with contextlib.suppress(Exception):
                subscriber.undeclare()
            raise
        self._pumps = [t for t in self._pumps if t.is_alive()]
        self._pumps.append(pump)
        return self._keep(subscriber)

    def subscribe_liveliness(self, key_expr: str, tag: int) -> int:
        """Declare a liveliness subscriber with history (the tokens alive now
        are reported first); changes arrive as ``LivelinessChange`` items."""
        z = load_zenoh()
        inbox = self.inbox
        put = z.SampleKind.PUT

        def on_change(sample: zenoh.Sample) -> None:
            inbox.push(LivelinessChange(tag, str(sample.key_expr), sample.kind == put))

        sub = self._session.liveliness().declare_subscriber(key_expr, on_change, history=True)
        return self._keep(sub)

    def declare_token(self, key_expr: str) -> int:
        """Declare a liveliness token; alive until undeclared or closed."""
        return self._keep(self._session.liveliness().declare_token(key_expr))

    # -- queryables (services we serve) ----------------------------------------------
    def declare_queryable(self, key_expr: str, tag: int) -> int:
        """Declare a *complete* queryable on ``key_expr`` (as rmw_zenoh's
        service servers do). Each query arrives as a
        :class:`~ros_mobile_bridge.wire.rmw_zenoh.Request` tagged ``tag``
        and waits for :meth:`reply` or :meth:`reply_error` (see the module's
        bound). Returns a handle for :meth:`undeclare`, which answers the
        queries still open with an error."""
        inbox = self.inbox
        lock = self._served_lock
        open_queries = self._open
        live = self._live_tags

        def on_query(query: zenoh.Query) -> None:
            payload = query.payload
            attachment = query.attachment
            with lock:
                refused = None if tag in live else "the service is no longer served"
                if refused is None and len(open_queries) >= self.max_open_queries:
                    self.refused_queries += 1
                    refused = f"{self.max_open_queries} calls already wait for an answer"
                if refused is None:
                    self._incoming += 1
                    query_id = self._incoming
                    open_queries[query_id] = (tag, query)
            if refused is not None:
                _answer_error(query, refused)
                return
            inbox.push(
                Request(
                    tag,
                    query_id,
                    str(query.key_expr),
                    b"" if payload is None else payload.to_bytes(),
                    None if attachment is None else attachment.to_bytes(),
                )
            )

        with lock:
            live.add(tag)
        try:
            queryable = self._session.declare_queryable(key_expr, on_query, complete=True)
        except BaseException:
            with lock:
                live.discard(tag)
            raise
        handle = self._keep(queryable)
        self._queryable_tags[handle] = tag
        return handle

    def _take_open(self, query_id: int) -> Any:
        with self._served_lock:
            entry = self._open.pop(query_id, None)
        return None if entry is None else entry[1]

    def reply(self, query_id: int, key_expr: str, payload: bytes, attachment: bytes) -> bool:
        """Answer the open query ``query_id`` with one reply on ``key_expr``
        and end it. False when it is not open (answered already, ended by an
        undeclare or the close, or unknown). When zenoh refuses the reply
        (a closed session) the query is ended with an error reply and the
        error raised."""
        query = self._take_open(query_id)
        if query is None:
            return False
        try:
            query.reply(key_expr, payload, attachment=attachment)
        except Exception:
            _answer_error(query, "the server could not send its reply")
            raise
        with contextlib.suppress(Exception):
            query.drop()
        return True

    def reply_error(self, query_id: int, text: str) -> bool:
        """Answer the open query ``query_id`` with an error reply carrying
        ``text`` (UTF-8) and end it; False when it is not open."""
        query = self._take_open(query_id)
        if query is None:
            return False
        _answer_error(query, text)
        return True

    @property
    def open_queries(self) -> int:
        """Queries to our queryables that wait for an answer now."""
        return len(self._open)

    def _finish_open(self, tag: int | None, text: str) -> None:
        """Answer with an error every open query of the queryable ``tag``
        (every open query when ``tag`` is None)."""
        with self._served_lock:
            ids = [q for q, (t, _query) in self._open.items() if tag is None or t == tag]
            queries = [self._open.pop(q)[1] for q in ids]
        for query in queries:
            _answer_error(query, text)

    # -- queries -----------------------------------------------------------------
    def _reply_handler(self, query_id: int) -> Any:
        z = load_zenoh()
        inbox = self.inbox

        def on_reply(reply: zenoh.Reply) -> None:
            ok = reply.ok
            if ok is not None:
                attachment = ok.attachment
                inbox.push(
                    Reply(
                        query_id,
                        str(ok.key_expr),
                        ok.payload.to_bytes(),
                        True,
                        None if attachment is None else attachment.to_bytes(),
                    )
                )
            else:
                err = reply.err
                text = err.payload.to_bytes() if err is not None else b""
                inbox.push(Reply(query_id, None, text, False, None))

        def on_done() -> None:
            inbox.push(QueryDone(query_id))

        return z.handlers.Callback(on_reply, on_done)

    def query(
        self,
        selector: str,
        *,
        payload: bytes | None = None,
        attachment: bytes | None = None,
        timeout: float,
    ) -> int:
        """Send a query; its replies arrive as ``Reply`` items with the
        returned query id, then one ``QueryDone`` (after the last reply or
        the timeout). Replies from every matching queryable are awaited
        (target ALL_COMPLETE), as rmw_zenoh's service clients do."""
        z = load_zenoh()
        self._queries += 1
        query_id = self._queries
        self._session.get(
            selector,
            self._reply_handler(query_id),
            target=z.QueryTarget.ALL_COMPLETE,
            payload=payload,
            attachment=attachment,
            timeout=max(timeout, 0.001),
        )
        return query_id

    def query_liveliness(self, selector: str, *, timeout: float) -> int:
        """A liveliness query: each alive token matching ``selector`` comes
        back as a ``Reply`` (its key), then ``QueryDone``."""
        self._queries += 1
        query_id = self._queries
        self._session.liveliness().get(
            selector, self._reply_handler(query_id), timeout=max(timeout, 0.001)
        )
        return query_id

    # -- kept history (transient-local topics: adapters/_zenoh_latched.py) ------------
    def query_history(self, selector: str, *, timeout: float) -> int:
        """Ask the publishers' caches that ``selector`` reaches for what they
        keep: every matching queryable answers (target ALL), every reply is
        kept (no consolidation: several publishers' samples share one key)
        and replies on any key are taken (a cache answers with the data key,
        not the query's). Replies and the end come as for :meth:`query`."""
        z = load_zenoh()
        self._queries += 1
        query_id = self._queries
        self._session.get(
            selector,
            self._reply_handler(query_id),
            target=z.QueryTarget.ALL,
            consolidation=z.ConsolidationMode.NONE,
            accept_replies=z.ReplyKeyExpr.ANY,
            timeout=max(timeout, 0.001),
        )
        return query_id

    def declare_cached_publisher(self, key_expr: str, *, depth: int, reliable: bool) -> Any:
        """A zenoh-ext advanced publisher on ``key_expr`` that keeps its last
        ``depth`` samples for late joiners, detectable through liveliness,
        and (``reliable``) announcing its last sequence number with a
        sporadic heartbeat of :data:`HEARTBEAT_PERIOD` s, so a subscriber can
        recover a lost last sample (as rmw_zenoh's transient-local
        publishers are made). Undeclared with the session."""
        z = load_zenoh()
        import zenoh.ext as zext

        publisher = zext.declare_advanced_publisher(
            self._session,
            key_expr,
            congestion_control=(
                z.CongestionControl.BLOCK if reliable else z.CongestionControl.DROP
            ),
            reliability=z.Reliability.RELIABLE if reliable else z.Reliability.BEST_EFFORT,
            cache=zext.CacheConfig(depth),
            publisher_detection=True,
            sample_miss_detection=(
                zext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=HEARTBEAT_PERIOD)
                if reliable
                else None
            ),
        )
        self._keep(publisher)
        return publisher

    # -- writes --------------------------------------------------------------------
    def declare_publisher(self, key_expr: str, *, reliable: bool, express: bool) -> Any:
        """A zenoh publisher for ``key_expr``: congestion control BLOCK when
        ``reliable`` (nothing dropped locally), DROP otherwise."""
        z = load_zenoh()
        publisher = self._session.declare_publisher(
            key_expr,
            congestion_control=(
                z.CongestionControl.BLOCK if reliable else z.CongestionControl.DROP
            ),
            reliability=z.Reliability.RELIABLE if reliable else z.Reliability.BEST_EFFORT,
            express=express,
        )
        self._keep(publisher)
        return publisher

    # -- closing ---------------------------------------------------------------------
    async def aclose(self) -> None:
        """Undeclare everything, close the session (in a worker thread: it
        flushes and joins zenoh's tasks). Never raises; idempotent."""
        if self._closed:
            return
        self._closed = True
        self.inbox.close()
        declared = list(self._declared.values())
        self._declared.clear()
        pumps, self._pumps = self._pumps, []
        self._queryable_tags.clear()
        with self._served_lock:
            self._live_tags.clear()
        session = self._session

        def close() -> None:  # in a worker thread
            self._finish_open(None, "the server closed its session")
            for obj in reversed(declared):
                with contextlib.suppress(Exception):
                    obj.undeclare()
            with contextlib.suppress(Exception):
                session.close()  # type: ignore[no-untyped-call]
            deadline = time.monotonic() + _PUMP_JOIN_TIMEOUT
            for pump in pumps:  # each ends once its subscriber's channel is closed
                pump.join(max(deadline - time.monotonic(), 0.0))

        with anyio.CancelScope(shield=True):
            await anyio.to_thread.run_sync(close)


def _pump(handler: Any, tag: int, inbox: Inbox, closed: type[Exception]) -> None:
    """A data subscriber's thread: wait for a sample in zenoh's channel
    (without the GIL), then take what else waits there (:data:`PUMP_BATCH`
    at most), copy each out of its zenoh objects and hand the lot to the
    inbox as one item, stamped with one receive time; until the channel
    closes (the subscriber is undeclared or the session closed).

    Zenoh's own callback thread would take the GIL, build the arguments and
    call Python once per sample; here a sample costs one ``try_recv`` and
    its copies, and a burst one inbox lock and at most one wake-up of the
    event loop. Consecutive samples on one key share one key string (a
    subscriber usually hears one key). ``closed`` is what the channel
    raises once it is closed and empty (``zenoh.ZError``); any other
    failure here ends the session (``SessionLost``, the reconnect policy
    then opens a new one) rather than leaving the subscription silent."""
    recv, try_recv = handler.recv, handler.try_recv
    push = inbox.push_samples
    clock = time.time_ns
    last_expr: Any = None
    last_key = ""
    open_ = True
    try:
        while open_:
            try:
                sample = recv()
            except closed:  # undeclared or closed, and empty
                return
            received = clock()
            batch: list[SampleData] = []
            size = 0
            while sample is not None:
                expr = sample.key_expr
                if expr != last_expr:
                    last_expr, last_key = expr, str(expr)
                payload = sample.payload.to_bytes()
                attachment = sample.attachment
                batch.append(
                    (last_key, payload, None if attachment is None else attachment.to_bytes())
                )
                size += len(payload)
                if len(batch) >= PUMP_BATCH:
                    break
                try:
                    sample = try_recv()
                except closed:  # undeclared or closed
                    sample, open_ = None, False
            push(tag, batch, size, received)
    except Exception as exc:
        inbox.push(SessionLost(f"the receiving thread of subscriber {tag} failed: {exc!r}"))


def _answer_error(query: Any, text: str) -> None:
    """End ``query`` with an error reply carrying ``text``; never raises (a
    query whose session is gone cannot be answered any more)."""
    with contextlib.suppress(Exception):
        query.reply_err(text.encode("utf-8", "replace"))
    with contextlib.suppress(Exception):
        query.drop()
