"""Connection options: handshake headers, the caller's TLS context, the
rosbridge ``auth`` operation.

Peers: the Foxglove SDK server (also over TLS: it serves ``wss://`` with a
certificate from a trustme CA), rosbridge_server_rs on a real ROS 2 graph,
and a reverse proxy built on ``websockets``' own server (tests/_relay.py)
that checks a bearer token and records what it relays."""

from __future__ import annotations

import functools
import json
import logging
import ssl
from collections.abc import Iterator
from functools import partial
from typing import Any

import anyio
import pytest
import trustme

import ros_mobile_bridge as rmb
from _relay import Relay
from _util import fast_options, wait_until
from peers.foxglove_sdk import SdkServer, string_msg
from peers.rosbridge import RosBridge

pytest_plugins = ["peers.ros_fixtures"]

TOKEN = "Bearer s3cret-token-4242"


options = partial(fast_options, zero_twist_on_exit=False)


@pytest.fixture(scope="module")
def ca() -> trustme.CA:
    return trustme.CA()


@pytest.fixture
def tls_server(ca: trustme.CA) -> Iterator[SdkServer]:
    cert = ca.issue_cert("127.0.0.1", "localhost")
    pem = b"".join(blob.bytes() for blob in cert.cert_chain_pems)
    with SdkServer(tls=(pem, cert.private_key_pem.bytes())) as srv:
        yield srv


async def first_message(sub: rmb.Subscription) -> rmb.Message:
    with anyio.fail_after(5):
        async for msg in sub:
            return msg
    raise AssertionError("subscription ended")


# -- headers ----------------------------------------------------------------------


async def test_headers_reach_a_token_checking_proxy_and_the_session_works(
    server: SdkServer,
) -> None:
    chatter = server.channel("/chatter", "std_msgs/msg/String")
    with Relay(server.url, require=("authorization", TOKEN)) as proxy:
        opts = options(headers={"Authorization": TOKEN, "X-Robot-Fleet": "north"})
        async with rmb.connect(proxy.url, options=opts) as robot:
            assert robot.protocol == "foxglove-ws"
            assert robot.server_info.subprotocol == "foxglove.sdk.v1.1"  # relayed
            async with robot.subscribe("/chatter") as sub:
                await wait_until(lambda: "/chatter" in server.subscribed())
                chatter.log(string_msg("through the proxy"))
                msg = await first_message(sub)
            await robot.publish("/note", "std_msgs/msg/String", {"data": "back"})
            await wait_until(lambda: server.messages("/note"))
        assert msg.data.to_dict() == {"data": "through the proxy"}
        (headers,) = proxy.requests
        assert headers["Authorization"] == TOKEN
        assert headers["X-Robot-Fleet"] == "north"
        assert headers.get_all("Authorization") == [TOKEN]  # sent once


async def test_proxy_refusal_without_the_token_is_a_handshake_rejection(
    server: SdkServer,
) -> None:
    with Relay(server.url, require=("authorization", TOKEN)) as proxy:
        bad = options(headers={"Authorization": "Bearer wrong"}, reconnect=None)
        with pytest.raises(rmb.ConnectError) as caught:
            async with rmb.connect(proxy.url, protocol="foxglove-ws", options=bad):
                pass
    assert getattr(caught.value, "status", None) == 401
    assert "token required" in getattr(caught.value, "body", "")


@pytest.mark.parametrize(
    ("headers", "error", "words"),
    [
        ({"X-Token": "a\r\nInjected: yes"}, ValueError, "CR, LF"),
        ({"X-Token": "a\nb"}, ValueError, "CR, LF"),
        ({"X-Token": "nul\0"}, ValueError, "CR, LF"),
        ({"X-Token": "Injected\x01"}, ValueError, "control character"),
        ({"X-Token": "Injected\x1f"}, ValueError, "control character"),
        ({"X-Token": "Injected\x7f"}, ValueError, "control character"),
        ({"X-Token": "caf\u00e9"}, ValueError, "ASCII"),
        ({"X-Token": " padded"}, ValueError, "whitespace"),
        ({"Bad Name": "x"}, ValueError, "invalid header name"),
        ({"X-Na\r\nme": "x"}, ValueError, "invalid header name"),
        ({"X-Name\n": "x"}, ValueError, "invalid header name"),
        ({"": "x"}, ValueError, "invalid header name"),
        ({"Host": "evil.example"}, ValueError, "handshake"),
        ({"upgrade": "h2c"}, ValueError, "handshake"),
        ({"Connection": "close"}, ValueError, "handshake"),
        ({"Sec-WebSocket-Key": "AAAAAAAAAAAAAAAAAAAAAA=="}, ValueError, "handshake"),
        ({"sec-websocket-protocol": "foxglove.sdk.v1"}, ValueError, "handshake"),
        ({"X-Token": 42}, TypeError, "str"),
        ("Authorization: x", TypeError, "not a str"),
        ([("only-a-name",)], TypeError, "pairs"),
    ],
)
def test_bad_headers_are_refused_when_the_options_are_built(
    headers: Any, error: type[Exception], words: str
) -> None:
    with pytest.raises(error, match=words) as caught:
        rmb.ClientOptions(headers=headers)
    assert "Injected" not in str(caught.value)  # a value is never echoed


@pytest.mark.parametrize("bad", ["\x01", "\x08", "\x1b", "\x7f"])
def test_control_characters_in_a_value_are_refused_without_showing_it(bad: str) -> None:
    """Only tab and 0x20-0x7E pass (RFC 9110 field-value, ASCII): any other
    control character would otherwise reach websockets at connect time,
    whose own error prints the value."""
    secret = f"Bearer s3cret{bad}tail"
    with pytest.raises(ValueError, match="X-Token") as caught:
        rmb.ClientOptions(headers={"X-Token": secret})
    assert "s3cret" not in str(caught.value) and "tail" not in str(caught.value)


def test_header_values_may_hold_tabs_spaces_and_every_visible_ascii_character() -> None:
    visible = "".join(chr(c) for c in range(0x21, 0x7F))
    value = f"a\tb c {visible}"
    assert rmb.ClientOptions(headers={"X-All": value}).headers == (("X-All", value),)


def test_headers_accept_pairs_and_keep_their_order() -> None:
    opts = rmb.ClientOptions(headers=[("X-B", "2"), ("X-A", "1"), ("X-A", "3")])
    assert opts.headers == (("X-B", "2"), ("X-A", "1"), ("X-A", "3"))


def test_repr_shows_header_names_but_never_values_nor_the_auth_mac() -> None:
    auth = rmb.RosbridgeAuth("mac-secret", "10.0.0.5", "10.0.0.1", "r4nd", 1, "admin", 2)
    opts = rmb.ClientOptions(headers={"Authorization": TOKEN}, rosbridge_auth=auth)
    text = repr(opts)
    assert "Authorization" in text and "s3cret" not in text
    assert "mac-secret" not in text and "mac-secret" not in repr(auth)
    assert "r4nd" in text  # the rest of the auth is shown
    assert dict(opts.headers)["Authorization"] == TOKEN  # the value itself is kept


async def test_header_values_never_reach_a_log_even_at_debug(
    server: SdkServer, caplog: pytest.LogCaptureFixture
) -> None:
    with Relay(server.url) as proxy:
        caplog.set_level(logging.DEBUG)  # the root logger: every library's debug log
        for name in ("websockets", "websockets.client", "ros_mobile_bridge"):
            caplog.set_level(logging.DEBUG, logger=name)
        async with rmb.connect(proxy.url, options=options(headers={"Authorization": TOKEN})):
            pass
        assert proxy.requests[0]["Authorization"] == TOKEN
    assert caplog.records  # debug logging did happen (the connection was logged)
    assert "s3cret" not in caplog.text


async def test_the_auth_mac_never_reaches_a_log_even_at_debug(
    rosbridge: RosBridge, caplog: pytest.LogCaptureFixture
) -> None:
    """No headers, only ``rosbridge_auth``: websockets' debug log of the
    first frame would print the start of ``auth``, MAC included."""
    caplog.set_level(logging.DEBUG)
    for name in ("websockets", "websockets.client", "ros_mobile_bridge"):
        caplog.set_level(logging.DEBUG, logger=name)
    mac = "feedc0de"  # short: within the part of a frame websockets logs
    auth = rmb.RosbridgeAuth(mac, "127.0.0.1", "127.0.0.1", "r", 1, "admin", 2)
    opts = options(rosbridge_auth=auth, latency_probe_interval=0)
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=opts) as robot:
        assert robot.topics  # discovery went on after auth
    assert caplog.records  # debug logging did happen
    assert mac not in caplog.text


async def test_without_headers_websockets_debug_log_is_left_alone(
    server: SdkServer, caplog: pytest.LogCaptureFixture
) -> None:
    """The control for the test above: the handshake's debug log exists and
    prints request headers, so silencing it with headers set is what keeps
    the token out."""
    caplog.set_level(logging.DEBUG, logger="websockets.client")
    async with rmb.connect(server.url, options=options()):
        pass
    assert "> Sec-WebSocket-Key:" in caplog.text


# -- TLS --------------------------------------------------------------------------


async def test_wss_with_the_callers_context_trusting_a_private_ca(
    tls_server: SdkServer, ca: trustme.CA
) -> None:
    assert tls_server.url.startswith("wss://")
    ctx = ssl.create_default_context()
    ca.configure_trust(ctx)
    chatter = tls_server.channel("/chatter", "std_msgs/msg/String")
    async with rmb.connect(tls_server.url, options=options(ssl_context=ctx)) as robot:
        assert robot.protocol == "foxglove-ws"
        async with robot.subscribe("/chatter") as sub:
            await wait_until(lambda: "/chatter" in tls_server.subscribed())
            chatter.log(string_msg("over TLS"))
            msg = await first_message(sub)
    assert msg.data.to_dict() == {"data": "over TLS"}


async def test_wss_with_a_context_that_does_not_trust_the_certificate_fails(
    tls_server: SdkServer,
) -> None:
    untrusting = ssl.create_default_context()  # the system CAs only
    with pytest.raises(rmb.ConnectError, match=r"(?i)certificate"):
        async with rmb.connect(
            tls_server.url, options=options(ssl_context=untrusting, reconnect=None)
        ):
            pass


async def test_wss_default_context_does_not_trust_a_private_ca(tls_server: SdkServer) -> None:
    with pytest.raises(rmb.ConnectError):
        async with rmb.connect(tls_server.url, options=options(reconnect=None)):
            pass


def test_ssl_context_must_be_a_context() -> None:
    with pytest.raises(TypeError, match="SSLContext"):
        rmb.ClientOptions(ssl_context="/etc/ssl/ca.pem")  # type: ignore[arg-type]


# -- rosbridge auth -----------------------------------------------------------------

AUTH = rmb.RosbridgeAuth(
    mac="0123456789abcdef", client="127.0.0.1", dest="127.0.0.1", rand="r4nd0m",
    t=1_700_000_000, level="admin", end=1_700_003_600,
)  # fmt: skip


def test_auth_builder_writes_the_protocol_fields_in_order() -> None:
    from ros_mobile_bridge.wire.rosbridge import RosbridgeEngine

    text = RosbridgeEngine.auth(
        mac="m", client="c", dest="d", rand="r", t=1.5, level="user", end=10.0
    )
    assert json.loads(text) == {
        "op": "auth", "mac": "m", "client": "c", "dest": "d", "rand": "r",
        "t": 1.5, "level": "user", "end": 10,
    }  # fmt: skip
    assert list(json.loads(text)) == ["op", "mac", "client", "dest", "rand", "t", "level", "end"]
    with pytest.raises(ValueError, match="finite"):
        RosbridgeEngine.auth(
            mac="m", client="c", dest="d", rand="r", t=float("nan"), level="u", end=1
        )
    with pytest.raises(TypeError):
        RosbridgeEngine.auth(mac=1, client="c", dest="d", rand="r", t=1, level="u", end=1)  # type: ignore[arg-type]


def test_bad_auth_options_are_refused_at_once() -> None:
    with pytest.raises(TypeError, match="RosbridgeAuth"):
        rmb.ClientOptions(rosbridge_auth="mac")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="finite"):
        rmb.RosbridgeAuth("m", "c", "d", "r", -1, "admin", 2)
    with pytest.raises(TypeError, match=r"RosbridgeAuth\.mac must be a str"):
        rmb.RosbridgeAuth(None, "c", "d", "r", 1, "admin", 2)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"RosbridgeAuth\.end must be a number"):
        rmb.RosbridgeAuth("m", "c", "d", "r", 1, "admin", True)


def test_auth_and_the_engine_check_the_same_rules() -> None:
    """One validator behind both: the same input fails the same way."""
    from ros_mobile_bridge.wire.rosbridge import RosbridgeEngine

    good: dict[str, Any] = {
        "mac": "m", "client": "c", "dest": "d", "rand": "r", "t": 1, "level": "u", "end": 2,
    }  # fmt: skip
    for field, bad in [("rand", 5), ("level", None), ("t", "1"), ("end", float("inf"))]:
        fields = {**good, field: bad}
        with pytest.raises((TypeError, ValueError)) as by_engine:
            RosbridgeEngine.auth(**fields)
        with pytest.raises((TypeError, ValueError)) as by_options:
            rmb.RosbridgeAuth(**fields)
        assert type(by_engine.value) is type(by_options.value)
        assert str(by_options.value) == f"RosbridgeAuth.{by_engine.value}"


def make_auth(secret: str) -> rmb.RosbridgeAuth:
    return rmb.RosbridgeAuth(f"mac-of-{secret}", "c", "d", "r", 1, "admin", 2)


def test_repr_hides_an_auth_callable_which_may_hold_the_secret() -> None:
    opts = rmb.ClientOptions(rosbridge_auth=functools.partial(make_auth, secret="hunter2"))
    assert "hunter2" not in repr(opts)
    assert "rosbridge_auth=<callable>" in repr(opts)
    assert "rosbridge_auth=None" in repr(rmb.ClientOptions())


def test_a_failing_auth_callable_is_a_connect_error_that_does_not_quote_it() -> None:
    def leaky() -> rmb.RosbridgeAuth:
        raise RuntimeError("secret=hunter2 rejected")

    with pytest.raises(rmb.ConnectError, match="RuntimeError") as caught:
        rmb.ClientOptions(rosbridge_auth=leaky).auth_message()
    assert "hunter2" not in str(caught.value) and "hunter2" not in repr(caught.value)
    assert isinstance(caught.value.__cause__, RuntimeError)  # the cause is chained
    with pytest.raises(rmb.ConnectError, match="returned str, not RosbridgeAuth"):
        rmb.ClientOptions(rosbridge_auth=lambda: "mac").auth_message()  # type: ignore[arg-type, return-value]


async def test_auth_is_the_first_message_and_rosbridge_server_rs_carries_on(
    rosbridge: RosBridge,
) -> None:
    """rosbridge_server_rs has no authentication (its --help names none):
    it must not break on ``auth``, and the proxy shows what went on the
    wire, first."""
    with Relay(rosbridge.url) as proxy:
        opts = options(rosbridge_auth=AUTH, latency_probe_interval=0)
        async with rmb.connect(proxy.url, protocol="rosbridge", options=opts) as robot:
            assert "/chatter" in [t.name for t in robot.topics]  # discovery went on
            async with robot.subscribe("/chatter") as sub:
                msg = await first_message(sub)
        assert isinstance(msg.data.data, str)
        first = json.loads(proxy.sent[0])
        later = [json.loads(m)["op"] for m in proxy.sent[1:]]
    assert first == {
        "op": "auth", "mac": "0123456789abcdef", "client": "127.0.0.1", "dest": "127.0.0.1",
        "rand": "r4nd0m", "t": 1_700_000_000, "level": "admin", "end": 1_700_003_600,
    }  # fmt: skip
    assert "auth" not in later and "call_service" in later and "subscribe" in later


async def test_auth_callable_is_called_for_every_connection(server: SdkServer) -> None:
    """A recording server (no upstream): each connection attempt calls the
    callable once and sends its result first."""
    made: list[int] = []

    def fresh() -> rmb.RosbridgeAuth:
        made.append(1)
        return rmb.RosbridgeAuth(f"mac{len(made)}", "c", "d", f"r{len(made)}", 1, "admin", 2)

    with Relay(None) as recorder:
        opts = options(rosbridge_auth=fresh, connect_timeout=0.5, reconnect=None)
        for _ in range(2):
            with pytest.raises(rmb.ConnectError):  # nothing answers discovery
                async with rmb.connect(recorder.url, protocol="rosbridge", options=opts):
                    pass
        await wait_until(lambda: len(recorder.sent) >= 2)
        firsts = [json.loads(m) for m in recorder.sent if json.loads(m)["op"] == "auth"]
    assert len(made) == 2
    assert [a["mac"] for a in firsts] == ["mac1", "mac2"]


async def test_auth_callable_that_fails_fails_the_connection() -> None:
    def broken() -> rmb.RosbridgeAuth:
        raise RuntimeError("no key")

    with Relay(None) as recorder:
        opts = options(rosbridge_auth=broken, reconnect=None)
        with pytest.raises(rmb.ConnectError, match="rosbridge_auth callable failed") as caught:
            async with rmb.connect(recorder.url, protocol="rosbridge", options=opts):
                pass
        assert recorder.sent == []  # nothing was sent
    assert "no key" not in str(caught.value)
    assert isinstance(caught.value.__cause__, RuntimeError)


@pytest.mark.parametrize("transport", ["default", "httpx"])
async def test_auth_callable_failing_on_a_reconnection_is_retried(
    rosbridge: RosBridge, transport: str
) -> None:
    """The relay drops the link; the callable fails for the first
    reconnection attempt only: that attempt fails, the policy retries, the
    next attempt sends a fresh auth and the session carries on."""
    import httpx

    made: list[int] = []

    def flaky() -> rmb.RosbridgeAuth:
        made.append(1)
        if len(made) == 2:
            raise OSError("key store unreachable")
        return rmb.RosbridgeAuth(f"mac{len(made)}", "c", "d", "r", 1, "admin", 2)

    with Relay(rosbridge.url) as proxy:
        async with httpx.AsyncClient() as http:
            opts = options(
                rosbridge_auth=flaky,
                latency_probe_interval=0,
                http_client=http if transport == "httpx" else None,
                reconnect=rmb.ReconnectPolicy(initial_delay=0.05, max_delay=0.2),
            )
            async with rmb.connect(proxy.url, protocol="rosbridge", options=opts) as robot:
                assert proxy.drop() == 1
                await wait_until(
                    lambda: len(made) >= 3 and robot.status == "connected", 10, "reconnection"
                )
                async with robot.subscribe("/chatter") as sub:
                    msg = await first_message(sub)  # the session works again
                assert isinstance(msg.data.data, str)
                # the attempt whose callable failed failed with ConnectError
                assert isinstance(robot.last_error, rmb.ConnectError)
                assert isinstance(robot.last_error.__cause__, OSError)
        macs = [json.loads(m)["mac"] for m in proxy.sent if json.loads(m)["op"] == "auth"]
    assert len(made) == 3
    assert macs == ["mac1", "mac3"]  # the failed attempt sent nothing


async def test_no_answer_after_auth_says_a_refused_auth_looks_like_this() -> None:
    """A server that swallows every frame (as one checking the MAC may
    ignore a client whose MAC is wrong): the error says that a refused
    ``auth`` looks like this; without ``auth`` it does not.

    The timeout covers the handshake too: 2 s, not less, so a loaded
    machine's slow handshake is not mistaken for the silence (CI once
    timed out the handshake itself at 0.5 s)."""
    with Relay(None) as silent:
        for auth, hinted in [(AUTH, True), (None, False)]:
            opts = options(rosbridge_auth=auth, connect_timeout=2.0, reconnect=None)
            with pytest.raises(rmb.ProtocolMismatchError) as caught:
                async with rmb.connect(silent.url, protocol="rosbridge", options=opts):
                    pass
            text = str(caught.value)
            assert "no answer to /rosapi/topics" in text
            assert ("refuses it (a wrong or expired MAC)" in text) is hinted
            assert caught.value.detected is None
            assert AUTH.mac not in text


# -- reconnection ---------------------------------------------------------------------


@pytest.mark.parametrize("transport", ["default", "httpx"])
async def test_headers_and_transport_hold_across_a_reconnection(transport: str) -> None:
    """The upstream restarts on its port; the proxy drops the client, which
    reconnects through the proxy with its token again."""
    import httpx

    first = SdkServer()
    port = first.port
    with Relay(first.url, require=("authorization", TOKEN)) as proxy:
        async with httpx.AsyncClient() as http:
            opts = options(
                headers={"Authorization": TOKEN},
                http_client=http if transport == "httpx" else None,
                reconnect=rmb.ReconnectPolicy(initial_delay=0.05, max_delay=0.2),
            )
            async with rmb.connect(proxy.url, options=opts) as robot:
                first.stop()
                await wait_until(lambda: robot.status != "connected", what="the drop")
                with SdkServer(port=port) as second:
                    second.channel("/back", "std_msgs/msg/String")
                    await wait_until(
                        lambda: "/back" in [t.name for t in robot.topics], 10, "reconnection"
                    )
                    assert robot.status == "connected"
        tokens = [h["Authorization"] for h in proxy.requests]
    assert len(tokens) >= 2 and set(tokens) == {TOKEN}
