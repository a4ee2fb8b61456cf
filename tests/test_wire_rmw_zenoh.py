"""rmw_zenoh's naming conventions (wire/rmw_zenoh.py): round trips, the exact
strings rmw_zenoh_cpp writes, and every malformed input refused with
MalformedKey / MalformedAttachment, never another exception."""

from __future__ import annotations

import contextlib
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ros_mobile_bridge.wire import rmw_zenoh as rz

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"

identifiers = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,15}", fullmatch=True)
ros_names = st.lists(identifiers, min_size=1, max_size=4).map(lambda p: "/" + "/".join(p))
type_names = st.builds(
    lambda pkg, kind, t: f"{pkg}/{kind}/{t}",
    identifiers,
    st.sampled_from(["msg", "srv", "action"]),
    identifiers,
)
hashes = st.from_regex(r"RIHS01_[0-9a-f]{64}", fullmatch=True)
domains = st.integers(0, 232)
qos_values = st.builds(rz.Qos, st.booleans(), st.booleans(), st.booleans(), st.integers(0, 10**6))


def test_the_exact_strings_rmw_zenoh_writes() -> None:
    key = rz.TopicKey(0, "/chatter", "std_msgs/msg/String", STRING_HASH)
    assert rz.format_key(key) == f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    token = rz.Token(
        domain=0,
        zid="aac3178e146ba6f1fc6e6a4085e77f21",
        node_id=0,
        entity_id=10,
        kind=rz.EntityKind.PUBLISHER,
        enclave="",
        namespace="/",
        node_name="talker",
        name="/cmd_vel",
        type_name="geometry_msgs/msg/Twist",
        type_hash=TWIST_HASH,
        qos=rz.Qos(),
    )
    assert rz.format_token(token) == (
        "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MP/%/%/talker/%cmd_vel/"
        f"geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}/::,10:,:,:,,"
    )
    assert rz.liveliness_selector(7) == "@ros2_lv/7/**"
    assert rz.dds_type_name("example_interfaces/action/Fibonacci_SendGoal") == (
        "example_interfaces::action::dds_::Fibonacci_SendGoal_"
    )


def test_a_name_with_slashes_parses_from_the_right() -> None:
    key = f"3/robot1/camera/image_raw/sensor_msgs::msg::dds_::Image_/{STRING_HASH}"
    parsed = rz.parse_key(key)
    assert parsed == rz.TopicKey(
        3, "/robot1/camera/image_raw", "sensor_msgs/msg/Image", STRING_HASH
    )


@given(domains, ros_names, type_names, hashes)
def test_keys_round_trip(domain: int, name: str, type_name: str, hash_: str) -> None:
    key = rz.TopicKey(domain, name, type_name, hash_)
    assert rz.parse_key(rz.format_key(key)) == key


@given(qos_values)
def test_qos_round_trips(qos: rz.Qos) -> None:
    assert rz.parse_qos(rz.format_qos(qos)) == qos


def test_qos_as_peers_write_it() -> None:
    assert rz.parse_qos("::,10:,:,:,,") == rz.Qos()
    assert rz.parse_qos("2:1:1,5:,:,:,,") == rz.Qos(reliable=False, transient_local=True, depth=5)
    assert rz.parse_qos("1:2:2,0:1,5:0,0:1,2,3") == rz.Qos(keep_all=True, depth=0)


@given(
    domains,
    st.from_regex(r"[0-9a-f]{1,32}", fullmatch=True),
    st.integers(0, 2**31),
    st.integers(0, 2**31),
    st.sampled_from(list(rz.EntityKind)),
    st.sampled_from(["", "/", "/enclave"]),
    st.one_of(st.just("/"), ros_names),
    identifiers,
    ros_names,
    type_names,
    hashes,
    qos_values,
)
def test_tokens_round_trip(
    domain: int,
    zid: str,
    node_id: int,
    entity_id: int,
    kind: rz.EntityKind,
    enclave: str,
    namespace: str,
    node: str,
    name: str,
    type_name: str,
    hash_: str,
    qos: rz.Qos,
) -> None:
    if kind is rz.EntityKind.NODE:
        token = rz.Token(domain, zid, node_id, entity_id, kind, enclave, namespace, node)
    else:
        token = rz.Token(
            domain,
            zid,
            node_id,
            entity_id,
            kind,
            enclave,
            namespace,
            node,
            name,
            type_name,
            hash_,
            qos,
        )
    parsed = rz.parse_token(rz.format_token(token))
    # the empty enclave is written "%" and reads back as "/", as in rmw_zenoh
    assert parsed == rz.Token(
        domain,
        zid,
        node_id,
        entity_id,
        kind,
        enclave or "/",
        namespace,
        node,
        *((name, type_name, hash_, qos) if kind is not rz.EntityKind.NODE else ()),
    )


@given(
    st.integers(-(2**63), 2**63 - 1),
    st.integers(-(2**63), 2**63 - 1),
    st.binary(min_size=16, max_size=16),
)
def test_attachments_round_trip(seq: int, ts: int, gid: bytes) -> None:
    data = rz.encode_attachment(seq, ts, gid)
    assert len(data) == rz.ATTACHMENT_SIZE == 33
    assert data[16] == 0x10
    assert rz.decode_attachment(data) == rz.Attachment(seq, ts, gid)


def test_attachment_layout_is_little_endian() -> None:
    data = rz.encode_attachment(1, 2, bytes(range(16)))
    assert data == (1).to_bytes(8, "little") + (2).to_bytes(8, "little") + b"\x10" + bytes(
        range(16)
    )


@pytest.mark.parametrize(
    "data",
    [None, b"", b"\x00" * 32, b"\x00" * 34, b"\x00" * 16 + b"\x0f" + b"\x00" * 16],
    ids=["missing", "empty", "short", "long", "bad-gid-length"],
)
def test_malformed_attachments(data: bytes | None) -> None:
    with pytest.raises(rz.MalformedAttachment):
        rz.decode_attachment(data)


def keyed(seq: int, ts: int, gid: bytes) -> bytes:
    """The keyed form rmw_zenoh_cpp Jazzy 0.2.0-0.2.3 (Rolling 0.3.0-0.5.0)
    sends, built by hand from zenoh-ext's layout: each name a string (one
    length byte, its bytes), each number an int64 little-endian, the gid a
    byte array (one length byte 0x10, 16 bytes)."""

    def string(text: str) -> bytes:
        return bytes([len(text)]) + text.encode()

    return (
        string("sequence_number")
        + seq.to_bytes(8, "little", signed=True)
        + string("source_timestamp")
        + ts.to_bytes(8, "little", signed=True)
        + string("source_gid")
        + b"\x10"
        + gid
    )


def test_the_keyed_form_of_early_releases_is_read() -> None:
    gid = bytes(range(100, 116))
    data = keyed(7, 1_700_000_000_123_456_789, gid)
    assert len(data) == rz.KEYED_ATTACHMENT_SIZE == 77
    assert rz.decode_attachment(data) == rz.Attachment(7, 1_700_000_000_123_456_789, gid)
    assert rz.attachment_timestamp(data) == 1_700_000_000_123_456_789
    assert rz.encode_keyed_attachment(7, 1_700_000_000_123_456_789, gid) == data


def test_the_fixed_form_is_read_by_the_hot_path_check() -> None:
    data = rz.encode_attachment(3, 42, bytes(16))
    assert rz.attachment_timestamp(data) == 42
    assert rz.attachment_timestamp(None) is None
    assert rz.attachment_timestamp(data[:-1]) is None
    assert rz.attachment_timestamp(data[:16] + b"\x0f" + data[17:]) is None


@given(
    st.integers(-(2**63), 2**63 - 1),
    st.integers(-(2**63), 2**63 - 1),
    st.binary(min_size=16, max_size=16),
)
def test_both_forms_decode_to_the_same_attachment(seq: int, ts: int, gid: bytes) -> None:
    fixed = rz.decode_attachment(rz.encode_attachment(seq, ts, gid))
    assert rz.decode_attachment(keyed(seq, ts, gid)) == fixed == rz.Attachment(seq, ts, gid)


@pytest.mark.parametrize(
    "mutate",
    [
        lambda d: d[:-1],
        lambda d: d + b"\x00",
        lambda d: b"\x0e" + d[1:],  # the first name's length
        lambda d: d[:1] + b"S" + d[2:],  # "Sequence_number"
        lambda d: d[:24] + b"\x10source_timestamq" + d[41:],
        lambda d: d[:49] + b"\x0asource_gie" + d[60:],
        lambda d: d[:60] + b"\x0f" + d[61:],  # the gid's length
    ],
    ids=["short", "long", "name-length", "name", "second-name", "third-name", "gid-length"],
)
def test_a_malformed_keyed_attachment_is_refused(mutate: Any) -> None:
    data = mutate(keyed(1, 2, bytes(16)))
    with pytest.raises(rz.MalformedAttachment):
        rz.decode_attachment(data)
    assert rz.attachment_timestamp(data) is None


@given(st.one_of(st.binary(max_size=96), st.binary(min_size=77, max_size=77)))
def test_any_bytes_decode_or_raise_malformed(data: bytes) -> None:
    with contextlib.suppress(rz.MalformedAttachment):
        rz.decode_attachment(data)
    stamp = rz.attachment_timestamp(data)
    assert stamp is None or isinstance(stamp, int)


# gids computed by rmw_zenoh_cpp's own code (Jazzy 0.2.10: XXH3-128 of the
# liveliness key, low then high 64 bits memcpy'd on a little-endian machine)
GID_VECTORS = [
    (
        "@ros2_lv/0/8f3c2a9e5b7d4c1e0f2a3b4c5d6e7f80/0/3/MP/%/%/talker/%chatter/"
        "std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,",
        "7a09db853b7bb8e3cc621d6f3c8d4194",
    ),
    ("x" * 300, "5435c87d60b4d1a57abcd72aea375212"),  # past XXH3's 240-byte path
]


@pytest.mark.parametrize(("key", "gid"), GID_VECTORS, ids=["publisher-token", "long-key"])
def test_entity_gid_is_rmw_zenohs(key: str, gid: str) -> None:
    assert rz.entity_gid(key).hex() == gid


def test_entity_gid_is_the_low_half_then_the_high_half_little_endian() -> None:
    # XXH3-128 of the empty input is 99aa06d3014798d8 (high) 6001c324468d497f (low)
    assert rz.entity_gid("") == bytes.fromhex("7f498d4624c30160d8984701d306aa99")


BAD_KEYS = [
    "",
    "0/chatter",
    f"0/std_msgs::msg::dds_::String_/{STRING_HASH}",  # no name
    f"x/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}",
    f"233/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}",
    f"0/chatter/std_msgs/msg/String/{STRING_HASH}",
    "0/chatter/std_msgs::msg::dds_::String_/RIHS01_short",
    "0/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported",
    f"0//chatter/std_msgs::msg::dds_::String_/{STRING_HASH}",
    "0/" + "a/" * 3000 + f"std_msgs::msg::dds_::String_/{STRING_HASH}",
]


@pytest.mark.parametrize("key", BAD_KEYS)
def test_malformed_keys(key: str) -> None:
    with pytest.raises(rz.MalformedKey):
        rz.parse_key(key)


GOOD_TOKEN = (
    "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MP/%/%/talker/%cmd_vel/"
    f"geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}/::,10:,:,:,,"
)
BAD_TOKENS = [
    "",
    "@ros2_lv/0",
    GOOD_TOKEN.replace("@ros2_lv", "@ros_lv"),
    GOOD_TOKEN.replace("/MP/", "/XX/"),
    GOOD_TOKEN.replace("/0/10/", "/a/10/"),
    GOOD_TOKEN.replace("aac3178e", "AAC3178E"),
    GOOD_TOKEN.replace("/talker/", "//"),
    GOOD_TOKEN.replace("%cmd_vel", "cmd_vel"),
    GOOD_TOKEN.replace("::,10:,:,:,,", "::,10"),
    GOOD_TOKEN.replace("::,10:,:,:,,", "9::,10:,:,:,,"),
    GOOD_TOKEN.replace("::,10:,:,:,,", "::,x:,:,:,,"),
    GOOD_TOKEN.replace(TWIST_HASH, "RIHS01_00"),
    GOOD_TOKEN.replace("geometry_msgs::msg::dds_::Twist_", "geometry_msgs/msg/Twist"),
    "@ros2_lv/0/aac3/0/0/NN/%/%/node/%extra/t::msg::dds_::T_/" + TWIST_HASH + "/::,10:,:,:,,"[:0],
    "@ros2_lv/0/aac3/0/0/NN/%/%/node/%x/a::msg::dds_::T_/" + TWIST_HASH,
    GOOD_TOKEN + "x" * rz.MAX_KEY_LENGTH,
]


@pytest.mark.parametrize("token", BAD_TOKENS)
def test_malformed_tokens(token: str) -> None:
    with pytest.raises(rz.MalformedKey):
        rz.parse_token(token)


@given(st.text(max_size=300))
def test_any_text_parses_or_raises_malformed(text: str) -> None:
    for parser in (rz.parse_key, rz.parse_token, rz.parse_qos, rz.ros_type_name):
        with contextlib.suppress(rz.MalformedKey):
            parser(text)


@given(
    st.lists(
        st.sampled_from(["@ros2_lv", "0", "%", "MP", "NN", "a", "", "::,10:,:,:,,"]), max_size=14
    )
)
def test_token_shaped_text_parses_or_raises_malformed(parts: list[str]) -> None:
    with contextlib.suppress(rz.MalformedKey):
        rz.parse_token("/".join(parts))


@pytest.mark.parametrize(
    "call",
    [
        lambda: rz.format_key(rz.TopicKey(233, "/a", "std_msgs/msg/String", STRING_HASH)),
        lambda: rz.format_key(rz.TopicKey(0, "/", "std_msgs/msg/String", STRING_HASH)),
        lambda: rz.format_key(rz.TopicKey(0, "/a/*", "std_msgs/msg/String", STRING_HASH)),
        lambda: rz.format_key(rz.TopicKey(0, "/a", "String", STRING_HASH)),
        lambda: rz.format_key(rz.TopicKey(0, "/a", "std_msgs/msg/String", "RIHS01_x")),
        lambda: rz.format_qos(rz.Qos(depth=-1)),
        lambda: rz.encode_attachment(0, 0, b"short"),
        lambda: rz.encode_attachment(2**63, 0, bytes(16)),
        lambda: rz.liveliness_selector(-1),
    ],
)
def test_bad_caller_arguments_raise_value_error(call: object) -> None:
    with pytest.raises(ValueError):  # noqa: PT011 - each call names its own reason
        call()  # type: ignore[operator]


def test_entity_gid_is_16_stable_bytes() -> None:
    gid = rz.entity_gid(GOOD_TOKEN)
    assert len(gid) == 16
    assert gid == rz.entity_gid(GOOD_TOKEN)
    assert gid != rz.entity_gid(GOOD_TOKEN.replace("/10/", "/11/"))


def test_the_key_value_attachment_of_the_first_jazzy_releases_is_read() -> None:
    """rmw_zenoh_cpp's first Jazzy binaries wrote the three values as
    key-value pairs (zenoh-ext strings and buffers, each with its length in
    front; test_zenoh_queryable.py checks this layout against zenoh-ext)."""
    gid = bytes(range(16))
    data = (
        b"\x0fsequence_number"
        + (42).to_bytes(8, "little", signed=True)
        + b"\x10source_timestamp"
        + (-7).to_bytes(8, "little", signed=True)
        + b"\x0asource_gid\x10"
        + gid
    )
    assert len(data) == rz.KEYED_ATTACHMENT_SIZE == 77
    assert rz.decode_attachment(data) == rz.Attachment(42, -7, gid)
    for bad in (data.replace(b"source_gid", b"source_gix"), data[:-17] + b"\x0f" + bytes(16)):
        with pytest.raises(rz.MalformedAttachment):
            rz.decode_attachment(bad)


def test_a_request_item_carries_its_query() -> None:
    item = rz.Request(3, 9, "k", b"p", None)
    assert (item.tag, item.query_id, item.key, item.payload, item.attachment) == (
        3,
        9,
        "k",
        b"p",
        None,
    )
    assert repr(item).startswith("Request(")
