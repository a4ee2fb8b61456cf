"""The httpx transport (``ClientOptions(http_client=...)``): the caller's
``httpx.AsyncClient`` makes the WebSocket upgrade, the library's own
WebSocket runs on the upgraded stream.

Peers: the Foxglove SDK server (plain and TLS), rosbridge_server_rs on a real
ROS 2 graph, and the token-checking proxy built on ``websockets``' server
(tests/_relay.py)."""

from __future__ import annotations

import ssl
import sys
from collections.abc import AsyncIterator, Iterator
from functools import partial

import anyio
import httpx
import pytest
import trustme

import ros_mobile_bridge as rmb
from _relay import Relay
from _util import fast_options, wait_until
from peers.foxglove_sdk import SdkServer, decode, string_msg
from peers.rosbridge import RosBridge

pytest_plugins = ["peers.ros_fixtures"]

TOKEN = "Bearer httpx-s3cret"


options = partial(fast_options, zero_twist_on_exit=False)


@pytest.fixture
async def client() -> AsyncIterator[httpx.AsyncClient]:
    async with httpx.AsyncClient() as c:
        yield c


async def first_message(sub: rmb.Subscription) -> rmb.Message:
    with anyio.fail_after(5):
        async for msg in sub:
            return msg
    raise AssertionError("subscription ended")


# -- Foxglove -------------------------------------------------------------------------


async def test_foxglove_negotiates_its_subprotocol_subscribes_and_publishes(
    server: SdkServer, client: httpx.AsyncClient
) -> None:
    chatter = server.channel("/chatter", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options(http_client=client)) as robot:
        assert robot.protocol == "foxglove-ws"
        assert robot.server_info.subprotocol == "foxglove.sdk.v1.1"
        assert [t.name for t in robot.topics] == ["/chatter"]
        async with robot.subscribe("/chatter") as sub:
            await wait_until(lambda: "/chatter" in server.subscribed())
            for i in range(50):
                chatter.log(string_msg(f"m{i}"))
            got = []
            with anyio.fail_after(5):
                async for msg in sub:
                    got.append(msg.data.data)
                    if len(got) == 50:
                        break
        await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.5}})
        await wait_until(lambda: server.messages("/cmd_vel"))
    assert got == [f"m{i}" for i in range(50)]
    twist = decode("geometry_msgs/msg/Twist", server.messages("/cmd_vel")[0].data)
    assert twist.linear.x == 0.5
    assert not client.is_closed  # the caller's client is the caller's to close


async def test_protocol_auto_through_httpx_finds_foxglove(
    server: SdkServer, client: httpx.AsyncClient
) -> None:
    async with rmb.connect(
        server.url, protocol="auto", options=options(http_client=client)
    ) as robot:
        assert robot.protocol == "foxglove-ws"


async def test_the_clients_default_headers_and_the_options_headers_reach_the_proxy(
    server: SdkServer,
) -> None:
    with Relay(server.url, require=("authorization", TOKEN)) as proxy:
        async with httpx.AsyncClient(headers={"Authorization": TOKEN}) as c:
            opts = options(http_client=c, headers={"X-Robot-Fleet": "north"})
            async with rmb.connect(proxy.url, options=opts) as robot:
                assert robot.server_info.subprotocol == "foxglove.sdk.v1.1"
        (headers,) = proxy.requests
    assert headers["Authorization"] == TOKEN
    assert headers["X-Robot-Fleet"] == "north"
    assert headers["Upgrade"].lower() == "websocket"


async def test_the_clients_auth_flow_applies_to_the_upgrade(server: SdkServer) -> None:
    class Bearer(httpx.Auth):
        def auth_flow(self, request: httpx.Request) -> Iterator[httpx.Request]:
            request.headers["Authorization"] = TOKEN
            yield request

    with Relay(server.url, require=("authorization", TOKEN)) as proxy:
        async with httpx.AsyncClient(auth=Bearer()) as c:
            async with rmb.connect(proxy.url, options=options(http_client=c)) as robot:
                assert robot.protocol == "foxglove-ws"


async def test_a_refused_upgrade_is_a_handshake_rejection_with_status_and_body(
    server: SdkServer, client: httpx.AsyncClient
) -> None:
    with Relay(server.url, require=("authorization", TOKEN)) as proxy:
        with pytest.raises(rmb.ConnectError) as caught:
            async with rmb.connect(
                proxy.url,
                protocol="foxglove-ws",
                options=options(http_client=client, reconnect=None),
            ):
                pass
    assert getattr(caught.value, "status", None) == 401
    assert "token required" in getattr(caught.value, "body", "")


async def test_a_refused_tcp_connection_is_a_connect_error(client: httpx.AsyncClient) -> None:
    with SdkServer() as srv:
        url = srv.url
    with pytest.raises(rmb.ConnectError, match="cannot connect"):
        async with rmb.connect(url, protocol="foxglove-ws", options=options(http_client=client)):
            pass


async def test_the_server_going_away_is_noticed(client: httpx.AsyncClient) -> None:
    srv = SdkServer()
    try:
        async with rmb.connect(
            srv.url, options=options(http_client=client, reconnect=None)
        ) as robot:
            assert robot.status == "connected"
            srv.stop()
            await wait_until(lambda: robot.status == "error", what="connection loss")
    finally:
        srv.stop()


async def test_a_message_over_max_frame_size_fails_the_connection_as_by_default(
    server: SdkServer, client: httpx.AsyncClient
) -> None:
    """The bounds are the library's WebSocket's, whichever transport opened it."""
    chatter = server.channel("/chatter", "std_msgs/msg/String")
    opts = options(http_client=client, max_frame_size=4096, reconnect=None)
    async with rmb.connect(server.url, options=opts) as robot:
        async with robot.subscribe("/chatter") as sub:
            await wait_until(lambda: "/chatter" in server.subscribed())
            chatter.log(string_msg("x" * 10_000))
            with pytest.raises(rmb.NotConnected), anyio.fail_after(5):
                async for _ in sub:
                    raise AssertionError("an oversized message was delivered")
        assert robot.status == "error"
        assert "1009" in str(robot.last_error), robot.last_error


async def test_wss_with_the_clients_tls_settings() -> None:
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1", "localhost")
    pem = b"".join(blob.bytes() for blob in cert.cert_chain_pems)
    with SdkServer(tls=(pem, cert.private_key_pem.bytes())) as srv:
        ctx = ssl.create_default_context()
        ca.configure_trust(ctx)
        chatter = srv.channel("/chatter", "std_msgs/msg/String")
        async with httpx.AsyncClient(verify=ctx) as c:
            async with rmb.connect(srv.url, options=options(http_client=c)) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await wait_until(lambda: "/chatter" in srv.subscribed())
                    chatter.log(string_msg("tls via httpx"))
                    msg = await first_message(sub)
        assert msg.data.to_dict() == {"data": "tls via httpx"}
        async with httpx.AsyncClient() as untrusting:  # the system CAs only
            with pytest.raises(rmb.ConnectError, match=r"(?i)certificate"):
                async with rmb.connect(
                    srv.url, options=options(http_client=untrusting, reconnect=None)
                ):
                    pass


# -- client transports that cannot upgrade ---------------------------------------------


def switching_protocols(request: httpx.Request) -> httpx.Response:
    """httpx's own MockTransport answering a correct 101 (the accept key
    computed by websockets), but a mock has no connection to hand over."""
    from websockets.utils import accept_key

    return httpx.Response(
        101,
        headers={
            "Upgrade": "websocket",
            "Connection": "Upgrade",
            "Sec-WebSocket-Accept": accept_key(request.headers["Sec-WebSocket-Key"]),
            "Sec-WebSocket-Protocol": "foxglove.sdk.v1.1",
        },
    )


async def test_a_transport_without_a_network_stream_is_a_connect_error_naming_it() -> None:
    async with httpx.AsyncClient(transport=httpx.MockTransport(switching_protocols)) as c:
        opts = options(http_client=c, reconnect=None)
        with pytest.raises(rmb.ConnectError, match="no network stream") as caught:
            async with rmb.connect("ws://robot.test:8765", protocol="foxglove-ws", options=opts):
                pass
    assert "MockTransport" in str(caught.value)


@pytest.mark.parametrize("status", [101, 200])
async def test_an_http2_answer_says_http2_whatever_its_status(status: int) -> None:
    """HTTP/2 has no 101 upgrade: a client with http2=True gets a 200 (or
    an error) from a server that would upgrade HTTP/1.1. The error names
    HTTP/2 rather than reporting a refused handshake."""

    def over_http2(request: httpx.Request) -> httpx.Response:
        return httpx.Response(status, extensions={"http_version": b"HTTP/2"})

    async with httpx.AsyncClient(transport=httpx.MockTransport(over_http2)) as c:
        opts = options(http_client=c, reconnect=None)
        with pytest.raises(rmb.ConnectError, match="answered over HTTP/2") as caught:
            async with rmb.connect("ws://robot.test:8765", protocol="foxglove-ws", options=opts):
                pass
    assert getattr(caught.value, "status", None) is None  # not a HandshakeRejected
    assert "without http2" in str(caught.value)


# -- rosbridge ------------------------------------------------------------------------


async def test_rosbridge_server_rs_through_httpx_with_auth_first(
    rosbridge: RosBridge, client: httpx.AsyncClient
) -> None:
    auth = rmb.RosbridgeAuth("mac", "127.0.0.1", "127.0.0.1", "rand", 1, "admin", 2)
    with Relay(rosbridge.url) as proxy:
        opts = options(http_client=client, rosbridge_auth=auth, latency_probe_interval=0)
        async with rmb.connect(proxy.url, protocol="rosbridge", options=opts) as robot:
            assert "/chatter" in [t.name for t in robot.topics]
            async with robot.subscribe("/chatter") as sub:
                msg = await first_message(sub)
            ok = await robot.call_service("/set_flag", {"data": True}, timeout=5)
        assert isinstance(msg.data.data, str)
        assert isinstance(ok.success, bool)  # a SetBool.Response
        assert '"op":"auth"' in str(proxy.sent[0])


# -- configuration errors ---------------------------------------------------------------


async def test_options_refuse_a_wrong_or_closed_client_and_an_ssl_context() -> None:
    with pytest.raises(TypeError, match=r"httpx\.AsyncClient"):
        rmb.ClientOptions(http_client=httpx.Client())  # type: ignore[arg-type]
    c = httpx.AsyncClient()
    with pytest.raises(ValueError, match="verify"):
        rmb.ClientOptions(http_client=c, ssl_context=ssl.create_default_context())
    await c.aclose()
    with pytest.raises(ValueError, match="closed"):
        rmb.ClientOptions(http_client=c)


def test_httpx_missing_is_a_clear_import_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "httpx", None)  # import httpx -> ImportError
    with pytest.raises(ImportError, match=r"pip install 'ros-mobile-bridge\[httpx\]'"):
        rmb.ClientOptions(http_client=object())  # type: ignore[arg-type]


async def test_httpx_missing_when_the_transport_is_opened(
    monkeypatch: pytest.MonkeyPatch, client: httpx.AsyncClient
) -> None:
    opts = options(http_client=client)
    monkeypatch.setitem(sys.modules, "httpx", None)
    monkeypatch.delitem(sys.modules, "ros_mobile_bridge.transport._httpx", raising=False)
    with pytest.raises(ImportError, match=r"\[httpx\]"):
        async with rmb.connect("ws://127.0.0.1:9", protocol="foxglove-ws", options=opts):
            pass


def test_the_library_without_http_client_does_not_import_httpx() -> None:
    import subprocess

    code = (
        "import sys, ros_mobile_bridge as rmb; "
        "rmb.ClientOptions(headers={'A': 'b'}); rmb.connect; rmb.Client; "
        "import ros_mobile_bridge.adapters; "
        "print(sorted(m for m in ('httpx', 'httpcore', 'httpx_ws') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert out.stdout.strip() == "[]"
