"""The Zenoh transport's parts that need no router: the thread-to-loop inbox,
targets and options, parameter values, ``.action`` texts, the missing extra
and a refused router."""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterator
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from peers.rosbridge import free_port
from ros_mobile_bridge._connect import parse_target
from ros_mobile_bridge.adapters._zenoh import (
    default_domain,
    parameter_from_ros,
    parameter_to_ros,
)
from ros_mobile_bridge.codec import CodecRegistry
from ros_mobile_bridge.transport._zenoh import PUMP_BATCH, Inbox, _pump
from ros_mobile_bridge.wire.rmw_zenoh import LivelinessChange, Samples, SessionLost

# -- the inbox: zenoh's threads to the event loop, in batches ---------------------


async def test_inbox_hands_over_every_item_in_order_in_few_batches() -> None:
    inbox = Inbox(max_items=100_000, max_bytes=1 << 30)
    count = 20_000
    wakes = 0
    original = inbox._wake

    def counting_wake() -> None:
        nonlocal wakes
        wakes += 1
        original()

    inbox._wake = counting_wake  # type: ignore[method-assign]

    def produce() -> None:
        for start in range(0, count, 7):  # batches of 7 samples, as a pump hands them over
            batch = [("k", i.to_bytes(4, "big"), None) for i in range(start, min(start + 7, count))]
            assert inbox.push_samples(1, batch, len(batch), start) == len(batch)
        inbox.push(LivelinessChange(0, "end", True))

    thread = threading.Thread(target=produce)
    thread.start()
    seen: list[int] = []
    stamps: list[int] = []
    batches = 0
    with anyio.fail_after(30):
        while True:
            batch = await inbox.get_batch()
            batches += 1
            done = False
            for item in batch:
                if type(item) is LivelinessChange:
                    done = True
                else:
                    assert type(item) is Samples
                    assert item.tag == 1
                    stamps.append(item.receive_time_ns)
                    seen.extend(int.from_bytes(payload, "big") for _k, payload, _a in item.samples)
            if done:
                break
    thread.join()
    assert seen == list(range(count))
    assert stamps == list(range(0, count, 7))
    assert inbox.overflowed == 0
    assert inbox.waiting == (0, 0)
    # one wake-up per batch at most, never one per item
    assert wakes <= batches + 1
    assert batches < count // 7


async def test_inbox_bounds_samples_and_bytes_and_counts_the_rest() -> None:
    inbox = Inbox(max_items=10, max_bytes=1000)
    one = [("k", b"x" * 10, None)]
    accepted = [inbox.push_samples(7, one, 10, 0) for _ in range(8)]
    assert accepted == [1] * 8
    assert inbox.waiting == (8, 80)
    # a batch that passes the bound: what fits is kept, in order; the rest counted
    batch = [("k", bytes([i]) * 10, None) for i in range(5)]
    assert inbox.push_samples(7, batch, 50, 0) == 2
    assert inbox.overflowed == 3
    assert inbox.overflowed_by_tag == {7: 3}
    assert inbox.waiting == (10, 100)
    assert inbox.push_samples(7, one, 10, 0) == 0
    assert inbox.overflowed_by_tag == {7: 4}
    inbox.push(LivelinessChange(0, "k", True))  # control items are never dropped
    items = await inbox.get_batch()
    assert [type(item) for item in items] == [Samples] * 9 + [LivelinessChange]
    kept = items[8]
    assert isinstance(kept, Samples)
    assert [payload for _k, payload, _a in kept.samples] == [b"\x00" * 10, b"\x01" * 10]
    assert inbox.waiting == (0, 0)
    # by bytes: one large sample passes alone, a second (however small) does not
    assert inbox.push_samples(8, [("k", b"x" * 5000, None)], 5000, 0) == 1
    assert inbox.push_samples(8, [("k", b"y", None)], 1, 0) == 0
    # within one batch too: a small one after the large one that passed alone
    await inbox.get_batch()
    both = [("k", b"x" * 5000, None), ("k", b"y", None)]
    assert inbox.push_samples(9, both, 5001, 0) == 1
    assert inbox.overflowed_by_tag == {7: 4, 8: 1, 9: 1}
    assert inbox.overflowed == 6


async def test_a_closed_inbox_takes_nothing_more() -> None:
    inbox = Inbox(max_items=10, max_bytes=1000)
    inbox.push_samples(1, [("k", b"x", None)], 1, 0)
    inbox.close()
    inbox.push(LivelinessChange(0, "k", True))
    assert inbox.push_samples(1, [("k", b"y", None)], 1, 0) == 0
    assert inbox.waiting == (0, 0)
    with anyio.move_on_after(0.2) as scope:
        await inbox.get_batch()
    assert scope.cancelled_caught  # nothing was queued before or after close


# -- the pump: a data subscriber's channel to the inbox ------------------------------
# A scripted channel stands in for zenoh's FIFO channel here: the faults below
# (a sample that cannot be read) are ones a real router cannot produce.


class Closed(Exception):
    """What the scripted channel raises once it is closed and empty."""


class Bytes:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class Key:
    """A key expression: equal by text, a new object per sample (as zenoh's)."""

    def __init__(self, text: str) -> None:
        self.text = text

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Key) and other.text == self.text

    def __hash__(self) -> int:
        return hash(self.text)

    def __str__(self) -> str:
        return self.text


class FakeSample:
    def __init__(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        self.key_expr = Key(key)
        self.payload = Bytes(payload)
        self.attachment = None if attachment is None else Bytes(attachment)


class Channel:
    """``recv`` takes the next sample, of the next burst (a list of samples)
    when the current one is done; ``try_recv`` takes what is left of the
    current burst, then None; after the last burst ``recv`` raises
    :class:`Closed`."""

    def __init__(self, bursts: list[list[Any]]) -> None:
        self.bursts: Iterator[list[Any]] = iter(bursts)
        self.current: list[Any] = []
        self.done = False

    def recv(self) -> Any:
        if self.current:
            return self.current.pop(0)
        try:
            self.current = list(next(self.bursts))
        except StopIteration:
            self.done = True
            raise Closed from None
        return self.current.pop(0)

    def try_recv(self) -> Any:
        if self.current:
            return self.current.pop(0)
        return None


async def test_the_pump_hands_bursts_over_in_order_in_bounded_batches() -> None:
    inbox = Inbox(max_items=100_000, max_bytes=1 << 30)
    big = [FakeSample("0/a/t/h", i.to_bytes(4, "big"), b"att") for i in range(PUMP_BATCH + 10)]
    small = [FakeSample("0/a/t/h" if i < 2 else "0/a/u/h", b"s%d" % i, None) for i in range(3)]
    channel = Channel([big, small])
    thread = threading.Thread(target=_pump, args=(channel, 5, inbox, Closed))
    thread.start()
    thread.join(10)
    assert not thread.is_alive() and channel.done  # it ended when the channel closed
    items = await inbox.get_batch()
    assert all(type(item) is Samples and item.tag == 5 for item in items)
    sizes = [len(item.samples) for item in items if isinstance(item, Samples)]
    assert sizes == [PUMP_BATCH, 10, 3]  # one burst past PUMP_BATCH is cut there
    samples = [sample for item in items if isinstance(item, Samples) for sample in item.samples]
    assert [int.from_bytes(p, "big") for _k, p, _a in samples[: PUMP_BATCH + 10]] == list(
        range(PUMP_BATCH + 10)
    )
    assert [a for _k, _p, a in samples] == [b"att"] * (PUMP_BATCH + 10) + [None] * 3
    keys = [k for k, _p, _a in samples]
    assert keys == ["0/a/t/h"] * (PUMP_BATCH + 12) + ["0/a/u/h"]
    assert len({id(k) for k in keys[: PUMP_BATCH + 12]}) == 1  # one string while the key holds
    assert inbox.items_received == PUMP_BATCH + 13
    assert inbox.bytes_received == 4 * (PUMP_BATCH + 10) + 6


async def test_a_pump_that_cannot_read_a_sample_ends_the_session() -> None:
    class Unreadable(FakeSample):
        @property  # type: ignore[override]
        def payload(self) -> Any:
            raise RuntimeError("a zenoh object gone bad")

        @payload.setter
        def payload(self, value: Any) -> None:
            pass

    inbox = Inbox(max_items=100, max_bytes=1000)
    good = FakeSample("0/a/t/h", b"x", None)
    channel = Channel([[good], [Unreadable("0/a/t/h", b"y", None)], [good]])
    thread = threading.Thread(target=_pump, args=(channel, 3, inbox, Closed))
    thread.start()
    thread.join(10)
    assert not thread.is_alive()
    items = await inbox.get_batch()
    assert [type(item) for item in items] == [Samples, SessionLost]
    lost = items[1]
    assert isinstance(lost, SessionLost)
    assert "subscriber 3" in lost.reason and "a zenoh object gone bad" in lost.reason
    assert not channel.done  # it stopped there: no sample after the failure is taken


# -- targets and options --------------------------------------------------------------


def test_zenoh_targets() -> None:
    assert parse_target("tcp/127.0.0.1:7448").zenoh_locator == "tcp/127.0.0.1:7448"
    ep = parse_target("robot.local", protocol="zenoh")
    assert (ep.zenoh, ep.zenoh_locator) == (True, "tcp/robot.local:7447")
    assert parse_target("[::1]:7000", protocol="zenoh").zenoh_locator == "tcp/[::1]:7000"
    with pytest.raises(ValueError, match="not a URL"):
        parse_target("ws://robot:9090", protocol="zenoh")
    assert parse_target("robot", protocol="zenoh", secure=True).zenoh_locator == ("tls/robot:7447")


def test_domain_id_option(monkeypatch: pytest.MonkeyPatch) -> None:
    assert rmb.ClientOptions(domain_id=42).domain_id == 42
    for bad in (-1, 233):
        with pytest.raises(ValueError, match="domain_id"):
            rmb.ClientOptions(domain_id=bad)
    with pytest.raises(TypeError, match="domain_id"):
        rmb.ClientOptions(domain_id="3")  # type: ignore[arg-type]
    monkeypatch.setenv("ROS_DOMAIN_ID", "17")
    assert default_domain() == 17
    for junk in ("", "x", "999", "-3"):
        monkeypatch.setenv("ROS_DOMAIN_ID", junk)
        assert default_domain() == 0
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert default_domain() == 0
    with pytest.raises(ValueError, match="zenoh_backlog"):
        rmb.ClientOptions(zenoh_backlog=0)
    with pytest.raises(TypeError, match="zenoh_shared_memory"):
        rmb.ClientOptions(zenoh_shared_memory=1)  # type: ignore[arg-type]


# -- parameter values -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "code"),
    [
        (True, 1),
        (3, 2),
        (2.5, 3),
        ("fast", 4),
        (b"\x01\x02", 5),
        ([True, False], 6),
        ([1, 2], 7),
        ([1.5, 2], 8),
        (["a", "b"], 9),
    ],
)
def test_parameter_values_round_trip(value: object, code: int) -> None:
    ros = parameter_to_ros(value)
    assert ros["type"] == code
    known, plain = parameter_from_ros(ros)
    assert known
    assert plain == ([1.5, 2.0] if code == 8 else value)


def test_parameter_values_refused() -> None:
    assert parameter_from_ros({"type": 0}) == (False, None)
    assert parameter_from_ros({"type": 99}) == (False, None)
    for bad in (None, {"a": 1}, [1, "a"], object()):
        with pytest.raises(ValueError, match="parameter type"):
            parameter_to_ros(bad)


# -- .action texts --------------------------------------------------------------------

_FIBONACCI = "int32 order\n---\nint32[] sequence\n---\nint32[] sequence\n"


def test_action_text_registers_the_derived_types() -> None:
    reg = CodecRegistry()
    reg.add_schema("test_msgs/action/Fibonacci", "ros2action", _FIBONACCI)
    encode = reg.encoder("test_msgs/action/Fibonacci_SendGoal_Request", "cdr")
    decode = reg.decoder("test_msgs/action/Fibonacci_SendGoal_Request", "cdr")
    payload = encode({"goal_id": {"uuid": list(range(16))}, "goal": {"order": 7}})
    back = decode(memoryview(payload))
    assert back.goal.to_dict() == {"order": 7}
    assert list(back.goal_id.uuid) == list(range(16))
    for suffix in ("_GetResult_Response", "_FeedbackMessage", "_SendGoal_Response"):
        reg.decoder(f"test_msgs/action/Fibonacci{suffix}", "cdr")
    with pytest.raises(rmb.SchemaError, match="three sections"):
        reg.add_schema("x/action/Y", "ros2action", "int32 a\n---\nint32 b\n")


# -- no extra, no router -------------------------------------------------------------------


async def test_without_eclipse_zenoh_the_error_names_the_extra(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(sys.modules, "zenoh", None)  # import zenoh -> ImportError
    with pytest.raises(rmb.NotSupportedError, match=r"ros-mobile-bridge\[zenoh\]"):
        async with rmb.connect("tcp/127.0.0.1:7447"):
            pass


async def test_a_refused_router_raises_connect_error_at_once() -> None:
    port = free_port()
    options = rmb.ClientOptions(connect_timeout=5.0)
    with anyio.fail_after(5):
        with pytest.raises(rmb.ConnectError, match="cannot reach a router"):
            async with rmb.connect(f"tcp/127.0.0.1:{port}", options=options):
                pass
