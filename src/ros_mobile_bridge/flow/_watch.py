"""An observable value with async-iterator watchers (status, topic lists, ...)."""

from __future__ import annotations

from typing import Generic, TypeVar

import anyio

__all__ = ["Watchable", "Watcher"]

T = TypeVar("T")


class Watchable(Generic[T]):
    """Holds a value; :meth:`watch` yields the current value at once, then
    every change. A slow watcher sees the newest value (changes in between
    are coalesced), never a backlog. :meth:`close` ends every watcher."""

    def __init__(self, value: T) -> None:
        self._value = value
        self._version = 0
        self._changed = anyio.Event()
        self._closed = False

    @property
    def value(self) -> T:
        return self._value

    def set(self, value: T) -> bool:
        """Store ``value``; wakes watchers if it differs. Returns whether it did."""
        if value == self._value:
            return False
        self._value = value
        self._version += 1
        changed, self._changed = self._changed, anyio.Event()
        changed.set()
        return True

    def close(self) -> None:
        self._closed = True
        self._changed.set()

    def watch(self) -> Watcher[T]:
        return Watcher(self)


class Watcher(Generic[T]):
    """Async iterator over a :class:`Watchable`'s values."""

    def __init__(self, source: Watchable[T]) -> None:
        self._source = source
        self._seen: int | None = None

    def __aiter__(self) -> Watcher[T]:
        return self

    async def __anext__(self) -> T:
        source = self._source
        while self._seen == source._version:
            if source._closed:
                raise StopAsyncIteration
            await source._changed.wait()
        self._seen = source._version
        return source._value
