"""The Zenoh transport's parts that need no router: the thread-to-loop inbox,
targets and options, parameter values, ``.action`` texts, the missing extra
and a refused router."""

from __future__ import annotations

import sys
import threading

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
from ros_mobile_bridge.transport._zenoh import Inbox
from ros_mobile_bridge.wire.rmw_zenoh import LivelinessChange, Samples

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


# -- targets and options --------------------------------------------------------------


def test_zenoh_targets() -> None:
    assert parse_target("tcp/127.0.0.1:7448").zenoh_locator == "tcp/127.0.0.1:7448"
    ep = parse_target("robot.local", protocol="zenoh")
    assert (ep.zenoh, ep.zenoh_locator) == (True, "tcp/robot.local:7447")
    assert parse_target("[::1]:7000", protocol="zenoh").zenoh_locator == "tcp/[::1]:7000"
    with pytest.raises(ValueError, match="not a URL"):
        parse_target("ws://robot:9090", protocol="zenoh")
    with pytest.raises(ValueError, match="secure"):
        parse_target("robot", protocol="zenoh", secure=True)


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
    assert back["goal"] == {"order": 7}
    assert list(back["goal_id"]["uuid"]) == list(range(16))
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
