"""The pending-request registry every adapter shares: correlate a request id
with the response that answers it, and fail every waiter when the connection
goes away, so no call waits forever."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Hashable
from typing import Generic, TypeVar

import anyio

from .._errors import RosBridgeError

__all__ = ["PendingRequests"]

T = TypeVar("T")


class _Slot(Generic[T]):
    __slots__ = ("error", "event", "value")

    def __init__(self) -> None:
        self.event = anyio.Event()
        self.value: T | None = None
        self.error: BaseException | None = None


class PendingRequests(Generic[T]):
    """Request id -> the task waiting for its answer.

    ``register`` then ``wait`` in the requesting task; ``resolve`` / ``fail``
    from the reader; ``fail_all`` when the connection is lost or closed."""

    def __init__(self) -> None:
        self._slots: dict[Hashable, _Slot[T]] = {}

    def __len__(self) -> int:
        return len(self._slots)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._slots

    def register(self, key: Hashable) -> None:
        """Start waiting for ``key``. ValueError if it is already pending."""
        if key in self._slots:
            raise ValueError(f"request {key!r} is already pending")
        self._slots[key] = _Slot()

    async def request(self, key: Hashable, send: Callable[[], Awaitable[object]]) -> T:
        """Register ``key``, run ``send`` (which puts the request on the
        wire), then wait for the answer. If ``send`` fails the registration
        is dropped and its error raised."""
        self.register(key)
        try:
            await send()
        except BaseException:
            self.discard(key)
            raise
        return await self.wait(key)

    def discard(self, key: Hashable) -> None:
        """Forget ``key`` without answering it (the request was never sent)."""
        self._slots.pop(key, None)

    async def wait(self, key: Hashable) -> T:
        """Wait for ``key``'s answer and return it, or raise its failure.

        The registration is removed however this ends (answer, failure,
        cancellation or timeout), so a late answer is simply ignored."""
        slot = self._slots[key]
        try:
            await slot.event.wait()
        finally:
            self._slots.pop(key, None)
        if slot.error is not None:
            raise slot.error
        return slot.value  # type: ignore[return-value]

    def resolve(self, key: Hashable, value: T) -> bool:
        """Answer ``key``. Returns False when nobody is waiting for it."""
        slot = self._slots.get(key)
        if slot is None or slot.event.is_set():
            return False
        slot.value = value
        slot.event.set()
        return True

    def fail(self, key: Hashable, error: BaseException) -> bool:
        """Fail ``key`` with ``error``. Returns False when nobody is waiting."""
        slot = self._slots.get(key)
        if slot is None or slot.event.is_set():
            return False
        slot.error = error
        slot.event.set()
        return True

    def fail_all(self, error: RosBridgeError) -> int:
        """Fail every pending request with ``error``; returns how many."""
        n = 0
        for slot in self._slots.values():
            if not slot.event.is_set():
                slot.error = error
                slot.event.set()
                n += 1
        return n
