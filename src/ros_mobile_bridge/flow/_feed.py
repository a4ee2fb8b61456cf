"""A stream of events with async-iterator watchers, each with its own
bounded backlog (the server's status messages, ...): unlike a
:class:`~._watch.Watchable`, a watcher sees every event, not only the
newest, up to its bound."""

from __future__ import annotations

from collections import deque
from typing import Generic, TypeVar
from weakref import WeakSet

import anyio

__all__ = ["Feed", "FeedWatcher"]

T = TypeVar("T")


class FeedWatcher(Generic[T]):
    """Async iterator over the events a :class:`Feed` published since this
    watcher was made. When it falls ``backlog`` events behind, the oldest
    are dropped (counted in :attr:`dropped`); it ends when the feed closes,
    after the events it holds."""

    __slots__ = ("__weakref__", "_closed", "_items", "_wake", "dropped")

    def __init__(self, backlog: int) -> None:
        self._items: deque[T] = deque(maxlen=backlog)
        self._wake = anyio.Event()
        self._closed = False
        self.dropped = 0
        """Events dropped because this watcher fell behind."""

    def push(self, item: T) -> None:
        """(The feed's:) one more event."""
        if len(self._items) == self._items.maxlen:
            self.dropped += 1
        self._items.append(item)
        self._wake.set()

    def close(self) -> None:
        """(The feed's:) no more events."""
        self._closed = True
        self._wake.set()

    def __aiter__(self) -> FeedWatcher[T]:
        return self

    async def __anext__(self) -> T:
        while not self._items:
            if self._closed:
                raise StopAsyncIteration
            await self._wake.wait()
            self._wake = anyio.Event()
        return self._items.popleft()


class Feed(Generic[T]):
    """Publishes events to every live :class:`FeedWatcher` (held weakly: a
    watcher dropped without being read to its end costs nothing after)."""

    def __init__(self, backlog: int = 256) -> None:
        if backlog < 1:
            raise ValueError(f"backlog must be at least 1, got {backlog!r}")
        self._backlog = backlog
        self._watchers: WeakSet[FeedWatcher[T]] = WeakSet()
        self._closed = False

    def publish(self, item: T) -> None:
        for watcher in list(self._watchers):
            watcher.push(item)

    def close(self) -> None:
        """End every watcher (after the events it holds), and those made later."""
        self._closed = True
        for watcher in list(self._watchers):
            watcher.close()

    def watch(self) -> FeedWatcher[T]:
        """A watcher of the events published from now on."""
        watcher: FeedWatcher[T] = FeedWatcher(self._backlog)
        if self._closed:
            watcher.close()
        else:
            self._watchers.add(watcher)
        return watcher
