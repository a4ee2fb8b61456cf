"""What a Foxglove server offers beside topics, services and parameters:
its assets (``assets``: files by URI), its connection graph
(``connectionGraph``: who publishes, subscribes to and provides what) and
the control of a recording it plays (``playbackControl``). Parts of
:class:`~._foxglove.FoxgloveAdapter`: :class:`FoxgloveAssets` is its
``assets`` part, :class:`FoxgloveGraph` its ``node_list``,
:class:`FoxglovePlayback` its ``playback``."""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import AsyncIterator, Awaitable, Callable

import anyio

from .._errors import (
    AssetError,
    ConnectError,
    NotSupportedError,
    RosBridgeError,
    ServiceTimeout,
)
from .._options import ClientOptions
from .._types import PlaybackRequest, PlaybackState, PlaybackStatus, TopicEndpoints
from ..flow import PendingRequests
from ..wire import foxglove as fx

__all__ = ["FoxgloveAssets", "FoxgloveGraph", "FoxglovePlayback"]

_U32 = 0xFFFF_FFFF
_PLAYBACK_STATUS: dict[int, PlaybackStatus] = {
    0: "playing",
    1: "paused",
    2: "buffering",
    3: "ended",
}


def _require(capabilities: tuple[str, ...], capability: str, what: str) -> None:
    if capability not in capabilities:
        raise NotSupportedError(
            f"the Foxglove server offers no {what}: its serverInfo lists no {capability!r} "
            f"capability (it lists: {', '.join(capabilities) or 'none'})"
        )


class FoxgloveAssets:
    """``fetchAsset`` requests and their answers (an
    :class:`~._seam.AssetFetcher`)."""

    def __init__(
        self,
        engine: fx.FoxgloveEngine,
        send_request: Callable[[str], Awaitable[None]],
        check_pending: Callable[[str], None],
        capabilities: Callable[[], tuple[str, ...]],
    ) -> None:
        self._engine = engine
        self._send_request = send_request
        self._check_pending = check_pending
        self._capabilities = capabilities
        self._ids = itertools.count(1)
        self.requests: PendingRequests[fx.FetchAssetResponse] = PendingRequests()

    async def fetch_asset(self, uri: str) -> bytes:
        """The asset's bytes; ``AssetError`` with the server's reason when it
        refused, ``NotSupportedError`` without the ``assets`` capability."""
        _require(self._capabilities(), "assets", "assets")
        self._check_pending(f"fetchAsset {uri}")
        request_id = (next(self._ids) - 1) % _U32 + 1  # 1 ..= u32 max
        frame = self._engine.fetch_asset(uri, request_id)
        answer = await self.requests.request(request_id, lambda: self._send_request(frame))
        if not answer.ok:
            raise AssetError(uri, answer.error or "the server gave no reason")
        return bytes(answer.data)

    def on_response(self, event: fx.FetchAssetResponse) -> bool:
        """Hand an answer to its request; False when none waits for it."""
        return self.requests.resolve(event.request_id, event)


class FoxgloveGraph:
    """The server's connection graph (a :class:`~._seam.NodeLister`).

    The client subscribes to the graph only while a call needs it: each
    :meth:`nodes` / :meth:`topic_endpoints` subscribes (unless another call
    already holds the subscription), waits for the server's first update,
    which is the whole graph, answers from it and unsubscribes when the last
    caller is done. A server updating a large graph often thus costs nothing
    between calls; the price is one round trip per call. The node names are
    the ids the server gives the graph's endpoints (foxglove_bridge: node
    names); a server may use other ids."""

    def __init__(
        self,
        engine: fx.FoxgloveEngine,
        send_request: Callable[[str], Awaitable[None]],
        capabilities: Callable[[], tuple[str, ...]],
        options: ClientOptions,
        reject: Callable[[str, str, int], None],
    ) -> None:
        """``reject(reason, detail, count)`` reports the parts of an update
        skipped: malformed entries, and names past ``options.max_channels``
        per table (published, subscribed, services)."""
        self._engine = engine
        self._send_request = send_request
        self._capabilities = capabilities
        self._options = options
        self._reject = reject
        self._users = 0
        self._current = False  # the first update since subscribing arrived
        self._updated = anyio.Event()
        self._failed: RosBridgeError | None = None  # the connection is gone
        self._published: dict[str, tuple[str, ...]] = {}
        self._subscribed: dict[str, tuple[str, ...]] = {}
        self._provided: dict[str, tuple[str, ...]] = {}

    def on_update(self, event: fx.ConnectionGraphUpdate) -> None:
        """Apply one ``connectionGraphUpdate`` (ignored while no call holds
        the subscription: a late one after unsubscribing)."""
        if not self._users:
            return
        for topic in event.removed_topics:
            self._published.pop(topic, None)
            self._subscribed.pop(topic, None)
        for service in event.removed_services:
            self._provided.pop(service, None)
        malformed = refused = 0
        limit = self._options.max_channels
        for entries, key, table in (
            (event.published_topics, "publisherIds", self._published),
            (event.subscribed_topics, "subscriberIds", self._subscribed),
            (event.advertised_services, "providerIds", self._provided),
        ):
            for entry in entries:
                name, ids = entry.get("name"), entry.get(key)
                if not isinstance(name, str) or not isinstance(ids, list):
                    malformed += 1
                elif name not in table and len(table) >= limit:
                    refused += 1
                else:
                    table[name] = tuple(sorted({str(i) for i in ids if isinstance(i, str | int)}))
        if malformed:
            what = f"connectionGraphUpdate: {malformed} entries without a name or id list skipped"
            self._reject("malformed", what, malformed)
        if refused:
            what = f"connectionGraphUpdate: {refused} names past the {limit} kept skipped"
            self._reject("channel_limit", what, refused)
        self._current = True
        self._updated.set()
        self._updated = anyio.Event()

    def fail(self, error: RosBridgeError) -> None:
        """The connection is gone: every call waiting for the graph raises ``error``."""
        self._failed = error
        self._updated.set()

    @contextlib.asynccontextmanager
    async def _held(self) -> AsyncIterator[None]:
        """The graph subscription, held for the block, once the server's
        whole graph has arrived; ``ServiceTimeout`` after
        ``options.service_timeout`` without it."""
        _require(self._capabilities(), "connectionGraph", "connection graph")
        self._users += 1
        try:
            if self._users == 1:
                self._current = False
                self._published.clear()
                self._subscribed.clear()
                self._provided.clear()
                await self._send_request(self._engine.subscribe_connection_graph())
            limit = self._options.service_timeout
            with anyio.move_on_after(limit):
                while not self._current and self._failed is None:
                    await self._updated.wait()
            if self._failed is not None:
                raise self._failed
            if not self._current:
                raise ServiceTimeout("subscribeConnectionGraph", limit)
            yield
        finally:
            self._users -= 1
            if not self._users:
                with (
                    anyio.CancelScope(shield=True),
                    anyio.move_on_after(self._options.teardown_timeout),
                    contextlib.suppress(ConnectError),
                ):
                    await self._send_request(self._engine.unsubscribe_connection_graph())

    async def nodes(self) -> list[str]:
        """Every id the graph names: publishers, subscribers and service
        providers, sorted."""
        async with self._held():
            names: set[str] = set()
            for table in (self._published, self._subscribed, self._provided):
                for ids in table.values():
                    names.update(ids)
        return sorted(names)

    async def topic_endpoints(self, topic: str) -> TopicEndpoints:
        async with self._held():
            pubs = self._published.get(topic, ())
            subs = self._subscribed.get(topic, ())
        return TopicEndpoints(topic, pubs, subs)


class FoxglovePlayback:
    """Playback control requests and the states answering them (a
    :class:`~._seam.PlaybackControl`)."""

    def __init__(
        self,
        engine: fx.FoxgloveEngine,
        send_request: Callable[[bytes], Awaitable[None]],
        check_pending: Callable[[str], None],
        capabilities: Callable[[], tuple[str, ...]],
    ) -> None:
        self._engine = engine
        self._send_request = send_request
        self._check_pending = check_pending
        self._capabilities = capabilities
        self._ids = itertools.count(1)
        self.requests: PendingRequests[PlaybackState] = PendingRequests()

    async def control_playback(self, request: PlaybackRequest) -> PlaybackState:
        """Send ``request``; the state the server answers it with (the one
        carrying its request id). ``NotSupportedError`` without the
        ``playbackControl`` capability."""
        _require(self._capabilities(), "playbackControl", "playback control")
        self._check_pending("playbackControlRequest")
        request_id = f"rmb-{next(self._ids)}"
        frame = self._engine.playback_control(
            request.play, request.speed, request.seek_ns, request_id
        )
        return await self.requests.request(request_id, lambda: self._send_request(frame))

    def on_state(self, event: fx.PlaybackState) -> PlaybackState | None:
        """The public form of a state the server sent, handed to the request
        it answers; None for a status this client does not know."""
        status = _PLAYBACK_STATUS.get(event.status)
        if status is None:
            return None
        state = PlaybackState(
            status, event.current_time_ns, event.speed, event.did_seek, event.request_id or None
        )
        if event.request_id:
            self.requests.resolve(event.request_id, state)
        return state
