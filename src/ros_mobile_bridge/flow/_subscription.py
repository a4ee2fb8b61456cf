"""The subscription pipeline: raw frames in, filters ahead of decoding, decoded
messages out to the consumer.

Where a frame goes, in order:

1. The reader calls :meth:`FrameQueue.offer` (synchronous, never blocks).
2. The rate cap (``max_hz``, tightened by the adaptive throttle: a
   :class:`~._rate_window.RateWindow`) holds frames that arrive inside the
   current window; the newest held frame is delivered when the window ends
   (trailing delivery: the last message before a topic goes quiet always
   arrives, at most one window late). Older held frames are dropped, never
   decoded.
3. Dispatch: ``"all"`` queues every frame that passed, up to ``buffer``; a
   consumer that falls behind loses the *oldest* queued frames (counted, never
   decoded). ``"latest"`` keeps only the newest frame (conflation).
4. The consumer's ``async for`` takes a frame and decodes it, with the decoder
   captured when the frame arrived. A payload that does not decode is logged
   and delivered raw (``Message.data`` is the ``memoryview``).

Decoding on the consumer's pull, rather than in a producer task ahead of it,
means a dropped or superseded frame is never decoded and a message costs no
task switch when frames are already waiting."""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any, Final, Generic

import anyio
import anyio.lowlevel

from .._errors import DecodeError, NotConnected
from .._loop._wakeup import Wakeup, new_wakeup
from .._types import DataT, Dispatch, Message, SubscriptionState, SubscriptionStats
from ._breaker import CircuitBreaker
from ._frame import RawFrame, frame_message
from ._rate_window import Clock, RateWindow
from ._throttle import AdaptiveThrottle

__all__ = ["FrameQueue", "Subscription"]

_YIELD_EVERY: Final = 32
_LARGE_PAYLOAD: Final = 64 * 1024
_LARGE_WEIGHT: Final = 17  # a large payload counts as one message more per 128 KiB
HOLD_BYTES: Final = 64 * 1024
"""Payload bytes a subscription lets wait in the kernel while its reads are
held (:meth:`FrameQueue.quiet_until`): below a socket's default receive
buffer, so the server is never slowed by a hold."""


class FrameQueue:
    """Rate cap, conflation and the bounded queue of one subscription.

    The rate cap is a :class:`RateWindow` (``max_hz``, tightened by
    ``adaptive``); the frames it releases come to :meth:`_enqueue`.
    ``clock`` (monotonic seconds) is injectable so the filter is testable
    exactly. Synchronous apart from :meth:`get`."""

    def __init__(
        self,
        *,
        max_hz: float | None = None,
        dispatch: Dispatch = "all",
        buffer: int = 1024,
        max_bytes: int = 64 * 1024 * 1024,
        adaptive: Callable[[], float] | None = None,
        clock: Clock = time.monotonic,
    ) -> None:
        # (the window checks max_hz, first)
        window = RateWindow(
            max_hz,
            release=self._enqueue,
            supersede=self._supersede,
            adaptive=adaptive,
            clock=clock,
        )
        if dispatch not in ("all", "latest"):
            raise ValueError(f"dispatch must be 'all' or 'latest', got {dispatch!r}")
        if isinstance(buffer, bool) or not isinstance(buffer, int):
            raise TypeError("buffer must be an int")
        if buffer < 1:
            raise ValueError(f"buffer must be at least 1, got {buffer}")
        if isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 1:
            raise ValueError(f"max_bytes must be a positive int, got {max_bytes!r}")
        self.max_hz = max_hz
        self.dispatch: Dispatch = dispatch
        self.buffer = 1 if dispatch == "latest" else buffer
        self.max_bytes = max_bytes
        self._bytes = 0
        self._window = window
        # the window's offer, or None where it would pass every frame (no cap,
        # no adaptive throttle): the frame is then queued with no call more
        self._admit = None if window.unlimited else window.offer
        self.blocked = False
        """Set while the subscription's circuit breaker is tripped: frames
        are counted and dropped."""
        self._rate_start = clock()
        self._rate_bytes = 0
        self._arrival_rate = 0.0
        self._clock = clock
        self._queue: deque[RawFrame] = deque()
        # the consumer's wait (built at its first, on its loop), and whether
        # it waits with no time limit (a frame the cap holds must then wake
        # it, to arm its timer for the release)
        self._wakeup: Wakeup | None = None
        self._untimed = False
        self._closed = False
        self.error: Exception | None = None
        """Why the subscription ended (the connection was lost), once it did."""
        self.state: SubscriptionState = "pending"
        """``"active"`` while the server carries the topic; set by the router."""
        self._state_changed = anyio.Event()
        self.received = 0
        self.delivered = 0
        self.dropped_conflated = 0
        self.dropped_overflow = 0
        self.dropped_breaker = 0
        self.dropped_replay = 0
        self.decode_failures = 0
        self.bytes_received = 0
        """Payload bytes of every frame offered (``received``)."""

    @property
    def dropped_throttle(self) -> int:
        """Frames the rate cap replaced by a newer one (never delivered)."""
        return self._window.replaced

    @property
    def interval(self) -> float:
        """The effective minimum interval between delivered frames, seconds:
        the larger of the ``max_hz`` cap and the adaptive interval, as of the
        last frame that was not replaced inside a window (the adaptive
        interval is read once per window, when a frame arrives after it)."""
        return self._window.interval

    @property
    def arrival_bytes_per_s(self) -> float:
        """Payload bytes per second arriving over the last full second."""
        if self._clock() - self._rate_start >= 2.0:
            return 0.0  # nothing arrived for a whole window
        return self._arrival_rate

    def __len__(self) -> int:
        return len(self._queue) + (self._window.held is not None)

    # -- producer side (the reader) -----------------------------------------
    def offer(self, frame: RawFrame) -> None:
        """Route one frame through the filters: count it, then the breaker,
        the rate cap, the bounded queue. Never blocks, never decodes."""
        if self._closed:
            return
        self.received += 1
        now = self._clock()
        if now - self._rate_start >= 1.0:
            self._arrival_rate = self._rate_bytes / (now - self._rate_start)
            self._rate_start = now
            self._rate_bytes = 0
        size = frame.payload.nbytes
        self._rate_bytes += size
        self.bytes_received += size
        if self.blocked:
            self.dropped_breaker += 1
            return
        admit = self._admit
        if admit is None:
            self._enqueue(frame)
        elif admit(frame, now) and self._untimed:
            self._wake()  # the cap holds it: the waiting consumer arms its timer

    def quiet_until(self, now: float) -> float:
        """The monotonic time before which this subscription cannot take a
        new frame: the end of its rate cap's current window (a frame arriving
        before it would only be held by the cap, and replaced by any newer
        one), or sooner when :data:`HOLD_BYTES` would arrive before it at the
        rate of the last second. 0.0 when it can take one now: no cap, no
        frame released yet, closed, or its breaker tripped. The connection's
        reader may leave the socket unread until then and read what came
        meanwhile at once (see ``WebSocket.hold_reads``); the window is then
        :attr:`RateWindow.quiet`, so the frames read together at the end
        deliver the newest."""
        window = self._window
        last = window.last_release
        interval = window.interval
        if last is None or interval <= 0.0 or self._closed or self.blocked:
            return 0.0
        until = last + interval
        # bytes a second: the last full second's, or (higher, in the first
        # second) what came since, over at least 50 ms
        rate = self._rate_bytes / max(now - self._rate_start, 0.05)
        if self._arrival_rate > rate:
            rate = self._arrival_rate
        if rate > 0.0 and now + HOLD_BYTES / rate < until:
            until = now + HOLD_BYTES / rate
        window.quiet = True
        return until

    def replayed(self, size: int) -> None:
        """A frame of ``size`` payload bytes reached the client and was the
        message delivered last, replayed by the server on resubscription:
        received and dropped (``dropped_replay``), never queued."""
        if not self._closed:
            self.received += 1
            self.bytes_received += size
            self.dropped_replay += 1

    def _enqueue(self, frame: RawFrame) -> None:
        """Queue a frame the rate cap released, and wake the consumer."""
        queue = self._queue
        size = frame.payload.nbytes
        # bounded by count and by bytes (a queue of raw images is large);
        # the newest frame is always kept
        while queue and (len(queue) >= self.buffer or self._bytes + size > self.max_bytes):
            self._bytes -= queue.popleft().payload.nbytes
            if self.dispatch == "latest":
                self.dropped_conflated += 1
            else:
                self.dropped_overflow += 1
        queue.append(frame)
        self._bytes += size
        wakeup = self._wakeup  # (self._wake(), inline: once per frame)
        if wakeup is not None:
            wakeup.set()

    def _supersede(self, old: RawFrame, new: RawFrame) -> bool:
        """Put ``new`` in the place of ``old`` if ``old`` is the newest
        queued frame (no consumer has taken it yet); True if it did."""
        queue = self._queue
        if queue and queue[-1] is old:
            queue[-1] = new
            self._bytes += new.payload.nbytes - old.payload.nbytes
            return True
        return False

    def _wake(self) -> None:
        wakeup = self._wakeup
        if wakeup is not None:
            wakeup.set()

    def close(self) -> None:
        """No more frames will be offered; the consumer drains what is queued
        (and :meth:`wait_active` stops waiting)."""
        if not self._closed:
            self._closed = True
            self._wake()
            self._state_changed.set()

    def fail(self, error: Exception) -> None:
        """Close with ``error``: the consumer drains what is queued, then
        gets ``error`` (the connection was lost for good)."""
        if self.error is None:
            self.error = error
        self.close()

    def set_state(self, state: SubscriptionState) -> None:
        """The server now carries the topic (``"active"``) or not."""
        if state != self.state:
            self.state = state
            self._state_changed.set()
            self._state_changed = anyio.Event()

    async def wait_active(self, topic: str) -> None:
        """Return once :attr:`state` is ``"active"``; raise :attr:`error` (or
        ``NotConnected``) if the queue closes first."""
        while self.state != "active":
            if self._closed:
                raise self.error or NotConnected(f"the subscription to {topic} is closed")
            await self._state_changed.wait()

    async def next_frame(self) -> RawFrame:
        """The next frame, not decoded (the recorder writes CDR payloads as
        they came). It passed the same filters (throttle, breaker, buffer)
        and counts as delivered. ``StopAsyncIteration`` once closed and
        drained, :attr:`error` instead when the connection was lost."""
        frame = self.take()
        if frame is None:
            frame = await self.wait_frame()
        else:
            await anyio.lowlevel.checkpoint()
        self.delivered += 1
        return frame

    async def wait_frame(self) -> RawFrame:
        """:meth:`get`, ending as an iterator does: ``StopAsyncIteration``
        once closed and drained, or :attr:`error`."""
        try:
            return await self.get()
        except anyio.EndOfStream:
            if self.error is not None:
                raise self.error from None
            raise StopAsyncIteration from None

    @property
    def closed(self) -> bool:
        return self._closed

    # -- consumer side -------------------------------------------------------
    @property
    def waiting(self) -> bool:
        """Frames are queued for delivery (a frame held by the rate cap is
        not counted until its window ends)."""
        return bool(self._queue)

    def take(self) -> RawFrame | None:
        """The next frame ready for delivery, or None (releases a held frame
        whose window has ended)."""
        window = self._window
        if window.held is not None:
            window.release_due()
        if self._queue:
            frame = self._queue.popleft()
            self._bytes -= frame.payload.nbytes
            return frame
        return None

    async def get(self) -> RawFrame:
        """Wait for the next frame. Raises ``anyio.EndOfStream`` once closed
        and drained (a frame still held by the rate cap is delivered first)."""
        while True:
            frame = self.take()
            if frame is not None:
                return frame
            window = self._window
            if self._closed:
                held = window.take_held()
                if held is None:
                    raise anyio.EndOfStream
                return held
            wakeup = self._wakeup
            if wakeup is None:
                wakeup = self._wakeup = new_wakeup()
            if window.held is not None or window.holding:
                # a held frame is released when its window ends; and where the
                # cap held one in the last window (a stream faster than the
                # cap), the next window's end is armed now: its frames are held
                # without waking this task to arm it. (A window's end may be
                # taken a millisecond late.)
                await wakeup.wait(window.arm(), coarse=True)
            else:
                self._untimed = True
                try:
                    await wakeup.wait()
                finally:
                    self._untimed = False


class Subscription(Generic[DataT]):
    """A live subscription: ``async for msg in sub`` yields :class:`Message`.

    Obtained from ``Client.subscribe(...)``, an async context manager;
    leaving its block unsubscribes. Iteration ends (after the frames already
    queued) when the subscription or the client closes, and raises
    ``NotConnected`` when the connection was lost.

    ``Subscription[Odometry]`` (what ``subscribe(topic, Odometry)`` gives)
    yields ``Message[Odometry]``: a message that decodes to anything but an
    ``Odometry`` (the robot's definition of the type differs from the
    class's) is delivered raw with a ``decode_error`` saying so."""

    def __init__(
        self,
        topic: str,
        queue: FrameQueue,
        *,
        logger: logging.Logger,
        throttle: AdaptiveThrottle | None = None,
        breaker: CircuitBreaker | None = None,
        decode: bool = True,
        want: type | None = None,
    ) -> None:
        self.topic = topic
        self._queue = queue
        self._decoding = decode
        self._want = want
        self._throttle = throttle
        self.breaker: CircuitBreaker = breaker if breaker is not None else CircuitBreaker()
        """This subscription's circuit breaker: ``state``, ``next_retry_at``
        (monotonic seconds), ``retry()``, ``disable()``, ``watch()``. While
        it is tripped the bridge stops sending the topic (unless another
        local subscription still wants it); manual changes apply within the
        client's next reliability tick (200 ms)."""
        self._logger = logger
        self._since_yield = 0
        # the next frame once one arrives; StopAsyncIteration once closed and
        # drained (the connection's error instead, when it was lost). Bound
        # here, not wrapped: no call layer on the consumer's path
        self._wait = queue.wait_frame
        self._take = queue.take  # the next frame already waiting, or None

    @property
    def state(self) -> SubscriptionState:
        """``"pending"`` until the server carries the topic to this client
        (it may not be advertised yet), then ``"active"``."""
        return self._queue.state

    async def wait_active(self) -> None:
        """Return once the subscription is active. Raises ``NotConnected``
        (or the connection's error) if it closes first."""
        await self._queue.wait_active(self.topic)

    @property
    def stats(self) -> SubscriptionStats:
        """A snapshot of this subscription's counters."""
        q = self._queue
        return SubscriptionStats(
            received=q.received,
            delivered=q.delivered,
            dropped_throttle=q.dropped_throttle,
            dropped_conflated=q.dropped_conflated,
            dropped_overflow=q.dropped_overflow,
            decode_failures=q.decode_failures,
            effective_interval_ms=q.interval * 1000.0,
            dropped_breaker=q.dropped_breaker,
            bucket=self._throttle.bucket_label if self._throttle is not None else "",
            arrival_bytes_per_s=q.arrival_bytes_per_s,
            bytes_received=q.bytes_received,
            dropped_replay=q.dropped_replay,
        )

    def __aiter__(self) -> Subscription[DataT]:
        return self

    def batches(self, max_size: int = 256) -> Batches[DataT]:
        """Iterate over lists of messages instead of one message at a time:
        ``async for batch in sub.batches(): for msg in batch: ...``.

        Each batch holds every message already waiting, in order, at least
        one and at most ``max_size`` (a payload of 64 KiB or more ends a
        batch, so one batch never decodes more than one large message). When
        none is waiting it waits as ``async for msg in sub`` does, ends the
        same way, and raises the same error. The throttle, conflation and
        breaker apply exactly as for single messages; only the hand-over is
        batched: one cancellation check and one turn of the event loop per
        batch instead of per message, for consumers of heavy streams. Both
        forms take from the same queue; use one at a time.

        Raises ``TypeError`` or ``ValueError`` at once for a ``max_size``
        that is not a positive int."""
        if isinstance(max_size, bool) or not isinstance(max_size, int):
            raise TypeError(f"max_size must be an int, not {type(max_size).__name__}")
        if max_size < 1:
            raise ValueError(f"max_size must be at least 1, got {max_size}")
        return Batches(self._next_batch, max_size)

    async def _next_batch(self, max_size: int) -> list[Message[DataT]]:
        queue = self._queue
        # a pending cancellation is taken before any frame leaves the queue;
        # when frames are waiting, the loop also gets one turn per batch (the
        # reader and other tasks run), as ``__anext__`` gives it every 32
        if queue.waiting:
            await anyio.lowlevel.checkpoint()
        else:
            await anyio.lowlevel.checkpoint_if_cancelled()
        frame = queue.take() or await self._wait()
        if not self._decoding:
            return self._raw_batch(frame, max_size)
        batch: list[Message[DataT]] = []
        append = batch.append
        take = queue.take
        undecoded = self._undecoded
        want = self._want
        delivered = 0
        try:
            # each frame decoded here, as ``__anext__`` does: one call less
            while True:
                delivered += 1
                payload = frame.payload
                size = payload.nbytes
                decode = frame.decode
                if decode is None:
                    append(undecoded(frame, None))
                else:
                    try:
                        data = decode(payload)
                    except Exception as exc:  # a codec bug must not end the subscription
                        append(undecoded(frame, exc))
                    else:
                        if want is not None and data.__class__ is not want:
                            append(self._unwanted(frame, data))
                        else:
                            append(frame_message(frame, data, size, None))
                if delivered >= max_size or size >= _LARGE_PAYLOAD:
                    break
                more = take()
                if more is None:
                    break
                frame = more
        finally:
            queue.delivered += delivered
        return batch

    def _raw_batch(self, frame: RawFrame, max_size: int) -> list[Message[DataT]]:
        """:meth:`_next_batch`'s batch from ``frame`` on, ``decode=False``."""
        raw = self._raw
        batch = [raw(frame)]
        size = frame.payload.nbytes
        take = self._queue.take
        while len(batch) < max_size and size < _LARGE_PAYLOAD:
            more = take()
            if more is None:
                break
            batch.append(raw(more))
            size = more.payload.nbytes
        return batch

    async def __anext__(self) -> Message[DataT]:
        # A pending cancellation is taken before a frame leaves the queue, so
        # a cancelled ``__anext__`` raises and loses nothing. While frames are
        # waiting, the consumer yields to the loop (the reader and other tasks
        # run, and a cancellation is taken) once every 32 messages, a payload
        # of 64 KiB or more counting as one more per 128 KiB (a 921 KB image:
        # 8, so about 4 MiB of images between two yields): fair, without a
        # task switch per message, and a reader running ahead with images
        # does not pile them up (each one a fresh buffer) while the consumer
        # yields after each. The first call after a wait checks for
        # cancellation alone (the message taken at a yield counts as the
        # first of the next 32, already checked); between yields, no check
        # (anyio's costs about 1.4 us on asyncio, as much as the rest of a
        # small message's delivery), so a cancelled consumer of a steady
        # stream sees the cancellation within 32 messages.
        since = self._since_yield + 1
        if since > _YIELD_EVERY:
            since = 1
            await anyio.lowlevel.checkpoint()
        elif since == 1:
            await anyio.lowlevel.checkpoint_if_cancelled()
        frame = self._take()
        if frame is None:
            frame = await self._wait()
            since = 0
        payload = frame.payload
        size = payload.nbytes
        if size >= _LARGE_PAYLOAD:
            since += size >> _LARGE_WEIGHT  # about 4 MiB between two yields
        self._since_yield = since
        if not self._decoding:
            return self._raw(frame)
        self._queue.delivered += 1
        decode = frame.decode
        if decode is None:
            return self._undecoded(frame, None)
        try:
            data = decode(payload)
        except Exception as exc:  # a codec bug must not end the subscription
            return self._undecoded(frame, exc)
        if self._want is not None and data.__class__ is not self._want:
            return self._unwanted(frame, data)
        return frame_message(frame, data, size, None)

    def _unwanted(self, frame: RawFrame, data: Any) -> Message[DataT]:
        """A frame that decoded to something other than the class this
        subscription names: delivered raw, with the reason."""
        want: Any = self._want
        got = getattr(data, "__ros_hash__", None)
        if got is None:
            reason = f"not a {want.__ros_type__} but a {type(data).__name__}"
        else:
            reason = (
                f"the robot's {frame.schema_name} has another definition than "
                f"{want.__qualname__} ({got} != {want.__ros_hash__})"
            )
        return self._undecoded(
            frame, DecodeError(f"cannot decode as {want.__qualname__}: {reason}")
        )

    def _undecoded(self, frame: RawFrame, exc: Exception | None) -> Message[DataT]:
        """A delivered frame whose payload did not decode (``exc``; None: no
        decoder): logged, counted, delivered raw."""
        payload = frame.payload
        if exc is None:
            error = f"no decoder for {frame.schema_name!r} ({frame.encoding})"
        elif isinstance(exc, DecodeError):
            error = str(exc)
        else:
            error = f"{type(exc).__name__}: {exc}"
        self._queue.decode_failures += 1
        self._logger.warning(
            "could not decode a %s message on %s (%d bytes), delivering it raw: %s",
            frame.schema_name or "schemaless",
            frame.topic,
            payload.nbytes,
            error,
        )
        return frame_message(frame, payload, payload.nbytes, error)

    def _raw(self, frame: RawFrame) -> Message[DataT]:
        """A subscription opened with ``decode=False``: the payload as it
        came (``memoryview``), the codec never called."""
        self._queue.delivered += 1
        payload = frame.payload
        return frame_message(frame, payload, payload.nbytes, None)

    def close(self) -> None:
        """Stop receiving; iteration ends after the queued frames."""
        self._queue.close()


class Batches(Generic[DataT]):
    """The async iterator :meth:`Subscription.batches` returns: each step is a
    non-empty ``list`` of :class:`Message`."""

    __slots__ = ("_max_size", "_next")

    def __init__(
        self, next_batch: Callable[[int], Awaitable[list[Message[DataT]]]], max_size: int
    ) -> None:
        self._next = next_batch
        self._max_size = max_size

    def __aiter__(self) -> Batches[DataT]:
        return self

    async def __anext__(self) -> list[Message[DataT]]:
        return await self._next(self._max_size)
