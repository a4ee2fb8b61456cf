"""The WebSocket transport: TLS against the real Foxglove SDK server, and the
ping/pong keep-alive against a peer that stops answering."""

from __future__ import annotations

import shutil
import ssl
import subprocess
from pathlib import Path

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from peers.foxglove_sdk import SdkServer, string_msg
from peers.scripted import SERVER_INFO, Peer, scripted_server


@pytest.fixture(scope="module")
def certificate(tmp_path_factory: pytest.TempPathFactory) -> tuple[bytes, bytes, Path]:
    """A self-signed certificate for 127.0.0.1 (openssl is part of the base system)."""
    openssl = shutil.which("openssl")
    if openssl is None:  # pragma: no cover - Debian and CI images have it
        pytest.fail("openssl is needed to make a test certificate")
    d = tmp_path_factory.mktemp("tls")
    key, cert = d / "key.pem", d / "cert.pem"
    subprocess.run(
        [
            openssl,
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-subj",
            "/CN=127.0.0.1",
            "-addext",
            "subjectAltName=IP:127.0.0.1",
            "-keyout",
            str(key),
            "-out",
            str(cert),
        ],
        check=True,
        capture_output=True,
    )
    # the SDK wants a PKCS#8 key
    pk8 = d / "key8.pem"
    subprocess.run(
        [openssl, "pkcs8", "-topk8", "-nocrypt", "-in", str(key), "-out", str(pk8)],
        check=True,
        capture_output=True,
    )
    return cert.read_bytes(), pk8.read_bytes(), cert


async def test_wss_against_the_sdk_servers_own_tls(certificate: tuple[bytes, bytes, Path]) -> None:
    import foxglove

    cert_pem, key_pem, cert_path = certificate
    ctx = foxglove.Context()
    server = foxglove.start_server(
        host="127.0.0.1", port=0, context=ctx, tls_cert=cert_pem, tls_key=key_pem
    )
    try:
        channel = foxglove.Channel(
            "/secure",
            message_encoding="cdr",
            schema=foxglove.Schema(
                name="std_msgs/msg/String", encoding="ros2msg", data=b"string data"
            ),
            context=ctx,
        )
        trust = ssl.create_default_context(cafile=str(cert_path))
        options = rmb.ClientOptions(ssl_context=trust, connect_timeout=5)
        async with rmb.connect(f"wss://127.0.0.1:{server.port}", options=options) as robot:
            assert [t.name for t in robot.topics] == ["/secure"]
            async with robot.subscribe("/secure") as sub:
                await sub.wait_active()
                # the server registers the subscription on its own thread: log
                # until the first message comes through
                with anyio.fail_after(5):
                    while sub.stats.received == 0:
                        channel.log(string_msg("over tls"))
                        await anyio.sleep(0.02)
                    msg = await sub.__anext__()
        assert msg.data.to_dict() == {"data": "over tls"}
        # without trusting the certificate the handshake fails with a ConnectError
        with pytest.raises(rmb.ConnectError, match="certificate"):
            async with rmb.connect(
                f"wss://127.0.0.1:{server.port}", options=rmb.ClientOptions(connect_timeout=5)
            ):
                pass
    finally:
        server.stop()


async def test_keepalive_fails_a_connection_whose_peer_stopped_answering() -> None:
    async def silent(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await anyio.sleep(30)  # never reads, so never answers a ping

    options = rmb.ClientOptions(
        keepalive_interval=0.1, keepalive_timeout=0.2, discovery_grace=0, reconnect=None
    )
    async with scripted_server(silent) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options) as robot:
                await wait_until(lambda: robot.status == "error", what="keep-alive failure")
                assert "keep-alive" in str(robot.last_error)
                with pytest.raises(rmb.NotConnected):
                    await robot.call_service("/x", {})


async def test_keepalive_keeps_an_answering_connection_up() -> None:
    with SdkServer() as server:
        options = rmb.ClientOptions(keepalive_interval=0.05, keepalive_timeout=2)
        async with rmb.connect(server.url, options=options) as robot:
            await anyio.sleep(0.5)  # about ten ping/pong round trips
            assert robot.status == "connected"
