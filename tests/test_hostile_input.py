"""Input no real bridge sends, from the hostile server (trio-websocket in its
own process, ``peers.hostile``): skipped or refused, counted, never fatal and
never unbounded (issue 8, part 3). Every test runs on asyncio and trio."""

from __future__ import annotations

import contextlib
import logging
import tracemalloc

import anyio
import pytest

import ros_mobile_bridge as rmb
from _hostile import WIRE, options, until_data
from _util import wait_until
from peers.hostile import HostileServer

PROTOCOLS = pytest.mark.parametrize("protocol", ["foxglove", "rosbridge"])


async def _survives(scenario: str, protocol: str, **args: object) -> rmb.Client:
    """Connect, subscribe to /chatter, and read up to ``"after"`` (sent
    right after the fault): the client must still be connected then."""
    with HostileServer.start(scenario, protocol=protocol, **args) as server:
        with anyio.fail_after(20):
            async with rmb.connect(server.url, protocol=WIRE[protocol], options=options()) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await until_data(sub, "after")
                    assert robot.status == "connected"
                    assert robot.last_error is None
                    await until_data(sub, "1")  # and the stream goes on
                    return robot
    raise AssertionError("unreachable")


@PROTOCOLS
async def test_invalid_utf8_text_frame_is_skipped_and_counted(protocol: str) -> None:
    robot = await _survives("invalid_utf8", protocol)
    assert robot.rejections.get("invalid_utf8", 0) >= 1


async def test_cbor_status_with_20000_bit_integers_is_skipped() -> None:
    await _survives("cbor_bignum", "rosbridge")


# -- a message in one-byte continuation frames ------------------------------------------

SIZE = 96 * 1024
"""The message's size: over the 64 KiB frame limit of the refusal test, and
small enough that 98k one-byte frames parse in seconds with tracemalloc on."""
PARSER_STEP = 4 << 20
"""What the transport's bounded parser step may hold at once, whatever the
message (at most 64 KiB of input parsed into frames per step: about 22k
frame objects of ~150 B when each carries one byte). Reassembly itself must
stay proportional to the message; before the fix it cost ~150 B per byte
(15 MB for these 96 KiB, over three times the bound)."""


async def _fragmented(max_frame_size: int) -> tuple[rmb.Client, list[rmb.Message], int]:
    """The 256 KiB message in 1-byte frames; the messages delivered and the
    peak of memory the client allocated meanwhile (tracemalloc)."""
    got: list[rmb.Message] = []
    with HostileServer.start("one_byte_fragments", size=SIZE) as server:
        # (no keep-alive: a pong waits behind the ~100k frames, which a busy
        # machine's client, tracemalloc on, may take over 10 s to parse)
        opts = options(max_frame_size=max_frame_size, keepalive_interval=0)
        with anyio.fail_after(60):
            async with rmb.connect(server.url, protocol="foxglove-ws", options=opts) as robot:
                tracemalloc.start()
                try:
                    base = tracemalloc.get_traced_memory()[0]
                    tracemalloc.reset_peak()
                    async with robot.subscribe("/blob", adaptive=False) as sub:
                        with contextlib.suppress(rmb.NotConnected):
                            async for msg in sub:
                                got.append(msg)
                                if len(got) == 2:
                                    break
                    peak = tracemalloc.get_traced_memory()[1] - base
                finally:
                    tracemalloc.stop()
    print(f"\n1-byte fragments, {SIZE} B message: client allocation peak {peak / 1e6:.1f} MB")
    return robot, got, peak


async def test_message_in_one_byte_continuation_frames_is_delivered_in_bounded_memory() -> None:
    robot, got, peak = await _fragmented(64 * 1024 * 1024)
    assert len(got) == 2
    data = bytes(got[0].data.data)
    assert len(data) == SIZE - 21
    assert data == bytes(i % 251 for i in range(SIZE - 21))
    assert bytes(got[1].data.data) == b"end"
    assert robot.last_error is None
    assert peak < 4 * SIZE + PARSER_STEP, f"{peak} bytes allocated to reassemble {SIZE}"


async def test_one_byte_frames_over_max_frame_size_close_with_1009_in_bounded_memory() -> None:
    robot, got, peak = await _fragmented(64 * 1024)
    assert got == []
    assert robot.status == "error"
    assert "1009" in str(robot.last_error), str(robot.last_error)
    assert peak < 4 * SIZE + PARSER_STEP, f"{peak} bytes allocated before refusing {SIZE}"


# -- schemas and channels -------------------------------------------------------------------


async def test_schema_with_40000_fields_is_refused_and_other_channels_deliver() -> None:
    with HostileServer.start("huge_schema", fields=40_000) as server:
        with anyio.fail_after(20):
            async with rmb.connect(server.url, protocol="foxglove-ws", options=options()) as robot:
                async with contextlib.AsyncExitStack() as stack:
                    sub = await stack.enter_async_context(robot.subscribe("/chatter"))
                    # a refusal at subscribe time is as good as one later
                    with contextlib.suppress(rmb.RosBridgeError):
                        await stack.enter_async_context(robot.subscribe("/big"))
                    got = []
                    with anyio.fail_after(10):
                        async for msg in sub:
                            got.append(msg)
                            if len(got) == 5:
                                break
                    await wait_until(
                        lambda: robot.rejections.get("schema_too_large", 0) >= 1,
                        what="the schema to be refused",
                    )
                    assert robot.status == "connected"
                    assert robot.last_error is None


async def test_100000_channels_in_one_advertise_are_bounded_and_a_later_advertise_shows_up(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING)
    limit = rmb.ClientOptions().max_channels
    with HostileServer.start("many_channels", channels=100_000, delay=1) as server:
        # (generous waits: 100,000 channels are seconds of CPU for the server
        # and the client, more when the machine is busy)
        with anyio.fail_after(90):
            async with rmb.connect(server.url, protocol="foxglove-ws", options=options()) as robot:
                # the server advertises /early 1 s after the 100k channels: the
                # client is at its limit, so it is refused and counted
                await wait_until(lambda: server.events("sent_early"), timeout=30, what="/early")
                await wait_until(
                    lambda: robot.rejections.get("channel_limit", 0) >= 2,
                    timeout=30,
                    what="/early refused",
                )
                assert len(robot.topics) <= limit
                assert not any(t.name == "/early" for t in robot.topics)
                # then the flood is unadvertised and /late advertised: it shows
                # up (each advertisement costs what it changes); the ids the
                # client never kept (all but the limit less /chatter's) are
                # one rejection event, counted once per id and logged once.
                # (Nothing else here is malformed: the count is absolute, as a
                # loaded machine may read the unadvertise before this line.)
                await wait_until(
                    lambda: any(t.name == "/late" for t in robot.topics),
                    timeout=30,
                    what="/late in client.topics",
                )
                assert robot.status == "connected"
                assert not any(t.name.startswith("/c/") for t in robot.topics)
                never_kept = 100_000 - (limit - 1)
                assert robot.rejections.get("malformed", 0) == never_kept
                async with robot.subscribe("/chatter") as sub:
                    await until_data(sub, "1")
    unknown = [r for r in caplog.records if "unknown channel id" in r.getMessage()]
    assert len(unknown) == 1, [r.getMessage()[:80] for r in unknown[:5]]
    assert unknown[0].getMessage().startswith(f"skipped {never_kept} inputs from the server")


# -- what the library logs from the wire ----------------------------------------------------


@PROTOCOLS
async def test_50_mb_status_text_is_logged_truncated(
    protocol: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    with HostileServer.start("big_status", protocol=protocol) as server:
        with anyio.fail_after(30):
            async with rmb.connect(server.url, protocol=WIRE[protocol], options=options()) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await until_data(sub, "2", timeout=20)
                    assert robot.status == "connected"
        assert server.events("sent_status")
    longest = max(len(r.getMessage()) for r in caplog.records)
    assert any("bridge says" in r.getMessage() for r in caplog.records)
    assert longest < 8192, f"a log record of {longest} characters"
