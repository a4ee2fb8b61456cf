"""One bounded, thread-safe least-recently-used map, for the codec's
process-wide caches (built codecs, descriptions learnt from robots)."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Hashable
from typing import Generic, TypeVar

__all__ = ["LruCache"]

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class LruCache(Generic[K, V]):
    """At most ``max_entries`` values by key; a :meth:`put` over the bound
    drops the least recently used entry (read or written) first. ``hits``
    counts the :meth:`get` calls that found a value, ``stored`` the
    :meth:`put` calls, ``evicted`` the entries dropped for the bound. Every
    method holds one lock, so any thread may call it."""

    def __init__(self, max_entries: int) -> None:
        self.max_entries = max_entries
        self.hits = 0
        self.stored = 0
        self.evicted = 0
        self._entries: OrderedDict[K, V] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: K) -> V | None:
        """The value under ``key`` (now the most recently used), or None."""
        with self._lock:
            value = self._entries.get(key)
            if value is not None:
                self._entries.move_to_end(key)
                self.hits += 1
            return value

    def put(self, key: K, value: V) -> None:
        """Keep ``value`` under ``key``, dropping the oldest over the bound."""
        with self._lock:
            self._entries[key] = value
            self._entries.move_to_end(key)
            self.stored += 1
            while len(self._entries) > self.max_entries:
                self._entries.popitem(last=False)
                self.evicted += 1

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Forget every entry (the counters stay)."""
        with self._lock:
            self._entries.clear()
