"""``parse_target``: every accepted spelling of a target, and every malformed
one rejected with ``ValueError`` / ``TypeError`` before any I/O."""

from __future__ import annotations

import ipaddress

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge import DEFAULT_PORTS, Endpoint, parse_target


# -- accepted forms ----------------------------------------------------------------
@pytest.mark.parametrize(
    ("protocol", "port"),
    [("auto", 8765), ("foxglove-ws", 8765), ("rosbridge", 9090), ("zenoh", 7447)],
)
def test_default_port_is_the_protocols(protocol: str, port: int) -> None:
    ep = parse_target("robot.local", protocol=protocol)
    zenoh = protocol == "zenoh"
    assert ep == Endpoint(host="robot.local", port=port, secure=False, path="/", zenoh=zenoh)
    assert port == DEFAULT_PORTS.get(protocol, DEFAULT_PORTS["foxglove-ws"])


def test_default_ports_table() -> None:
    assert dict(DEFAULT_PORTS) == {"foxglove-ws": 8765, "rosbridge": 9090, "zenoh": 7447}


@pytest.mark.parametrize(
    ("target", "host", "port"),
    [
        ("robot", "robot", 8765),
        ("robot.local", "robot.local", 8765),
        ("my-robot_1.lan", "my-robot_1.lan", 8765),
        ("robot.local:9000", "robot.local", 9000),
        ("robot:1", "robot", 1),
        ("robot:65535", "robot", 65535),
        ("192.168.0.10", "192.168.0.10", 8765),
        ("192.168.0.10:8766", "192.168.0.10", 8766),
        ("[::1]", "::1", 8765),
        ("[::1]:9000", "::1", 9000),
        ("[2001:db8::7]:1", "2001:db8::7", 1),
        ("  robot:9  ", "robot", 9),  # surrounding whitespace is stripped
    ],
)
def test_host_and_port_forms(target: str, host: str, port: int) -> None:
    ep = parse_target(target)
    assert (ep.host, ep.port, ep.secure, ep.path, ep.zenoh) == (host, port, False, "/", False)


@pytest.mark.parametrize(
    ("target", "expected"),
    [
        ("[0:0:0:0:0:0:0:1]", "::1"),
        ("[FE80::1]", "fe80::1"),
        ("[2001:DB8:0:0:0:0:0:1]:5", "2001:db8::1"),
        ("[2001:0db8::0001]", "2001:db8::1"),
        ("127.0.0.1", "127.0.0.1"),
        ("ws://[0::1]:9", "::1"),
        ("tcp/[0:0::1]:7447", "::1"),
    ],
)
def test_ip_addresses_are_normalised(target: str, expected: str) -> None:
    assert parse_target(target).host == expected


@pytest.mark.parametrize(
    ("target", "secure", "port", "path"),
    [
        ("ws://robot", False, 8765, "/"),
        ("wss://robot", True, 8765, "/"),
        ("http://robot", False, 8765, "/"),
        ("https://robot", True, 8765, "/"),
        ("ws://robot:9090", False, 9090, "/"),
        ("wss://robot:443/foxglove", True, 443, "/foxglove"),
        ("ws://robot/a/b/", False, 8765, "/a/b/"),
        ("https://robot:8443/bridge/ws", True, 8443, "/bridge/ws"),
        ("WSS://robot", True, 8765, "/"),  # the scheme is case-insensitive
        ("ws://[::1]:9/p", False, 9, "/p"),
    ],
)
def test_url_forms(target: str, secure: bool, port: int, path: str) -> None:
    ep = parse_target(target)
    assert (ep.secure, ep.port, ep.path, ep.zenoh) == (secure, port, path, False)


def test_secure_scheme_is_overridable() -> None:
    assert parse_target("wss://robot", secure=False).secure is False
    assert parse_target("https://robot", secure=False).secure is False
    assert parse_target("ws://robot", secure=True).secure is True
    assert parse_target("robot", secure=True).secure is True
    assert parse_target("robot").secure is False


def test_explicit_port_wins() -> None:
    assert parse_target("robot:1", port=2).port == 2
    assert parse_target("robot", port=2).port == 2
    assert parse_target("ws://robot:1/x", port=2).port == 2
    assert parse_target("[::1]:1", port=2).port == 2
    assert parse_target("tcp/robot:1", port=2).port == 2
    assert parse_target("robot", protocol="rosbridge", port=8765).port == 8765


@pytest.mark.parametrize("protocol", ["auto", "zenoh"])
def test_tcp_endpoint_is_zenoh(protocol: str) -> None:
    ep = parse_target("tcp/10.0.0.5:7448", protocol=protocol)
    assert (ep.host, ep.port, ep.zenoh, ep.secure) == ("10.0.0.5", 7448, True, False)
    assert parse_target("tcp/robot", protocol=protocol).port == DEFAULT_PORTS["zenoh"]
    assert parse_target("TCP/[::1]:1", protocol=protocol).host == "::1"


@pytest.mark.parametrize("protocol", ["auto", "zenoh"])
def test_tls_endpoint_is_a_secure_zenoh_link(protocol: str) -> None:
    ep = parse_target("tls/robot.example:7448", protocol=protocol)
    assert (ep.host, ep.port, ep.zenoh, ep.secure) == ("robot.example", 7448, True, True)
    assert ep.zenoh_locator == "tls/robot.example:7448"
    assert parse_target("TLS/[::1]", protocol=protocol).zenoh_locator == "tls/[::1]:7447"
    assert parse_target("tcp/robot:1", protocol=protocol, secure=True).zenoh_locator == (
        "tls/robot:1"
    )
    assert parse_target("tls/robot:1", secure=False).zenoh_locator == "tcp/robot:1"
    with pytest.raises(ValueError, match="zenoh target"):
        parse_target("tls/robot:1", protocol="rosbridge")


def test_endpoint_url() -> None:
    assert parse_target("robot:9000").url == "ws://robot:9000/"
    assert parse_target("[::1]:9000").url == "ws://[::1]:9000/"
    assert parse_target("[FE80::1]").url == "ws://[fe80::1]:8765/"
    assert parse_target("wss://robot/foxglove").url == "wss://robot:8765/foxglove"
    assert Endpoint(host="2001:db8::1", port=1, secure=True, path="/x").url == (
        "wss://[2001:db8::1]:1/x"
    )


# -- rejected forms --------------------------------------------------------------------
@pytest.mark.parametrize(
    "target",
    [
        "",
        "   ",
        "\t\n",
        "robot local",  # inner whitespace
        "ws://robot /x",
        # bad port text
        "robot:abc",
        "robot:-1",
        "robot:+80",
        "robot:80a",
        "robot: 80",
        "robot:8.5",
        "robot:0",
        "robot:00",
        "robot:65536",
        "robot:99999999999999999999",
        "[::1]:0",
        "[::1]:65536",
        "[::1]:x",
        "ws://robot:0/",
        "tcp/robot:70000",
        # IPv6 without brackets
        "::1",
        "fe80::1",
        "2001:db8::1:8765",
        "robot:1:2",
        # brackets
        "[::1",
        "ws://[::1",
        "[::1]x",
        "[::1]9000",
        "[]",
        "[]:1",
        "[robot]",
        "[1.2.3.4]",
        "[::1]]",
        # unknown schemes and transports
        "ftp://robot",
        "ws+unix://robot",
        "://robot",
        "tcp://robot",
        "udp/robot:7447",
        # credentials
        "user@robot",
        "ws://user:pw@robot",
        "wss://user@robot:9/",
        "tcp/user@robot:7447",
        # no or bad host
        ":8765",
        "ws://",
        "ws://:1",
        "ws:///path",
        "robot/path",
        "robot?x",
        "-robot",
        "robot-",
        "robot!",
        "tcp/",
        "r\u00f6bot",
    ],
)
def test_malformed_targets_raise_value_error(target: str) -> None:
    with pytest.raises(ValueError):  # noqa: PT011 - any ValueError message is fine
        parse_target(target)


@pytest.mark.parametrize("target", [None, b"robot", 8765, ["robot"], ("robot", 1)])
def test_non_str_target_is_a_type_error(target: object) -> None:
    with pytest.raises(TypeError, match="target"):
        parse_target(target)  # type: ignore[arg-type]


@pytest.mark.parametrize("port", [True, False, "8765", 8765.0, b"1"])
def test_port_argument_must_be_an_int(port: object) -> None:
    with pytest.raises(TypeError, match="port"):
        parse_target("robot", port=port)  # type: ignore[arg-type]


@pytest.mark.parametrize("port", [0, -1, 65536, 10**9])
def test_port_argument_out_of_range(port: int) -> None:
    with pytest.raises(ValueError, match="port"):
        parse_target("robot", port=port)


@pytest.mark.parametrize("secure", ["yes", 1, 0])
def test_secure_argument_must_be_a_bool(secure: object) -> None:
    with pytest.raises(TypeError, match="secure"):
        parse_target("robot", secure=secure)  # type: ignore[arg-type]


@pytest.mark.parametrize("protocol", ["", "foxglove", "ws", "ROSBRIDGE", "zenoh ", None])
def test_unknown_protocol(protocol: object) -> None:
    with pytest.raises(ValueError, match="protocol"):
        parse_target("robot", protocol=protocol)  # type: ignore[arg-type]


@pytest.mark.parametrize("protocol", ["foxglove-ws", "rosbridge"])
def test_zenoh_endpoint_with_a_websocket_protocol(protocol: str) -> None:
    with pytest.raises(ValueError, match="zenoh"):
        parse_target("tcp/robot:7447", protocol=protocol)


@pytest.mark.parametrize("target", ["robot:\u0663", "robot:\uff18\uff17\uff16\uff15"])
def test_non_ascii_digits_are_not_a_port(target: str) -> None:
    with pytest.raises(ValueError, match="port"):
        parse_target(target)


@pytest.mark.parametrize(
    "target", ["010.1.1.1", "0177.0.0.1", "127.1", "2130706433", "0x7f.0.0.1", "1.2.3.256"]
)
def test_numeric_hosts_that_are_not_ipv4_are_rejected(target: str) -> None:
    with pytest.raises(ValueError):  # noqa: PT011
        parse_target(target)


@pytest.mark.parametrize("target", ["robot:", "[::1]:", "ws://robot:/"])
def test_an_empty_port_is_rejected(target: str) -> None:
    with pytest.raises(ValueError, match="port"):
        parse_target(target)


# -- properties ------------------------------------------------------------------------------
def _check_endpoint(ep: Endpoint) -> None:
    assert isinstance(ep, Endpoint)
    assert ep.host
    assert 0 < ep.port < 65536
    assert ep.path.startswith("/")
    assert ep.url.startswith("wss://" if ep.secure else "ws://")


_PIECES = st.sampled_from(
    [
        "ws://",
        "wss://",
        "http://",
        "tcp/",
        "udp/",
        "[",
        "]",
        ":",
        "::",
        "/",
        "@",
        "%",
        ".",
        "-",
        "_",
        "robot",
        "local",
        "::1",
        "fe80::1",
        "10.0.0.1",
        "0",
        "8765",
        "65536",
        "\u0663",
        " ",
        "\x00",
    ]
)


@settings(max_examples=examples(400), deadline=None)
@given(
    target=st.one_of(st.text(), st.lists(_PIECES, max_size=8).map("".join)),
    protocol=st.sampled_from(["auto", "foxglove-ws", "rosbridge", "zenoh", "bogus"]),
    port=st.one_of(st.none(), st.integers(-5, 70000)),
    secure=st.one_of(st.none(), st.booleans()),
)
def test_no_text_raises_anything_but_value_or_type_error(
    target: str, protocol: str, port: int | None, secure: bool | None
) -> None:
    try:
        ep = parse_target(target, protocol=protocol, port=port, secure=secure)
    except (ValueError, TypeError):
        return
    _check_endpoint(ep)
    if port is not None:
        assert ep.port == port
    if secure is not None:
        assert ep.secure is secure


_HOSTNAMES = st.from_regex(r"\A[a-z][a-z0-9-]{0,20}(\.[a-z][a-z0-9-]{0,20}){0,3}\Z").filter(
    lambda h: not h.endswith("-") and "-." not in h
)


@given(host=_HOSTNAMES, port=st.integers(1, 65535), scheme=st.sampled_from(["", "ws://", "wss://"]))
def test_hostname_and_port_round_trip(host: str, port: int, scheme: str) -> None:
    ep = parse_target(f"{scheme}{host}:{port}")
    assert (ep.host, ep.port, ep.secure) == (host, port, scheme == "wss://")
    assert ep.url == f"{'wss' if ep.secure else 'ws'}://{host}:{port}/"


@given(address=st.ip_addresses(), port=st.integers(1, 65535))
def test_ip_address_round_trip(
    address: ipaddress.IPv4Address | ipaddress.IPv6Address, port: int
) -> None:
    text = f"[{address}]" if address.version == 6 else str(address)
    ep = parse_target(f"{text}:{port}")
    assert ep.host == str(address)
    assert ep.port == port
    assert ep.url == f"ws://{text}:{port}/"
    # the unbracketed IPv6 spelling of the same address is rejected
    if address.version == 6:
        with pytest.raises(ValueError, match="IPv6"):
            parse_target(f"{address}:{port}")
