"""The rate cap on its own (``flow/_rate_window.py``, ``RateWindow``): what
passes at once, what is held and replaced, when a held frame is released,
where the next window starts, how a changing interval applies, and the
frames read together after a read hold.

Time is a fake clock advanced by hand (dyadic times where exactness
matters); the owner is a list the window releases into. No sleeps, nothing
asserted on the wall clock."""

from __future__ import annotations

import inspect
import time

import pytest

from ros_mobile_bridge.flow._frame import RawFrame
from ros_mobile_bridge.flow._rate_window import RateWindow


class FakeClock:
    """Monotonic seconds that move only when the test says so."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class Owner:
    """What a queue is to the window: the released frames, in order, and
    ``supersede`` for the one still waiting (``taken`` marks it handed over)."""

    def __init__(self) -> None:
        self.released: list[RawFrame] = []
        self.taken = 0

    def supersede(self, old: RawFrame, new: RawFrame) -> bool:
        if len(self.released) > self.taken and self.released[-1] is old:
            self.released[-1] = new
            return True
        return False

    def ids(self) -> list[int]:
        return [int(bytes(f.payload)) for f in self.released]

    def take_all(self) -> list[int]:
        """The ids released since the last call (handed over)."""
        out = self.ids()[self.taken :]
        self.taken = len(self.released)
        return out


def frame(i: int) -> RawFrame:
    return RawFrame("/t", "std_msgs/msg/Int32", "cdr", memoryview(str(i).encode()), None, i, None)


def window(
    max_hz: float | None, adaptive: float | None = None
) -> tuple[RateWindow, Owner, FakeClock, list[float]]:
    """A window on a fake clock; ``adaptive`` (when given) is the adaptive
    interval, changed through the returned list's first item, whose reads
    are appended to it."""
    clock = FakeClock()
    owner = Owner()
    reads: list[float] = [adaptive or 0.0]

    def interval() -> float:
        reads.append(clock.now)
        return reads[0]

    w = RateWindow(
        max_hz,
        release=owner.released.append,
        supersede=owner.supersede,
        adaptive=interval if adaptive is not None else None,
        clock=clock,
    )
    return w, owner, clock, reads


def offer(w: RateWindow, clock: FakeClock, i: int, at: float) -> bool:
    clock.now = at
    return w.offer(frame(i), at)


# -- pass ----------------------------------------------------------------------------
def test_the_first_frame_passes_at_once_and_starts_the_window() -> None:
    w, owner, clock, _ = window(4)  # 0.25 s windows
    assert w.last_release is None
    assert offer(w, clock, 0, 10.0) is False  # not held
    assert owner.ids() == [0]
    assert (w.held, w.last_release, w.interval) == (None, 10.0, 0.25)


def test_a_frame_an_interval_or_more_after_the_last_release_passes_at_once() -> None:
    w, owner, clock, _ = window(4)
    offer(w, clock, 0, 0.0)
    offer(w, clock, 1, 0.25)  # exactly one interval later
    offer(w, clock, 2, 10.0)  # after a quiet gap
    assert owner.ids() == [0, 1, 2]
    assert (w.replaced, w.held) == (0, None)
    assert w.last_release == 10.0  # far beyond the window: it starts at the release


def test_without_a_cap_every_frame_passes_and_the_owner_may_skip_the_window() -> None:
    w, owner, clock, _ = window(None)
    assert w.unlimited
    for i in range(5):
        assert offer(w, clock, i, 1.0) is False  # all at one instant
    assert owner.ids() == [0, 1, 2, 3, 4]
    assert (w.interval, w.replaced, w.last_release) == (0.0, 0, None)
    assert not window(None, adaptive=0.0)[0].unlimited  # an adaptive interval may come
    assert not window(4)[0].unlimited


# -- hold and replace ---------------------------------------------------------------------
def test_frames_inside_a_window_are_held_and_the_newest_replaces_the_older() -> None:
    w, owner, clock, _ = window(4)
    offer(w, clock, 0, 0.0)
    assert offer(w, clock, 1, 0.0625) is True  # starts a hold: a consumer arms its timer
    assert (w.held is not None, w.holding) == (True, True)
    assert offer(w, clock, 2, 0.125) is False  # replaces 1
    assert offer(w, clock, 3, 0.1875) is False  # replaces 2
    assert owner.ids() == [0]
    assert w.held is not None and int(bytes(w.held.payload)) == 3
    assert w.replaced == 2


def test_the_held_frame_is_released_when_its_window_ends_and_only_once() -> None:
    w, owner, clock, _ = window(4)
    offer(w, clock, 0, 0.0)
    offer(w, clock, 1, 0.0625)
    offer(w, clock, 2, 0.125)
    clock.now = 0.25 - 2e-6
    w.release_due()  # on the window's own clock (a consumer's poll)
    assert owner.ids() == [0]  # not before the window ends
    clock.now = 0.25 - 0.5e-6  # within a microsecond counts as ended
    w.release_due()
    assert owner.ids() == [0, 2]  # the newest of the window: trailing delivery
    assert (w.held, w.last_release) == (None, 0.25)  # the next window starts at the end
    clock.now = 100.0
    w.release_due()
    assert owner.ids() == [0, 2]  # released once


def test_an_offer_after_the_window_ended_releases_the_held_frame_first() -> None:
    w, owner, clock, _ = window(4)
    offer(w, clock, 0, 0.0)
    offer(w, clock, 1, 0.125)
    # the window ended at 0.25 (its frame released then); this frame is
    # inside the next window (0.25 .. 0.5): held
    assert offer(w, clock, 2, 0.3125) is True
    assert owner.ids() == [0, 1]
    assert w.held is not None and w.last_release == 0.25
    offer(w, clock, 3, 0.75)  # 2's window has ended: 2 first, then 3 at once
    assert owner.ids() == [0, 1, 2, 3]
    assert w.replaced == 0


def test_a_stream_faster_than_the_cap_gets_the_newest_frame_of_each_window() -> None:
    # 1024 Hz for a second under max_hz=8: exact dyadic times, exact schedule
    w, owner, clock, _ = window(8)
    for i in range(1024):
        offer(w, clock, i, i / 1024)
        w.release_due()
    assert owner.ids() == [0, *(128 * k - 1 for k in range(1, 8))]
    clock.now = 1.0
    w.release_due()
    assert owner.ids()[-1] == 1023  # the last window's frame, once it ends
    assert w.replaced == 1024 - 9


# -- cadence ----------------------------------------------------------------------------------
def test_a_release_a_little_late_keeps_the_cadence() -> None:
    w, owner, clock, _ = window(4)
    offer(w, clock, 0, 0.0)
    offer(w, clock, 1, 0.28125)  # 1/32 s late, under a quarter of the window: on cadence
    assert w.last_release == 0.25
    offer(w, clock, 2, 0.5)  # one window after 0.25, not after 0.28125
    assert owner.ids() == [0, 1, 2]
    offer(w, clock, 3, 0.8125)  # a quarter of the window late: the window starts here
    assert w.last_release == 0.8125
    assert offer(w, clock, 4, 1.0) is True  # held: 0.8125 + 0.25 is later


# -- interval changes ----------------------------------------------------------------------------
def test_the_adaptive_interval_is_read_once_per_window_not_per_frame() -> None:
    w, owner, clock, reads = window(4, adaptive=0.0)
    for i in range(16):  # 64 Hz for a quarter second
        offer(w, clock, i, i / 64)
    assert reads[1:] == [0.0, 1 / 64]  # opening the window, then starting the hold
    assert w.interval == 0.25
    reads[0] = 1.0  # the throttle tightened: read when the window ends
    offer(w, clock, 16, 0.25)
    assert reads[-1] == 0.25
    assert w.interval == 1.0
    assert owner.ids() == [0]  # the held frame's window is now a second long
    offer(w, clock, 17, 0.5)  # inside it: replaced, no read
    assert len(reads) == 4
    clock.now = 1.0
    w.release_due()
    assert owner.ids() == [0, 17]
    assert w.replaced == 16


def test_the_adaptive_interval_alone_caps_and_a_longer_cap_wins() -> None:
    w, owner, clock, _ = window(None, adaptive=0.5)
    offer(w, clock, 0, 0.0)
    assert offer(w, clock, 1, 0.25) is True  # inside the adaptive half second
    assert (w.interval, owner.ids()) == (0.5, [0])
    w2, _owner2, clock2, _ = window(4, adaptive=0.125)  # the cap's 0.25 s is longer
    offer(w2, clock2, 0, 0.0)
    assert w2.interval == 0.25


def test_a_lifted_interval_releases_the_held_frame_then_passes_every_frame() -> None:
    w, owner, clock, reads = window(None, adaptive=0.5)
    offer(w, clock, 0, 0.0)
    offer(w, clock, 1, 0.25)  # held until 0.5
    reads[0] = 0.0  # the throttle let go before the window ended
    offer(w, clock, 2, 0.5 - 1 / 64)  # inside the held frame's window: replaced, no read
    assert owner.ids() == [0]
    offer(w, clock, 3, 0.5)  # the window's end: read again, no cap any more
    offer(w, clock, 4, 0.5)
    assert owner.ids() == [0, 2, 3, 4]
    assert (w.interval, w.held, w.replaced) == (0.0, None, 1)


# -- read holds ---------------------------------------------------------------------------------
def test_frames_read_together_after_a_hold_deliver_the_newest() -> None:
    w, owner, clock, _ = window(5)  # 0.2 s windows
    offer(w, clock, 0, 0.0)
    assert owner.take_all() == [0]
    w.quiet = True  # the reader holds its reads until the window ends
    for i, t in enumerate((0.2002, 0.2003, 0.2004, 0.2005), start=1):
        offer(w, clock, i, t)  # read together, none taken meanwhile
    assert owner.take_all() == [4]  # each took the place of the one before
    assert (w.quiet, w.replaced, w.held) == (False, 3, None)


def test_a_read_together_frame_is_held_once_the_released_one_was_taken() -> None:
    w, owner, clock, _ = window(5)
    offer(w, clock, 0, 0.0)
    w.quiet = True
    offer(w, clock, 1, 0.2002)
    assert owner.take_all() == [0, 1]  # the consumer took it already
    assert offer(w, clock, 2, 0.2003) is True  # held for the next window instead
    assert owner.take_all() == []


def test_a_frame_a_quarter_interval_after_the_release_is_not_read_together() -> None:
    w, owner, clock, _ = window(4)  # 0.25 s windows: a quarter is 1/16 s
    offer(w, clock, 0, 0.0)
    w.quiet = True
    offer(w, clock, 1, 0.25)  # released, remembered
    assert offer(w, clock, 2, 0.3125) is True  # too late to be read together: held
    assert owner.ids() == [0, 1]


def test_without_a_hold_the_first_frame_after_the_window_passes_and_the_rest_are_held() -> None:
    w, owner, clock, _ = window(5)
    offer(w, clock, 0, 0.0)
    for i, t in enumerate((0.2002, 0.2003, 0.2004, 0.2005), start=1):
        offer(w, clock, i, t)
    assert owner.ids() == [0, 1]
    clock.now = 0.4
    w.release_due()
    assert owner.ids() == [0, 1, 4]


def test_the_release_at_a_window_end_while_quiet_is_the_one_read_together_frames_replace() -> None:
    w, owner, clock, _ = window(4)
    offer(w, clock, 0, 0.0)
    offer(w, clock, 1, 0.125)  # held
    w.quiet = True
    clock.now = 0.25
    w.release_due()  # the consumer's timer releases it
    offer(w, clock, 2, 0.25 + 1 / 64)  # read right after: takes its place
    assert owner.ids() == [0, 2]
    assert w.replaced == 1


# -- the consumer's timer, closing ------------------------------------------------------------------
def test_arm_is_the_time_to_the_window_end_and_clears_holding() -> None:
    w, _owner, clock, _ = window(4)
    offer(w, clock, 0, 0.0)
    offer(w, clock, 1, 0.0625)
    assert w.holding
    clock.now = 0.125
    assert w.arm() == 0.125
    assert not w.holding
    w.quiet = True  # the reader will offer what came meanwhile at the window end
    assert w.arm() == 0.125 + 0.0625  # the timer only if the reader does not
    w.quiet = False
    clock.now = 0.5
    assert w.arm() == 0.0  # already ended: no negative wait


def test_take_held_hands_over_the_held_frame_at_once() -> None:
    w, owner, clock, _ = window(4)
    offer(w, clock, 0, 0.0)
    offer(w, clock, 1, 0.0625)
    held = w.take_held()
    assert held is not None and int(bytes(held.payload)) == 1
    assert (w.held, w.take_held(), owner.ids()) == (None, None, [0])


# -- arguments ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("max_hz", [0, -1, float("nan")])
def test_max_hz_must_be_positive(max_hz: float) -> None:
    with pytest.raises(ValueError, match="max_hz must be positive"):
        window(max_hz)


@pytest.mark.parametrize("max_hz", [True, "10", [10]])
def test_max_hz_must_be_a_number(max_hz: object) -> None:
    with pytest.raises(TypeError, match="max_hz must be a number"):
        window(max_hz)  # type: ignore[arg-type]


def test_the_clock_is_monotonic_time_unless_given() -> None:
    assert inspect.signature(RateWindow).parameters["clock"].default is time.monotonic
