"""``save_bandwidth`` over Zenoh, against a real eclipse-zenoh router and a
raw eclipse-zenoh publisher putting 200 samples a second: the subscriber is
undeclared after each message taken and declared again when the next is
due, so the router forwards about one sample per delivery; each pause ends
its receiving thread; a subscription to the same topic without the mode
keeps the stream whole. (The talker of zenoh-ros2-sdk is in
``test_bytes_received_peers.py``.)"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import pytest

import ros_mobile_bridge as rmb
from _util import take, wait_until
from _util import zenoh_options as options
from test_zenoh import STRING, attachment, cdr, data_key, pump_threads

pytest.importorskip("zenoh")


class Talker:
    """Puts ``/fast`` Strings ``"m<seq>"`` at 200 Hz from a thread."""

    def __init__(self, raw: Any, domain: int) -> None:
        self.publisher = raw.declare_publisher(data_key(domain, "/fast"))
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        seq = 0
        while not self.stop.wait(0.005):
            seq += 1
            self.publisher.put(cdr(STRING, {"data": f"m{seq}"}), attachment=attachment(seq))


@pytest.fixture
def talker(raw: Any, zenoh_domain: int) -> Iterator[Talker]:
    t = Talker(raw, zenoh_domain)
    t.thread.start()
    try:
        yield t
    finally:
        t.stop.set()
        t.thread.join()
        t.publisher.undeclare()


async def test_the_subscriber_pauses_between_deliveries_and_its_threads_end(
    zenoh_router: Any, zenoh_domain: int, talker: Talker
) -> None:
    before = pump_threads()
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
        client.subscribe("/fast", max_hz=10, save_bandwidth=True, adaptive=False) as sub,
    ):
        got = await take(sub, 6)
        # one receiving thread at most: a pause ends it, a resumption starts one
        assert len({t for t in pump_threads() - before if t.is_alive()}) <= 1
        stats = sub.stats
    seqs = [m.sequence for m in got]
    assert seqs == sorted(seqs) and len(set(seqs)) == 6
    # about one sample per delivery (and those on their way at a pause: a
    # few on a loaded machine), where the 200 Hz stream would bring ~20 per
    # delivery at max_hz=10
    assert stats.received <= 4 * stats.delivered + 2, stats
    assert client.rejections == {}
    await wait_until(lambda: not (pump_threads() - before), what="the receiving threads end")


async def test_a_subscription_without_the_mode_keeps_the_stream_whole(
    zenoh_router: Any, zenoh_domain: int, talker: Talker
) -> None:
    """Several subscriptions to a topic pause only when every one asks: a
    second one without the mode resumes the stream at once, and gets every
    sample from then on."""
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
        client.subscribe("/fast", max_hz=5, save_bandwidth=True, adaptive=False) as saving,
    ):
        await take(saving, 2)  # paused now, until the next is due
        async with client.subscribe("/fast", adaptive=False, buffer=200) as every:
            whole = await take(every, 60)
            await take(saving, 2)  # and the first goes on, at its own cap
    seqs = [m.sequence for m in whole]
    assert seqs == list(range(seqs[0], seqs[0] + 60))  # none lost to a pause
    assert saving.stats.delivered == 4
    assert every.stats.dropped_replay == saving.stats.dropped_replay == 0
