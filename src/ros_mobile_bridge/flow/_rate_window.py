"""The rate cap of one subscription (``max_hz``, tightened by the adaptive
throttle): which frames pass at once, which are held for the end of their
window, which are replaced. No queue, no I/O: frames leave through the
owner's callbacks, time comes from an injectable clock."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Final

from ._frame import RawFrame

__all__ = ["Clock", "RateWindow"]

Clock = Callable[[], float]
"""Monotonic seconds."""

_DUE_SLACK: Final = 1e-6
"""A window ending within this many seconds counts as ended: a timer that
short cannot be armed, and waiting for it would spin."""
_READ_TOGETHER: Final = 0.25
"""The share of the interval after a release made while :attr:`RateWindow.quiet`
within which a newer frame replaces the released one while the owner still
has it waiting: the frames read together at the end of a read hold deliver
the newest, as the cap would have, not the oldest."""
_CADENCE_GRACE: Final = 0.25
"""A release less than this share of the interval after its window ended
starts the next window at that end, not at the release."""


class RateWindow:
    """At most one frame per interval, the newest of each window.

    The interval is the larger of ``1 / max_hz`` (0.0 for ``None``) and
    ``adaptive()`` (the adaptive throttle's interval, when given). The
    contract, for frames offered in order on ``clock``'s time:

    * **Pass.** The first frame, and every frame offered at least one
      interval after the last release, is released at once (``release``).
    * **Hold.** A frame offered sooner is held; a newer frame offered before
      the held one is released replaces it (counted in :attr:`replaced`; the
      older one is never released). The held frame is released when its
      window ends (the last release plus the interval, a microsecond early
      counting as ended), by the first :meth:`offer` or :meth:`release_due`
      at or after that time: the last frame before a stream goes quiet is
      always released, at most one window late.
    * **Cadence.** A window's release taken less than a quarter of the
      interval after the window ended (read late, or after a read hold)
      starts the next window where the last one ended, so such delays do
      not add up; taken later, the next window starts at the release.
    * **Interval changes.** ``adaptive()`` is read by each :meth:`offer`
      that is not inside a held frame's window: once per window, not per
      frame. :attr:`interval` is the value last read. A longer interval
      moves the held frame's release later; an interval of 0.0 (no cap:
      none given, or the adaptive one lifted) releases every frame at once,
      a frame still held first.
    * **Read together.** While :attr:`quiet` is set (by the owner: its
      reader was told it may hold its reads until the window ends), the
      next release clears it and is remembered; a frame offered within a
      quarter of the interval after that release takes the released frame's
      place through ``supersede(released, frame)``, if the owner has not
      handed it over yet (``supersede`` returns False: the frame is held
      instead).

    With no cap and no adaptive throttle (:attr:`unlimited`) every frame
    passes; the owner may then skip :meth:`offer` and take the frame itself.

    Public state, for the owner to read (it writes :attr:`quiet` only):
    :attr:`held`, :attr:`holding`, :attr:`last_release`, :attr:`interval`,
    :attr:`replaced`. ``max_hz`` must be a positive number or ``None``
    (``TypeError``, ``ValueError``)."""

    __slots__ = (
        "_adaptive",
        "_cap",
        "_clock",
        "_due",
        "_release",
        "_released",
        "_released_at",
        "_supersede",
        "held",
        "holding",
        "interval",
        "last_release",
        "quiet",
        "replaced",
        "unlimited",
    )

    def __init__(
        self,
        max_hz: float | None,
        *,
        release: Callable[[RawFrame], None],
        supersede: Callable[[RawFrame, RawFrame], bool],
        adaptive: Callable[[], float] | None = None,
        clock: Clock = time.monotonic,
    ) -> None:
        if max_hz is not None:
            if isinstance(max_hz, bool) or not isinstance(max_hz, int | float):
                raise TypeError(f"max_hz must be a number or None, not {type(max_hz).__name__}")
            if not max_hz > 0:
                raise ValueError(f"max_hz must be positive, got {max_hz!r}")
        self._cap = 1.0 / max_hz if max_hz else 0.0
        self._adaptive = adaptive
        self._clock = clock
        self._release = release
        self._supersede = supersede
        self.unlimited = self._cap <= 0.0 and adaptive is None
        """No frame can ever be held: no cap and no adaptive throttle."""
        self.interval = self._cap
        """The interval in force, seconds (0.0: none), as last read."""
        self.held: RawFrame | None = None
        """The frame waiting for the end of its window, or None."""
        self.holding = False
        """A frame was held since the owner last called :meth:`arm`."""
        self.last_release: float | None = None
        """When the current window started (its release, or the previous
        window's end; see the cadence rule), or None before the first."""
        self.quiet = False
        """Set by the owner when its reader may hold its reads until the
        current window ends; cleared by the next release."""
        self.replaced = 0
        """Frames replaced by a newer one, never released."""
        self._due = 0.0  # when the held frame's window ends (set with held)
        self._released: RawFrame | None = None  # the release made while quiet
        self._released_at = 0.0

    def offer(self, frame: RawFrame, now: float) -> bool:
        """Pass, hold or replace ``frame`` (see the class's contract), and
        release a held frame whose window has ended. ``now`` is ``clock()``
        as read by the owner for this frame. True when ``frame`` started a
        hold (no frame was held): an owner's consumer that waits with no
        time limit must now arm a timer (:meth:`arm`)."""
        held = self.held
        if held is not None and now + _DUE_SLACK < self._due:
            # inside the window of a held frame (the common case of a rate
            # cap): the newer frame replaces it, released at the same time.
            # The interval is read again when the window ends, not per frame
            self.replaced += 1
            self.held = frame
            return False
        interval = self._cap
        adaptive = self._adaptive
        if adaptive is not None:
            tighter = adaptive()
            if tighter > interval:
                interval = tighter
            self.interval = interval
        if held is not None:  # its window has ended, or the interval changed
            self.release_due(now)
        if interval <= 0.0:
            self._release(frame)
            return False
        last = self.last_release
        if last is None or now - last >= interval:
            # a frame taken a little after the window ended (read after a
            # hold, or late under load) keeps the cap's cadence: the next
            # window starts where this one ended, so such delays do not add up
            due = now if last is None else last + interval
            self.last_release = due if now - due < interval * _CADENCE_GRACE else now
            if self.quiet:  # the first frame read after a hold
                self.quiet = False
                self._released = frame
                self._released_at = now
            self._release(frame)
            return False
        released = self._released
        if (
            released is not None
            and now - self._released_at < interval * _READ_TOGETHER
            and self._supersede(released, frame)
        ):
            # read together with the frame just released, which the owner
            # has not handed over yet: the newer one goes in its place
            self.replaced += 1
            self._released = frame
            return False
        self._due = last + interval
        if self.held is not None:  # the interval grew: its window ends later
            self.replaced += 1
            self.held = frame
            return False
        self.held = frame
        self.holding = True
        return True

    def release_due(self, now: float | None = None) -> None:
        """Release the held frame if its window has ended by ``now``
        (default: ``clock()``); the next window starts at that end."""
        held = self.held
        last = self.last_release
        if held is None or last is None:
            return
        if now is None:
            now = self._clock()
        due = last + self.interval
        if now + _DUE_SLACK >= due:
            self.held = None
            self.last_release = due
            if self.quiet:
                self.quiet = False
                self._released = held
                self._released_at = now
            self._release(held)

    def arm(self) -> float:
        """Seconds until the current window ends (0.0 if it has), for the
        timer of a consumer that waits while a frame is held, or was held in
        the last window (:attr:`holding`, which this clears): the timer's
        :meth:`release_due` then releases it, and a stream faster than the
        cap has its next windows' frames held without a wake-up each to arm
        it. While :attr:`quiet`, a quarter of the interval more: the reader
        offers what came meanwhile when the window ends (which releases the
        newest), the timer only if it does not."""
        self.holding = False
        last = self.last_release
        if last is None:
            return 0.0
        interval = self.interval
        delay = last + interval - self._clock()
        if self.quiet:
            delay += interval * _CADENCE_GRACE
        return delay if delay > 0.0 else 0.0

    def take_held(self) -> RawFrame | None:
        """The held frame, now, whatever its window (the owner is closing),
        or None."""
        held = self.held
        self.held = None
        return held
