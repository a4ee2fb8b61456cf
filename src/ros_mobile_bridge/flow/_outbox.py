"""The publish outbox: control-priority frames first, coalesced per topic, then data.

Control frames (``priority="control"``: ``/cmd_vel``, E-stop, dead-man
switches) are kept one per key, newest wins: after a burst of ten velocity
commands only the last one (usually the stop) goes out, ahead of every queued
data frame. The client's writer task drains the outbox; its reader task also
drains the control frames before it handles each inbound frame, so a flood of
camera frames cannot delay a stop by more than one frame's handling.

The outbox holds encoded wire messages and knows no protocol."""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable
from typing import Final, NamedTuple

import anyio

__all__ = ["Outbox", "TopicMessage", "WireMessage"]


class TopicMessage(NamedTuple):
    """An encoded message for a transport with no shared stream but one
    writer per topic (Zenoh): the adapter hands ``payload`` to ``topic``'s
    publisher when it sends it."""

    topic: str
    payload: bytes


WireMessage = str | bytes | TopicMessage
"""An encoded message ready for the transport: a WebSocket text (JSON ops)
or binary frame, or a :class:`TopicMessage`."""

_DEFAULT_DATA_LIMIT: Final = 1024


class Outbox:
    """Control frames (coalesced per key) ahead of data frames (FIFO, bounded).

    ``put_data`` waits for room when ``data_limit`` frames are queued, so a
    publisher faster than the socket is slowed down rather than silently
    dropped. ``put_control`` never waits."""

    def __init__(self, data_limit: int = _DEFAULT_DATA_LIMIT) -> None:
        if data_limit < 1:
            raise ValueError("data_limit must be at least 1")
        self._control: dict[Hashable, WireMessage] = {}
        self._data: deque[tuple[Hashable, WireMessage]] = deque()
        self._data_limit = data_limit
        self._ready = anyio.Event()
        self._room = anyio.Event()
        self.coalesced = 0
        """How many control frames were superseded before they were sent."""

    def __len__(self) -> int:
        return len(self._control) + len(self._data)

    @property
    def has_control(self) -> bool:
        return bool(self._control)

    def put_control(self, key: Hashable, message: WireMessage) -> None:
        """Queue ``message`` as the newest control frame for ``key``,
        replacing one still waiting for the same key. Data frames still queued
        for ``key`` are older values and are dropped too."""
        if any(k == key for k, _ in self._data):
            kept = [(k, m) for k, m in self._data if k != key]
            self.coalesced += len(self._data) - len(kept)
            self._data = deque(kept)
            self._room.set()
        control = self._control
        if key in control:
            self.coalesced += 1
            del control[key]  # the newest value also takes the newest place
        control[key] = message
        self._ready.set()

    async def put_data(self, key: Hashable, message: WireMessage) -> None:
        """Queue a data frame for ``key``, waiting while the queue is full."""
        while len(self._data) >= self._data_limit:
            if self._room.is_set():
                self._room = anyio.Event()
            await self._room.wait()
        self._data.append((key, message))
        self._ready.set()

    def pop_control(self) -> WireMessage | None:
        """The oldest pending control frame, or None."""
        control = self._control
        if not control:
            return None
        key = next(iter(control))
        return control.pop(key)

    def pop(self) -> WireMessage | None:
        """The next frame to send: control first, then data. None when empty."""
        message = self.pop_control()
        if message is not None:
            return message
        if self._data:
            _, message = self._data.popleft()
            self._room.set()
            return message
        return None

    async def get(self) -> WireMessage:
        """Wait for and return the next frame to send."""
        while True:
            message = self.pop()
            if message is not None:
                return message
            if self._ready.is_set():
                self._ready = anyio.Event()
            await self._ready.wait()

    def clear(self) -> int:
        """Discard every queued frame, control and data; returns how many."""
        n = len(self._control)
        self._control.clear()
        return n + self.drop_data()

    def drop_data(self) -> int:
        """Discard every queued data frame; returns how many."""
        n = len(self._data)
        self._data.clear()
        self._room.set()
        return n
