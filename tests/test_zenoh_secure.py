"""Secure Zenoh links against real eclipse-zenoh routers on loopback
(tests/peers/zenoh_router.py), with certificates made here (``trustme``):
a ``tls/`` router (its CA given), a mutual-TLS router (a client certificate
required), a router requiring user/password; a Zenoh configuration as a
file and as JSON5 text. The right credentials connect and exchange a
message; a wrong CA, a missing or foreign client certificate, a wrong
password each fail ``connect()`` with ``ConnectError`` naming the cause
within ``connect_timeout``; no secret (the password, the private key's
content) reaches a log line at DEBUG, an error text, a chained error, a
``repr``, or the output of a process whose zenoh could log at DEBUG."""

from __future__ import annotations

import dataclasses
import logging
import os
import subprocess
import sys
import textwrap
import traceback
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _cli_run import cli_env
from _cli_run import rmb as run_rmb
from _util import take, wait_until
from peers.zenoh_router import ZenohRouter, tls_settings, usrpwd_settings

zenoh = pytest.importorskip("zenoh")
trustme = pytest.importorskip("trustme")

STRING = "std_msgs/msg/String"
PASSWORD = "Tr0ub4dor-s3cret"
USER = "fleet"
TIMEOUT = 5.0
"""connect_timeout of these tests: a refused password fails at its end."""


@dataclasses.dataclass(frozen=True)
class Pki:
    """Certificate files made for this module."""

    ca: str
    server_cert: str
    server_key: str
    client_cert: str
    client_key: str
    other_ca: str
    foreign_cert: str  # a client certificate signed by other_ca
    foreign_key: str
    users: str  # the routers' user/password dictionary
    named_cert: str  # a router certificate for "localhost" only (not 127.0.0.1)
    named_key: str

    def key_secrets(self) -> list[str]:
        """Lines of the private keys' PEM bodies: none may show anywhere."""
        lines: list[str] = []
        for path in (self.client_key, self.server_key, self.foreign_key):
            lines += [line for line in Path(path).read_text().splitlines() if "-----" not in line]
        return lines


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    d = tmp_path_factory.mktemp("pki")
    ca, other = trustme.CA(), trustme.CA()
    server = ca.issue_cert("127.0.0.1", "localhost")
    client = ca.issue_cert("fleet-manager.example")
    foreign = other.issue_cert("fleet-manager.example")
    named = ca.issue_cert("localhost")
    ca.cert_pem.write_to_path(str(d / "ca.pem"))
    other.cert_pem.write_to_path(str(d / "other-ca.pem"))
    for name, cert in (
        ("server", server), ("client", client), ("foreign", foreign), ("named", named)
    ):  # fmt: skip
        cert.cert_chain_pems[0].write_to_path(str(d / f"{name}.pem"))
        cert.private_key_pem.write_to_path(str(d / f"{name}.key"))
    (d / "users.txt").write_text(f"{USER}:{PASSWORD}\n")
    return Pki(
        ca=str(d / "ca.pem"),
        server_cert=str(d / "server.pem"),
        server_key=str(d / "server.key"),
        client_cert=str(d / "client.pem"),
        client_key=str(d / "client.key"),
        other_ca=str(d / "other-ca.pem"),
        foreign_cert=str(d / "foreign.pem"),
        foreign_key=str(d / "foreign.key"),
        users=str(d / "users.txt"),
        named_cert=str(d / "named.pem"),
        named_key=str(d / "named.key"),
    )


@pytest.fixture(scope="module")
def tls_router(pki: Pki) -> Iterator[ZenohRouter]:
    with ZenohRouter(scheme="tls", settings=tls_settings(pki.server_cert, pki.server_key)) as r:
        yield r


@pytest.fixture(scope="module")
def mtls_router(pki: Pki) -> Iterator[ZenohRouter]:
    settings = tls_settings(pki.server_cert, pki.server_key, client_ca_file=pki.ca)
    with ZenohRouter(scheme="tls", settings=settings) as r:
        yield r


@pytest.fixture(scope="module")
def auth_router(pki: Pki) -> Iterator[ZenohRouter]:
    settings = {**tls_settings(pki.server_cert, pki.server_key), **usrpwd_settings(pki.users)}
    with ZenohRouter(scheme="tls", settings=settings) as r:
        yield r


def opts(domain: int, **kw: Any) -> rmb.ClientOptions:
    return rmb.ClientOptions(domain_id=domain, connect_timeout=TIMEOUT, reconnect=None, **kw)


async def exchange(locator: str, options: rmb.ClientOptions) -> None:
    """Two clients with ``options`` through the router: one's message
    reaches the other's subscription."""
    async with (
        rmb.connect(locator, options=options) as a,
        rmb.connect(locator, options=options) as b,
        b.subscribe("/secure", schema=STRING) as sub,
    ):
        assert a.protocol == "zenoh"
        await wait_until(
            lambda: any(t.name == "/secure" for t in a.topics), 10.0, what="b's subscription"
        )
        await a.publish("/secure", STRING, {"data": "over tls"})
        [got] = await take(sub, 1)
        assert got.data.data == "over tls"


async def refused(locator: str, options: rmb.ClientOptions) -> rmb.ConnectError:
    """The ``ConnectError`` of a ``connect()`` that must fail within
    ``connect_timeout`` (plus the teardown's slack)."""
    with anyio.fail_after(options.connect_timeout + 5.0):
        with pytest.raises(rmb.ConnectError) as info:
            async with rmb.connect(locator, options=options):
                pass
    return info.value


# -- the options ---------------------------------------------------------------------------
def test_security_fields_are_checked_at_once(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="cert_file and key_file"):
        rmb.ZenohSecurity(cert_file="c.pem")
    with pytest.raises(ValueError, match="user and password"):
        rmb.ZenohSecurity(user="u")
    with pytest.raises(ValueError, match="user and password") as info:
        rmb.ZenohSecurity(password=PASSWORD)
    assert PASSWORD not in str(info.value)
    with pytest.raises(ValueError, match="password must be non-empty"):
        rmb.ZenohSecurity(user="u", password="")
    with pytest.raises(TypeError, match="ca_file"):
        rmb.ZenohSecurity(ca_file=b"ca.pem")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="verify_name"):
        rmb.ZenohSecurity(verify_name=1)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="zenoh_security"):
        rmb.ClientOptions(zenoh_security={"user": "u"})  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="zenoh_config"):
        rmb.ClientOptions(zenoh_config=b"{}")  # type: ignore[arg-type]
    assert rmb.ZenohSecurity(ca_file=tmp_path / "ca.pem").ca_file == str(tmp_path / "ca.pem")


def test_repr_shows_no_password_nor_json5_text() -> None:
    security = rmb.ZenohSecurity(user=USER, password=PASSWORD, ca_file="/etc/ca.pem")
    json5 = f'{{transport: {{auth: {{usrpwd: {{user: "{USER}", password: "{PASSWORD}"}}}}}}}}'
    options = rmb.ClientOptions(zenoh_security=security, zenoh_config=json5)
    for text in (repr(security), repr(options), str(options)):
        assert PASSWORD not in text
        assert "<redacted>" in text or "JSON5 text" in text
    assert "user='fleet'" in repr(security)
    assert "/etc/ca.pem" in repr(options)
    assert f"<JSON5 text, {len(json5)} characters>" in repr(options)
    assert rmb.ClientOptions(zenoh_config="/etc/zenoh.json5").zenoh_config == "/etc/zenoh.json5"


# -- the right credentials -------------------------------------------------------------------
async def test_tls_with_the_routers_ca_connects(
    tls_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    assert tls_router.locator.startswith("tls/")
    await exchange(
        tls_router.locator, opts(zenoh_domain, zenoh_security=rmb.ZenohSecurity(ca_file=pki.ca))
    )


async def test_mutual_tls_with_a_client_certificate_connects(
    mtls_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    security = rmb.ZenohSecurity(ca_file=pki.ca, cert_file=pki.client_cert, key_file=pki.client_key)
    await exchange(mtls_router.locator, opts(zenoh_domain, zenoh_security=security))


async def test_user_and_password_connect(
    auth_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    security = rmb.ZenohSecurity(ca_file=pki.ca, user=USER, password=PASSWORD)
    await exchange(auth_router.locator, opts(zenoh_domain, zenoh_security=security))


async def test_a_configuration_file_or_json5_text_carries_the_credentials(
    auth_router: ZenohRouter, pki: Pki, zenoh_domain: int, tmp_path: Path
) -> None:
    """Everything in the configuration, nothing in ZenohSecurity: the
    session starts from it; the target still names the router."""
    json5 = textwrap.dedent(
        f"""\
        {{
          // as rmw_zenoh reads ZENOH_SESSION_CONFIG_URI
          mode: "peer",
          connect: {{ endpoints: ["tcp/127.0.0.1:1"] }},
          transport: {{
            link: {{ tls: {{ root_ca_certificate: "{pki.ca}" }} }},
            auth: {{ usrpwd: {{ user: "{USER}", password: "{PASSWORD}" }} }},
          }},
        }}
        """
    )
    path = tmp_path / "session.json5"
    path.write_text(json5)
    await exchange(auth_router.locator, opts(zenoh_domain, zenoh_config=path))
    # the same as text; ZenohSecurity's fields win over the configuration's
    wrong = json5.replace(PASSWORD, "not-the-password")
    security = rmb.ZenohSecurity(user=USER, password=PASSWORD)
    await exchange(
        auth_router.locator, opts(zenoh_domain, zenoh_config=wrong, zenoh_security=security)
    )


async def test_a_secure_link_reconnects_with_its_credentials(pki: Pki, zenoh_domain: int) -> None:
    """Mutual TLS and a password together; the router restarts: the client
    reconnects (the probe and the session again, with the same security)
    and its subscription delivers again."""
    settings = {
        **tls_settings(pki.server_cert, pki.server_key, client_ca_file=pki.ca),
        **usrpwd_settings(pki.users),
    }
    security = rmb.ZenohSecurity(
        ca_file=pki.ca,
        cert_file=pki.client_cert,
        key_file=pki.client_key,
        user=USER,
        password=PASSWORD,
    )
    resilient = dataclasses.replace(
        opts(zenoh_domain, zenoh_security=security),
        keepalive_interval=0.2,
        keepalive_timeout=0.6,
        reconnect=rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.3),
    )
    router = ZenohRouter(scheme="tls", settings=settings).start()
    try:
        async with (
            rmb.connect(router.locator, options=resilient) as client,
            client.subscribe("/secure", schema=STRING) as sub,
        ):
            router.stop()
            await wait_until(lambda: client.status == "reconnecting", 10.0, what="reconnecting")
            router.start()  # the same port, the same settings
            await wait_until(lambda: client.status == "connected", 20.0, what="reconnected")
            async with rmb.connect(
                router.locator, options=opts(zenoh_domain, zenoh_security=security)
            ) as talker:
                await wait_until(
                    lambda: any(t.name == "/secure" for t in talker.topics),
                    10.0,
                    what="resubscribed",
                )
                await talker.publish("/secure", STRING, {"data": "after"})
                [got] = await take(sub, 1)
                assert got.data.data == "after"
    finally:
        router.stop()


# -- each failure names its cause -------------------------------------------------------------
async def test_a_wrong_ca_fails_naming_the_certificate(
    tls_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    options = opts(zenoh_domain, zenoh_security=rmb.ZenohSecurity(ca_file=pki.other_ca))
    error = await refused(tls_router.locator, options)
    text = str(error)
    assert "TLS" in text
    assert "certificate is not trusted" in text
    assert pki.other_ca in text  # the CA it was checked against


async def test_a_missing_client_certificate_fails_naming_mutual_tls(
    mtls_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    options = opts(zenoh_domain, zenoh_security=rmb.ZenohSecurity(ca_file=pki.ca))
    text = str(await refused(mtls_router.locator, options))
    assert "requires a client certificate" in text
    assert "mutual TLS" in text
    assert "cert_file" in text


async def test_a_foreign_client_certificate_fails_naming_it(
    mtls_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    security = rmb.ZenohSecurity(
        ca_file=pki.ca, cert_file=pki.foreign_cert, key_file=pki.foreign_key
    )
    text = str(await refused(mtls_router.locator, opts(zenoh_domain, zenoh_security=security)))
    assert "does not trust the client certificate's CA" in text
    assert pki.foreign_cert in text


async def test_a_wrong_password_fails_naming_authentication(
    auth_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    security = rmb.ZenohSecurity(ca_file=pki.ca, user=USER, password="not-" + PASSWORD)
    text = str(await refused(auth_router.locator, opts(zenoh_domain, zenoh_security=security)))
    assert "authentication failed" in text
    assert "wrong user or password" in text
    assert PASSWORD not in text


async def test_no_password_for_a_router_that_requires_one_says_so(
    auth_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    options = opts(zenoh_domain, zenoh_security=rmb.ZenohSecurity(ca_file=pki.ca))
    text = str(await refused(auth_router.locator, options))
    assert "refused the session" in text
    assert "ZenohSecurity(user=..., password=...)" in text


async def test_tls_to_a_plain_tcp_router_names_the_handshake(
    zenoh_router: ZenohRouter, pki: Pki, zenoh_domain: int
) -> None:
    locator = zenoh_router.locator.replace("tcp/", "tls/")
    options = opts(zenoh_domain, zenoh_security=rmb.ZenohSecurity(ca_file=pki.ca))
    text = str(await refused(locator, options))
    assert "TLS handshake" in text


async def test_an_invalid_configuration_names_its_position_not_its_text(
    tls_router: ZenohRouter, zenoh_domain: int, tmp_path: Path
) -> None:
    json5 = f'{{transport: {{auth: {{usrpwd: {{password: "{PASSWORD}" oops }}}}}}}}'
    error = await refused(tls_router.locator, opts(zenoh_domain, zenoh_config=json5))
    assert "invalid configuration <JSON5 text" in str(error)
    assert "line:column 1:" in str(error)
    missing = tmp_path / "nowhere.json5"
    error = await refused(tls_router.locator, opts(zenoh_domain, zenoh_config=missing))
    assert f"{str(missing)!r} does not exist" in str(error)


async def test_a_certificate_for_another_name_fails_unless_the_check_is_off(
    pki: Pki, zenoh_domain: int
) -> None:
    with ZenohRouter(scheme="tls", settings=tls_settings(pki.named_cert, pki.named_key)) as r:
        strict = opts(zenoh_domain, zenoh_security=rmb.ZenohSecurity(ca_file=pki.ca))
        text = str(await refused(r.locator, strict))  # 127.0.0.1: not the certificate's name
        assert "certificate is not trusted" in text
        assert "mismatch" in text
        loose = rmb.ZenohSecurity(ca_file=pki.ca, verify_name=False)
        await exchange(r.locator, opts(zenoh_domain, zenoh_security=loose))


async def test_user_and_password_over_plain_tcp(pki: Pki, zenoh_domain: int) -> None:
    with ZenohRouter(settings=usrpwd_settings(pki.users)) as r:
        right = rmb.ZenohSecurity(user=USER, password=PASSWORD)
        await exchange(r.locator, opts(zenoh_domain, zenoh_security=right))
        wrong = rmb.ZenohSecurity(user="intruder", password=PASSWORD)
        text = str(await refused(r.locator, opts(zenoh_domain, zenoh_security=wrong)))
        assert "authentication failed" in text
        assert "the router answers" in text  # a router is there: not an unreachable one


def test_rmb_reads_zenoh_session_config_uri(
    tls_router: ZenohRouter, pki: Pki, tmp_path: Path
) -> None:
    """The command line starts from ``$ZENOH_SESSION_CONFIG_URI``, as
    rmw_zenoh does: with the CA there, ``rmb`` reaches a ``tls/`` router."""
    config = tmp_path / "session.json5"
    config.write_text(f'{{transport: {{link: {{tls: {{root_ca_certificate: "{pki.ca}"}}}}}}}}')
    done = run_rmb("nodes", tls_router.locator, env=cli_env(ZENOH_SESSION_CONFIG_URI=str(config)))
    assert done.returncode == 0, done.stderr
    refused_ = run_rmb("nodes", tls_router.locator, env=cli_env(drop=["ZENOH_SESSION_CONFIG_URI"]))
    assert refused_.returncode == 1
    assert "ConnectError" in refused_.stderr
    assert "certificate is not trusted" in refused_.stderr


# -- no secret anywhere -------------------------------------------------------------------------
def _everything_about(error: BaseException) -> str:
    """An error's text, repr and whole printed chain (causes and contexts)."""
    return "\n".join(
        [
            str(error),
            repr(error),
            *traceback.format_exception(type(error), error, error.__traceback__),
        ]
    )


async def test_no_secret_in_any_log_error_or_repr(
    auth_router: ZenohRouter,
    mtls_router: ZenohRouter,
    pki: Pki,
    zenoh_domain: int,
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG)  # the root logger
    for name in [*logging.root.manager.loggerDict, "zenoh", "ros_mobile_bridge"]:
        caplog.set_level(logging.DEBUG, logger=name)  # every logger, zenoh's if any
    texts: list[str] = []
    good = rmb.ZenohSecurity(ca_file=pki.ca, user=USER, password=PASSWORD)
    await exchange(auth_router.locator, opts(zenoh_domain, zenoh_security=good))
    mtls = rmb.ZenohSecurity(ca_file=pki.ca, cert_file=pki.client_cert, key_file=pki.client_key)
    await exchange(mtls_router.locator, opts(zenoh_domain, zenoh_security=mtls))
    json5 = f'{{transport: {{auth: {{usrpwd: {{user: "{USER}", password: "{PASSWORD}" x}}}}}}}}'
    failing = [
        (auth_router.locator, opts(zenoh_domain, zenoh_security=dataclasses.replace(good, password=PASSWORD + "!"))),
        (auth_router.locator, opts(zenoh_domain, zenoh_config=json5)),
        (mtls_router.locator, opts(zenoh_domain, zenoh_security=rmb.ZenohSecurity(
            ca_file=pki.other_ca, cert_file=pki.client_cert, key_file=pki.client_key))),
        (mtls_router.locator, opts(zenoh_domain, zenoh_security=rmb.ZenohSecurity(
            ca_file=pki.ca, cert_file=pki.client_cert, key_file=pki.foreign_key))),  # mismatched
    ]  # fmt: skip
    for locator, options in failing:
        texts += [_everything_about(await refused(locator, options)), repr(options), str(options)]
        texts.append(repr(options.zenoh_security))
    texts += [repr(good), repr(mtls), caplog.text]
    texts += [record.getMessage() for record in caplog.records]
    assert caplog.records  # debug logging did happen
    whole = "\n".join(texts)
    assert "authentication failed" in whole  # the failures did fail, each for its cause
    assert PASSWORD not in whole
    for line in pki.key_secrets():
        assert line not in whole


def test_zenoh_logging_at_debug_in_the_environment_shows_no_secret(
    auth_router: ZenohRouter, pki: Pki
) -> None:
    """The library never starts zenoh's own (Rust) log: with ``RUST_LOG``
    at debug, a process that connects with a password prints nothing of
    it (zenoh's log, once a program starts it, prints the whole session
    configuration: docs/zenoh.md says so)."""
    program = textwrap.dedent(
        f"""\
        import anyio, logging, ros_mobile_bridge as rmb
        logging.basicConfig(level=logging.DEBUG)
        async def main():
            security = rmb.ZenohSecurity(ca_file={pki.ca!r}, user={USER!r}, password={PASSWORD!r})
            options = rmb.ClientOptions(zenoh_security=security, connect_timeout={TIMEOUT})
            async with rmb.connect({auth_router.locator!r}, options=options) as c:
                print("CONNECTED", c.protocol, repr(options))
        anyio.run(main)
        """
    )
    env = {**os.environ, "RUST_LOG": "debug", "PYTHONPATH": os.pathsep.join(sys.path)}
    done = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, env=env, timeout=60
    )
    output = done.stdout + done.stderr
    assert "CONNECTED zenoh" in done.stdout, output
    assert PASSWORD not in output
