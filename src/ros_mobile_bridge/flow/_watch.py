"""An observable value with async-iterator watchers (status, topic lists, ...)."""

from __future__ import annotations

from typing import Generic, TypeVar

import anyio

__all__ = ["Present", "Watchable", "Watcher"]

T = TypeVar("T")


class WatchCell(Generic[T]):
    """Internal, for :class:`Watchable` and its :class:`Watcher`: the state
    they share. The Watchable writes it (in :meth:`Watchable.set` and
    :meth:`Watchable.close`); a Watcher only reads it. Plain slots, so a
    watcher's wake-up reads attributes and calls nothing."""

    __slots__ = ("changed", "closed", "value", "version")

    def __init__(self, value: T) -> None:
        self.value = value
        self.version = 0
        self.changed = anyio.Event()
        self.closed = False


class Watchable(Generic[T]):
    """Holds a value; :meth:`watch` yields the current value at once, then
    every change. A slow watcher sees the newest value (changes in between
    are coalesced), never a backlog. :meth:`close` ends every watcher.

    ``cell``: internal, for :class:`Watcher` (the state it reads)."""

    def __init__(self, value: T) -> None:
        self.cell: WatchCell[T] = WatchCell(value)

    @property
    def value(self) -> T:
        return self.cell.value

    def set(self, value: T) -> bool:
        """Store ``value``; wakes watchers if it differs. Returns whether it did.

        A value that cannot be compared with the current one (decoded
        messages hold numpy arrays, whose ``==`` is element-wise and may
        raise) counts as different."""
        cell = self.cell
        try:
            same = value is cell.value or bool(value == cell.value)
        except (ValueError, TypeError):
            same = False
        if same:
            return False
        cell.value = value
        cell.version += 1
        changed, cell.changed = cell.changed, anyio.Event()
        changed.set()
        return True

    def close(self) -> None:
        cell = self.cell
        cell.closed = True
        cell.changed.set()

    def watch(self) -> Watcher[T]:
        return Watcher(self)


class Watcher(Generic[T]):
    """Async iterator over a :class:`Watchable`'s values."""

    def __init__(self, source: Watchable[T]) -> None:
        self._cell = source.cell
        self._seen: int | None = None

    def __aiter__(self) -> Watcher[T]:
        return self

    async def __anext__(self) -> T:
        cell = self._cell
        while self._seen == cell.version:
            if cell.closed:
                raise StopAsyncIteration
            await cell.changed.wait()
        self._seen = cell.version
        return cell.value


class Present(Generic[T]):
    """Async iterator over a ``Watchable[T | None]``'s values that are not
    None: the current one at once when there is one, then every change to
    a value (a value not yet known, None, is waited out)."""

    def __init__(self, source: Watchable[T | None]) -> None:
        self._values = source.watch()

    def __aiter__(self) -> Present[T]:
        return self

    async def __anext__(self) -> T:
        while True:
            value = await self._values.__anext__()
            if value is not None:
                return value
