"""How an adapter hands its events up (``adapters/_shared.EventSource``):
in order, to ``deliver`` from the reader and ``post`` from elsewhere, and a
bounded, counted backlog before the reader runs."""

from __future__ import annotations

from ros_mobile_bridge.adapters import Event, Rejected, TopicState
from ros_mobile_bridge.adapters._shared import _KEPT_BEFORE_RUN, EventSource


class Sink:
    def __init__(self) -> None:
        self.delivered: list[list[Event]] = []
        self.posted: list[Event] = []

    async def deliver(self, events: list[Event]) -> None:
        self.delivered.append(events)

    def post(self, event: Event) -> None:
        self.posted.append(event)


def source() -> EventSource:
    return EventSource()


async def test_the_reader_delivers_in_order_and_elsewhere_posts() -> None:
    s, sink = source(), Sink()
    s.emit(TopicState("/a", True))  # before the reader: kept
    s.post()  # no sink yet: nothing goes anywhere
    s.attach(sink)
    s.reject("malformed", "x")
    await s.deliver()
    assert sink.delivered == [[TopicState("/a", True), Rejected("malformed", "x")]]
    await s.deliver()  # an inbound message with no events still reaches the sink
    assert sink.delivered[-1] == []
    s.emit(TopicState("/a", False))
    s.post()
    assert sink.posted == [TopicState("/a", False)]
    s.post()  # nothing left: nothing posted twice
    assert len(sink.posted) == 1


async def test_events_before_the_reader_are_bounded_and_the_drop_is_counted() -> None:
    s, sink = source(), Sink()
    for i in range(_KEPT_BEFORE_RUN + 44):
        s.emit(TopicState(f"/t{i}", True))
    s.attach(sink)
    await s.deliver()
    (events,) = sink.delivered
    assert len(events) == _KEPT_BEFORE_RUN + 1
    assert events[0] == TopicState("/t0", True)
    overflow = events[-1]
    assert isinstance(overflow, Rejected)
    assert (overflow.reason, overflow.count) == ("overflow", 44)
    # once the reader runs, nothing is dropped
    for i in range(_KEPT_BEFORE_RUN + 1):
        s.emit(TopicState(f"/u{i}", True))
    await s.deliver()
    assert len(sink.delivered[-1]) == _KEPT_BEFORE_RUN + 1
