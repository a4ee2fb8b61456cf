"""What a Foxglove server offers beside topics, services and parameters,
against the official Foxglove SDK server (a real peer, in-process): assets,
the connection graph, the server's clock, its status messages. Every test
runs on asyncio and trio."""

from __future__ import annotations

import logging
import re

import anyio
import foxglove
import pytest
from foxglove.websocket import Capability, PlaybackState, PlaybackStatus

import ros_mobile_bridge as rmb
from _util import fast_options as options
from _util import wait_until
from peers.foxglove_sdk import ALL_CAPABILITIES, SdkServer
from ros_mobile_bridge.adapters import FoxgloveAdapter, RosbridgeAdapter, require
from ros_mobile_bridge.adapters._zenoh import ZenohAdapter
from ros_mobile_bridge.demo import DemoRobot

LOGGER = "ros_mobile_bridge"
MESH = b"solid demo\nendsolid demo\n"


def serve_mesh(uri: str) -> bytes | None:
    """The SDK server's asset handler: one mesh; a URI it refuses with a reason."""
    if uri == "package://demo/meshes/base.stl":
        return MESH
    if uri == "package://demo/meshes/broken.stl":
        raise PermissionError("the mesh store is locked")
    return None


# -- assets -------------------------------------------------------------------------------


async def test_fetch_asset_returns_the_servers_bytes_and_its_refusal_text() -> None:
    with SdkServer(asset_handler=serve_mesh) as server:
        async with rmb.connect(server.url, options=options()) as robot:
            assert "assets" in robot.server_info.capabilities
            assert await robot.fetch_asset("package://demo/meshes/base.stl") == MESH
            with pytest.raises(rmb.AssetError) as refused:
                await robot.fetch_asset("package://demo/meshes/broken.stl")
            assert refused.value.uri == "package://demo/meshes/broken.stl"
            assert "the mesh store is locked" in refused.value.reason
            with pytest.raises(rmb.AssetError, match="not found"):
                await robot.fetch_asset("package://demo/meshes/missing.stl")
            # several at once: each answer goes to its own request
            got: dict[str, bytes | str] = {}

            async def fetch(uri: str) -> None:
                try:
                    got[uri] = await robot.fetch_asset(uri)
                except rmb.AssetError as exc:
                    got[uri] = exc.reason

            async with anyio.create_task_group() as tg:
                for name in ("base", "broken", "base", "missing"):
                    tg.start_soon(fetch, f"package://demo/meshes/{name}.stl")
            assert got["package://demo/meshes/base.stl"] == MESH
            assert "locked" in str(got["package://demo/meshes/broken.stl"])
            assert robot.connected


async def test_fetch_asset_without_the_assets_capability_names_it() -> None:
    with SdkServer() as server:
        async with rmb.connect(server.url, options=options()) as robot:
            with pytest.raises(rmb.NotSupportedError, match="'assets' capability"):
                await robot.fetch_asset("package://demo/meshes/base.stl")
            with pytest.raises(ValueError, match="uri must be a URI"):
                await robot.fetch_asset("")


def test_only_foxglove_offers_assets_and_playback() -> None:
    """rosbridge and Zenoh have no such operation: their parts are None, and
    the client's one check names what is missing."""
    for adapter in (RosbridgeAdapter, ZenohAdapter):
        assert adapter.assets is None and adapter.playback is None
        with pytest.raises(rmb.NotSupportedError, match="no assets"):
            require(adapter.assets, "assets", adapter.protocol)
        with pytest.raises(rmb.NotSupportedError, match="no playback control"):
            require(adapter.playback, "playback", adapter.protocol)
    assert FoxgloveAdapter.protocol == "foxglove-ws"


# -- the connection graph -------------------------------------------------------------------


def graph(**published: list[str]) -> foxglove.ConnectionGraph:
    g = foxglove.ConnectionGraph()
    for topic, ids in published.items():
        g.set_published_topic(f"/{topic}", ids)
    return g


async def test_nodes_and_endpoints_come_from_the_connection_graph() -> None:
    with SdkServer() as server:
        g = graph(odom=["/base_driver", "/sim"], scan=["/lidar"])
        g.set_subscribed_topic("/odom", ["/nav2", "/rviz"])
        g.set_advertised_service("/reset", ["/sim"])
        server.server.publish_connection_graph(g)
        async with rmb.connect(server.url, options=options()) as robot:
            assert await robot.nodes() == ["/base_driver", "/lidar", "/nav2", "/rviz", "/sim"]
            odom = await robot.topic_endpoints("/odom")
            assert odom == rmb.TopicEndpoints("/odom", ("/base_driver", "/sim"), ("/nav2", "/rviz"))
            assert await robot.topic_endpoints("/none") == rmb.TopicEndpoints("/none", (), ())
            # the graph changed: the next call sees the server's graph now
            server.server.publish_connection_graph(graph(scan=["/lidar2"]))
            assert await robot.nodes() == ["/lidar2"]
            assert (await robot.topic_endpoints("/odom")).publishers == ()
            # subscribed only while a call needed it: each call subscribed and let go
            await wait_until(
                lambda: server.graph_subscriptions() == [True, False] * 5,
                what=server.graph_subscriptions,
            )


async def test_calls_at_once_share_one_graph_subscription() -> None:
    with SdkServer() as server:
        server.server.publish_connection_graph(graph(odom=["/a"], cmd_vel=["/b"]))
        async with rmb.connect(server.url, options=options()) as robot:
            answers: list[object] = []

            async def ask(topic: str) -> None:
                answers.append(await robot.topic_endpoints(topic))

            async with anyio.create_task_group() as tg:
                for topic in ("/odom", "/cmd_vel", "/odom"):
                    tg.start_soon(ask, topic)
            assert sorted(e.publishers for e in answers) == [("/a",), ("/a",), ("/b",)]  # type: ignore[attr-defined]
            # the three started together: one subscription, held until the last answered
            await wait_until(
                lambda: server.graph_subscriptions() == [True, False],
                what=server.graph_subscriptions,
            )


async def test_nodes_without_the_connection_graph_capability_names_it() -> None:
    caps = [c for c in ALL_CAPABILITIES if c != Capability.ConnectionGraph]
    with SdkServer(capabilities=caps) as server:
        async with rmb.connect(server.url, options=options()) as robot:
            with pytest.raises(rmb.NotSupportedError, match="'connectionGraph' capability"):
                await robot.nodes()
            with pytest.raises(rmb.NotSupportedError, match="'connectionGraph' capability"):
                await robot.topic_endpoints("/odom")


# -- the server's clock ---------------------------------------------------------------------


async def test_server_time_follows_the_servers_clock() -> None:
    with SdkServer() as server:
        async with rmb.connect(server.url, options=options()) as robot:
            assert robot.server_time is None
            seen: list[int] = []

            async def watch() -> None:
                async for t in robot.watch_server_time():
                    seen.append(t)
                    if t == 3_000_000_000:
                        return

            async with anyio.create_task_group() as tg:
                tg.start_soon(watch)
                server.server.broadcast_time(1_000_000_000)
                await wait_until(lambda: robot.server_time == 1_000_000_000)
                server.server.broadcast_time(3_000_000_000)
            assert seen[0] in (1_000_000_000, 3_000_000_000) and seen[-1] == 3_000_000_000
            assert robot.server_time == 3_000_000_000
            # a new watcher starts from the time known now
            with anyio.fail_after(5):
                assert await robot.watch_server_time().__anext__() == 3_000_000_000


# -- status messages ------------------------------------------------------------------------


async def test_status_messages_are_watched_and_logged_at_their_level(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger=LOGGER)
    with SdkServer() as server:
        async with rmb.connect(server.url, options=options()) as robot:
            events = robot.watch_server_status()
            server.server.publish_status("battery low", foxglove.StatusLevel.Warning, id="bat")
            server.server.publish_status("map loaded", foxglove.StatusLevel.Info)
            server.server.publish_status("lidar lost", foxglove.StatusLevel.Error, id="lidar")
            server.server.remove_status(["bat"])
            got = []
            with anyio.fail_after(5):
                async for event in events:
                    got.append(event)
                    if len(got) == 4:
                        break
            # (the SDK server does not keep the order of statuses of different levels)
            assert set(got) == {
                rmb.ServerStatus("warning", "battery low", "bat"),
                rmb.ServerStatus("info", "map loaded", None),
                rmb.ServerStatus("error", "lidar lost", "lidar"),
                rmb.StatusRemoved(("bat",)),
            }
            removed = got.index(rmb.StatusRemoved(("bat",)))
            assert removed > got.index(rmb.ServerStatus("warning", "battery low", "bat"))
    records = [(r.levelno, r.getMessage()) for r in caplog.records if r.name == LOGGER]
    assert (logging.WARNING, "server status: battery low") in records
    assert (logging.INFO, "server status: map loaded") in records
    assert (logging.ERROR, "server status: lidar lost") in records
    assert (logging.WARNING, "server status bat withdrawn: battery low") in records
    # the watcher ended with the client
    with anyio.fail_after(5):
        assert [e async for e in events] == []


# -- the demo robot serves both ---------------------------------------------------------------


async def test_demo_robot_serves_its_description_mesh_and_graph(robot: DemoRobot) -> None:
    async with rmb.connect(robot.url, options=options()) as client:
        urdf = (await client.fetch_asset("package://rmb_demo/urdf/rmb_demo.urdf")).decode()
        mesh_uri = re.search(r'<mesh filename="([^"]+)"', urdf)
        assert mesh_uri is not None
        mesh = await client.fetch_asset(mesh_uri[1])
        assert mesh.startswith(b"solid ") and mesh.count(b"facet normal") == 12
        with pytest.raises(rmb.AssetError, match="serves no package://rmb_demo/nothing"):
            await client.fetch_asset("package://rmb_demo/nothing")
        assert await client.nodes() == ["/rmb_demo_robot"]
        odom = await client.topic_endpoints("/odom")
        assert odom == rmb.TopicEndpoints("/odom", ("/rmb_demo_robot",), ())
        assert (await client.topic_endpoints("/cmd_vel")).subscribers == ("/rmb_demo_robot",)


# -- playback control -----------------------------------------------------------------------

START, END = 1_000_000_000, 9_000_000_000


async def test_playback_is_controlled_and_its_state_followed() -> None:
    with SdkServer(playback_time_range=(START, END)) as server:
        async with rmb.connect(server.url, options=options()) as robot:
            assert "playbackControl" in robot.server_info.capabilities
            assert robot.playback_state is None
            playing = await robot.control_playback(rmb.PlaybackRequest(play=True, speed=2.0))
            assert (playing.status, playing.current_time_ns, playing.speed) == (
                "playing",
                START,
                2.0,
            )
            assert not playing.did_seek and playing.request_id is not None
            seek = rmb.PlaybackRequest(play=False, speed=0.5, seek_ns=4_000_000_000)
            paused = await robot.control_playback(seek)
            assert paused == rmb.PlaybackState(
                "paused", 4_000_000_000, 0.5, True, paused.request_id
            )
            assert paused.request_id != playing.request_id
            # what the server received, field by field
            assert server.playback_requests() == [
                (True, 2.0, None, playing.request_id),
                (False, 0.5, 4_000_000_000, paused.request_id),
            ]
            assert robot.playback_state == paused
            # a state the server sends on its own: the recording ended
            states = robot.watch_playback()
            with anyio.fail_after(5):
                assert await states.__anext__() == paused
                server.server.broadcast_playback_state(
                    PlaybackState(PlaybackStatus.Ended, END, 0.5, False, None)
                )
                ended = await states.__anext__()
            assert ended == rmb.PlaybackState("ended", END, 0.5, False, None)
            assert robot.playback_state == ended


async def test_playback_control_without_the_capability_names_it() -> None:
    with SdkServer() as server:
        async with rmb.connect(server.url, options=options()) as robot:
            with pytest.raises(rmb.NotSupportedError, match="'playbackControl' capability"):
                await robot.control_playback(rmb.PlaybackRequest(play=True))
            with pytest.raises(TypeError, match="PlaybackRequest"):
                await robot.control_playback({"play": True})  # type: ignore[arg-type]
    assert server.playback_requests() == []


@pytest.mark.parametrize(
    ("fields", "error"),
    [
        ({"play": "yes"}, TypeError),
        ({"play": True, "speed": 0}, ValueError),
        ({"play": True, "speed": float("inf")}, ValueError),
        ({"play": True, "speed": "2"}, TypeError),
        ({"play": True, "seek_ns": -1}, ValueError),
        ({"play": True, "seek_ns": 1.5}, ValueError),
    ],
)
def test_a_bad_playback_request_is_refused_when_made(
    fields: dict[str, object], error: type[Exception]
) -> None:
    with pytest.raises(error):
        rmb.PlaybackRequest(**fields)  # type: ignore[arg-type]
