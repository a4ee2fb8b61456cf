"""The bookkeeping of ``save_bandwidth`` (``SubscribeHints.pause_hz``),
shared by the adapters that can stop a bridge's stream between deliveries:
which topics pause after each message and at what rate they resume, which
are paused (until when, and what the adapter needs to resume them), which
were just resumed (their first message may be the bridge's replay of the
one delivered last), and how long a resumed topic's next message took to
come (smoothed: the next resumption is made that much earlier).

It decides; the adapter does the I/O (unsubscribe, subscribe again) in
:meth:`PauseSchedule.run`'s callback and in its reader."""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import Generic, TypeVar

import anyio

from .._loop._wakeup import Wakeup, new_wakeup

K = TypeVar("K")

__all__ = ["PauseSchedule"]


class PauseSchedule(Generic[K]):
    """Per-topic pause state for one connection; ``K`` is what the adapter
    keeps with a paused topic to resume it (Foxglove: the channel; Zenoh:
    nothing). An adapter whose bridge replays on subscription passes each
    message's payload to :meth:`take`: the first message after a
    resumption is compared with the one delivered last, and only that
    first one, so a topic whose messages are all alike loses one per
    resumption, never the stream."""

    def __init__(self) -> None:
        self.rates: dict[str, float] = {}
        """topic -> the rate it resumes at; the readers' membership test."""
        self.paused: dict[str, tuple[float, K]] = {}
        """topic -> (when to resume it, the adapter's key)."""
        self._resumed: dict[str, tuple[float, bool]] = {}
        self._wait: dict[str, float] = {}
        self._last: dict[str, memoryview] = {}
        # run's wait (built there, on its loop) and the time it waits for
        # (inf: until a pause): a pause that is due no sooner does not wake it
        self._wakeup: Wakeup | None = None
        self._armed = math.inf

    def set_rate(self, topic: str, hz: float | None) -> None:
        """``topic`` pauses after each message and resumes at ``hz``; with
        None it no longer pauses (the caller resumes it if it is paused)."""
        if hz is not None:
            self.rates[topic] = hz
            return
        self.rates.pop(topic, None)
        self._resumed.pop(topic, None)
        self._last.pop(topic, None)

    def forget(self, topic: str) -> None:
        """Everything about ``topic`` (the user left it)."""
        self.rates.pop(topic, None)
        self.paused.pop(topic, None)
        self._resumed.pop(topic, None)
        self._wait.pop(topic, None)
        self._last.pop(topic, None)

    def take(self, topic: str, now: float, payload: memoryview | None = None) -> bool:
        """A message on a pausing topic: False when it is a replay to skip
        (the first message after a resumption, byte for byte the last
        ``payload`` delivered; the caller counts it); True when it is to be
        delivered, the caller then pausing the topic with :meth:`pause` if
        it still has the bridge's subscription. Without ``payload`` nothing
        is checked."""
        resumed = self._resumed.pop(topic, None)
        if resumed is not None:
            since, check = resumed
            last = self._last.get(topic)
            if (
                check
                and last is not None
                and payload is not None
                and last.nbytes == payload.nbytes
                and last == payload
            ):
                # the next one is delivered whatever it holds
                self._resumed[topic] = (since, False)
                return False
            waited = min(now - since, 0.5 / self.rates[topic])
            before = self._wait.get(topic)
            self._wait[topic] = waited if before is None else 0.75 * before + 0.25 * waited
        if payload is not None:
            self._last[topic] = payload
        return True

    def pause(self, topic: str, now: float, key: K) -> None:
        """Pause ``topic`` until its next message is due: as much earlier as
        the next message took to come lately (at most half the interval),
        so one arriving early waits in the subscription's rate cap and is
        delivered on time."""
        due = now + 1.0 / self.rates[topic] - self._wait.get(topic, 0.0)
        self.paused[topic] = (due, key)
        if due < self._armed and self._wakeup is not None:
            self._armed = -math.inf  # (woken once: run sets it again)
            self._wakeup.set()

    def unpause(self, topic: str) -> tuple[float, K] | None:
        """Take ``topic`` off the paused ones if it is (the caller subscribes
        again, or drops it) and forget the payload a replay would match."""
        self._resumed.pop(topic, None)
        self._last.pop(topic, None)
        return self.paused.pop(topic, None)

    def resumed(self, topic: str, now: float) -> None:
        """``topic`` was subscribed again at ``now``: its next message is
        timed, and checked for a replay."""
        self._resumed[topic] = (now, True)

    async def run(self, resume: Callable[[str, K], Awaitable[None]]) -> None:
        """Call ``resume(topic, key)`` for each paused topic when it is due
        (taken off the paused ones first); runs until cancelled, and an
        exception of ``resume`` ends it. One wait per pause and one per
        resumption, on the loop's own timer (:mod:`.._loop._wakeup`): a thousand
        connections in bandwidth mode wait thousands of times a second."""
        wakeup = self._wakeup = new_wakeup()
        try:
            while True:
                if not self.paused:
                    self._armed = math.inf
                    await wakeup.wait()
                    continue
                now = anyio.current_time()
                due = min(when for when, _ in self.paused.values())
                if due > now:
                    self._armed = due
                    await wakeup.wait(due - now, coarse=True)
                    continue
                self._armed = -math.inf  # resuming: a pause meanwhile needs no wake
                for topic in [t for t, (when, _) in self.paused.items() if when <= now]:
                    entry = self.paused.pop(topic, None)
                    if entry is not None:
                        await resume(topic, entry[1])
        finally:
            self._wakeup = None
