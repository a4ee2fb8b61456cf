"""The hostile server (``peers.hostile_server``: trio-websocket in its own
process) serves the library as Foxglove and as rosbridge: the ground the
``test_hostile_*`` fault tests stand on."""

from __future__ import annotations

from functools import partial

import anyio
import pytest

import ros_mobile_bridge as rmb
from peers.hostile import HostileServer

options = partial(rmb.ClientOptions, connect_timeout=5.0, reconnect=None, discovery_grace=0.05)


@pytest.mark.parametrize("protocol", ["foxglove", "rosbridge"])
async def test_library_connects_and_receives(protocol: str) -> None:
    with HostileServer.start("chatter", protocol=protocol) as server:
        wanted = "foxglove-ws" if protocol == "foxglove" else "rosbridge"
        with anyio.fail_after(10):
            async with rmb.connect(server.url, protocol=wanted, options=options()) as robot:
                assert robot.protocol == wanted
                async with robot.subscribe("/chatter") as sub:
                    msg = await sub.__anext__()
        assert isinstance(msg.data.data, str) and msg.data.data.isdigit()
        assert [e["subprotocol"] for e in server.events("connect")] == (
            ["foxglove.sdk.v1"] if protocol == "foxglove" else [None]
        )
        ops = {e["op"] for e in server.received()}
        assert "subscribe" in ops
