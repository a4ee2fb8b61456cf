"""Types learnt from the robot over Zenoh (REP-2011 get_type_description),
against zenoh-ros2-sdk nodes (tests/peers/zenoh_sdk_node.py) that serve
``/<node>/get_type_description`` from the official ROS 2 Jazzy description
files. test_msgs is not bundled with the library: its types are unknown
until a node describes them.

An un-bundled nested type reaches ``async for`` decoded; a service of such a
type is called; an answer whose hash disagrees with the key is refused and
counted, nothing decoded; a silent node gives a SchemaError within the
timeout; what was learnt is cached for the process; fetch_definition,
schema_definition and the recorder's schema text work for it. With several
nodes using the type, each is asked in turn until one answers with the
right hash (a silent, refusing or lying first node does not stop it); when
all fail the error names each; a type no node described is asked of a new
node that starts using it."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest
from mcap.reader import make_reader

import ros_mobile_bridge as rmb
from _util import wait_until
from _util import zenoh_options as options
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.codec import DESCRIPTION_CACHE, CodecRegistry, description_hash

pytest_plugins = ["peers.ros_fixtures"]
pytest.importorskip("zenoh_ros2_sdk")

NESTED = "test_msgs/msg/Nested"
ARRAYS = "test_msgs/msg/Arrays"
BASIC_SRV = "test_msgs/srv/BasicTypes"
NESTED_VALUES = {
    "basic_types_value": {
        "bool_value": True,
        "int32_value": -42,
        "uint64_value": 2**63,
        "float64_value": 1.5,
        "uint8_value": 200,
    }
}
ARRAYS_VALUES = {
    "int32_values": [1, -2, 3],
    "string_values": ["a", "bc", "def"],
    "basic_types_values": [{"int8_value": -1}, {"float32_value": 0.5}, {"bool_value": True}],
}


@pytest.fixture(autouse=True)
def _fresh_cache() -> Iterator[None]:
    """Each test starts with an empty process cache (what it learns stays in it)."""
    DESCRIPTION_CACHE.clear()
    yield
    DESCRIPTION_CACHE.clear()


def talker(sdk: Callable[..., SdkNode], type_name: str, values: Any, *flags: str) -> SdkNode:
    return sdk(
        "talker",
        "--topic",
        "/described",
        "--type",
        type_name,
        "--values",
        json.dumps(values),
        "--rate",
        "50",
        *flags,
    )


async def first_messages(client: rmb.Client, count: int) -> list[rmb.Message]:
    await wait_until(
        lambda: any(t.name == "/described" for t in client.topics), timeout=15.0, what="the talker"
    )
    got: list[rmb.Message] = []
    async with client.subscribe("/described") as sub:
        with anyio.fail_after(20):
            async for message in sub:
                got.append(message)
                if len(got) == count:
                    break
    return got


def test_test_msgs_is_not_bundled() -> None:
    registry = CodecRegistry()
    assert not registry.resolves(NESTED)
    assert not registry.resolves(BASIC_SRV + "_Request")


@pytest.mark.parametrize(
    ("type_name", "values"), [(NESTED, NESTED_VALUES), (ARRAYS, ARRAYS_VALUES)]
)
async def test_an_unknown_type_with_nested_types_is_fetched_and_decoded(
    sdk: Callable[..., SdkNode],
    zenoh_router: Any,
    zenoh_domain: int,
    type_name: str,
    values: dict[str, Any],
) -> None:
    node = talker(sdk, type_name, values, "--describe")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        got = await first_messages(client, 5)
        assert client.rejections == {}
    assert [m.decode_error for m in got] == [None] * 5
    assert {m.schema_name for m in got} == {type_name}
    data = got[0].data
    if type_name == NESTED:
        basic = data.basic_types_value
        assert (basic.bool_value, basic.int32_value) == (True, -42)
        assert (basic.uint64_value, basic.float64_value) == (2**63, 1.5)
        assert (basic.uint8_value, basic.int16_value) == (200, 0)
    else:
        assert list(data.int32_values) == [1, -2, 3]
        assert data.string_values == ["a", "bc", "def"]
        assert [b.int8_value for b in data.basic_types_values] == [-1, 0, 0]
        assert data.basic_types_values[1].float32_value == 0.5
        assert len(data.defaults_values) == 3
    assert node.described() == [type_name]  # asked once for all five


async def test_a_service_of_an_unknown_type_is_called_and_answered(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    node = sdk("service", "--type", BASIC_SRV, "--name", "/echo_basic", "--describe")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await wait_until(
            lambda: any(s.name == "/echo_basic" for s in client.services),
            timeout=15.0,
            what="the service",
        )
        for value in (7, -8):
            answer = await client.call_service(
                "/echo_basic", {"int32_value": value, "string_value": f"v{value}"}, timeout=10
            )
            assert (answer.int32_value, answer.string_value) == (value, f"v{value}")
            assert answer.bool_value is False
        assert client.rejections == {}
    assert node.described() == [BASIC_SRV]


async def test_an_answer_whose_hash_disagrees_is_refused_and_counted(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    node = talker(sdk, NESTED, NESTED_VALUES, "--describe-wrong")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        got = await first_messages(client, 5)
        assert client.rejections == {"type_hash_mismatch": 1}
        with pytest.raises(rmb.SchemaError):
            client.schema_definition(NESTED)
    assert all(isinstance(m.data, memoryview) for m in got)
    assert all(m.decode_error and "no decoder" in m.decode_error for m in got)
    assert node.described() == [NESTED]


async def test_a_silent_node_gives_a_schema_error_within_the_timeout(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    sdk("service", "--type", BASIC_SRV, "--name", "/silent_basic", "--describe-silent")
    opts = options(zenoh_domain, type_description_timeout=1.0)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        await wait_until(
            lambda: any(s.name == "/silent_basic" for s in client.services),
            timeout=15.0,
            what="the service",
        )
        with anyio.fail_after(5), pytest.raises(rmb.SchemaError) as caught:
            await client.call_service("/silent_basic", {"int32_value": 1}, timeout=10)
        text = str(caught.value)
        assert BASIC_SRV in text
        assert "node /sdk_service did not describe it within 1 s" in text
        assert "Client.register_type" in text
        assert "ClientOptions.interface_paths" in text
        # the outcome is kept for the connection: no second wait
        with anyio.fail_after(0.5), pytest.raises(rmb.SchemaError):
            await client.call_service("/silent_basic", {"int32_value": 1}, timeout=10)


async def test_a_fetched_description_is_cached_for_the_next_connection(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    node = talker(sdk, NESTED, NESTED_VALUES, "--describe")
    for _ in range(2):
        async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
            got = await first_messages(client, 3)
            assert [m.decode_error for m in got] == [None] * 3
            assert got[0].data.basic_types_value.int32_value == -42
    assert node.described() == [NESTED]
    assert DESCRIPTION_CACHE.hits >= 1


async def test_fetch_definition_schema_definition_and_recorder_text(
    sdk: Callable[..., SdkNode],
    zenoh_router: Any,
    zenoh_domain: int,
    tmp_path: Path,
    ros_share: Path,
) -> None:
    talker(sdk, NESTED, NESTED_VALUES, "--describe")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await wait_until(
            lambda: any(t.name == "/described" for t in client.topics),
            timeout=15.0,
            what="the talker",
        )
        with pytest.raises(rmb.SchemaError):
            client.schema_definition(NESTED)
        assert await client.fetch_definition(NESTED) is True
        fields = client.schema_definition(NESTED)
        assert [(f.name, f.type) for f in fields] == [
            ("basic_types_value", "test_msgs/msg/BasicTypes")
        ]
        basic = {f.name: f.type for f in client.schema_definition("test_msgs/msg/BasicTypes")}
        assert basic["int32_value"] == "int32"
        assert client.schema_template(NESTED)["basic_types_value"]["uint64_value"] == 0
        path = tmp_path / "described.mcap"
        async with client.record(path, topics=["/described"]) as recording:
            await first_messages(client, 3)
            # the recorder's task writes what it was handed in its own turn:
            # leaving before it did would cancel it with frames unwritten
            await wait_until(
                lambda: recording.stats.messages.get("/described", 0) >= 3,
                timeout=15.0,
                what="recorded",
            )
        assert recording is not None
    with path.open("rb") as f:
        recorded = list(make_reader(f).iter_messages(log_time_order=False))
    assert len(recorded) >= 3
    schema = recorded[0][0]
    assert schema is not None
    assert (schema.name, schema.encoding) == (NESTED, "ros2msg")
    text = schema.data.decode()
    # the official .msg texts the node sent, verbatim (comments kept)
    nested = (ros_share / f"{NESTED}.msg").read_text().rstrip("\n")
    basic = (ros_share / "test_msgs/msg/BasicTypes.msg").read_text().rstrip("\n")
    assert text == f"{nested}\n{'=' * 80}\nMSG: test_msgs/BasicTypes\n{basic}\n"


async def test_samples_held_during_a_fetch_are_bounded_and_counted(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    """A silent node: the samples that arrive while we wait for it are held
    (5 at most here, the rest counted), then delivered raw, in order, with
    the ones after them."""
    talker(sdk, NESTED, NESTED_VALUES, "--describe-silent")
    opts = options(zenoh_domain, type_description_timeout=1.0, type_description_hold=5)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        got = await first_messages(client, 8)
        overflow = client.rejections.get("description_hold_overflow", 0)
        assert overflow >= 10  # 50 Hz for 1 s, 5 held
        assert set(client.rejections) == {"description_hold_overflow", "type_description_timeout"}
    assert all(isinstance(m.data, memoryview) for m in got)
    stamps = [m.log_time_ns for m in got]  # the publisher's stamps
    assert None not in stamps
    assert stamps == sorted(stamps)


TWIST = "geometry_msgs/msg/Twist"
DESCRIBE = "type_description_interfaces/srv/GetTypeDescription"


async def test_our_node_describes_the_types_it_publishes_to_an_sdk_client(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int, ros_share: Path
) -> None:
    official = json.loads((ros_share / f"{TWIST}.json").read_text())
    twist_hash = official["type_hashes"][0]["hash_string"]
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.1}})
        node = f"rmb_{client.server_info.session_id[:12]}"
        service = f"/{node}/get_type_description"
        requests = [
            {"type_name": TWIST, "type_hash": twist_hash, "include_type_sources": True},
            {"type_name": TWIST, "type_hash": "RIHS01_" + "0" * 64, "include_type_sources": False},
            {"type_name": "std_msgs/msg/String", "type_hash": "", "include_type_sources": True},
        ]
        caller = await anyio.to_thread.run_sync(
            lambda: sdk(
                "client", "--name", service, "--type", DESCRIBE, "--requests", json.dumps(requests)
            )
        )
        await wait_until(lambda: caller.done, timeout=15.0, what="the sdk's calls")
        answers = [record["response"] for record in caller.records()]
        await client.publish_zero_twist()
    assert len(answers) == 3
    first = answers[0]
    assert first["successful"] is True
    assert description_hash(first["type_description"]) == twist_hash
    described = first["type_description"]["type_description"]
    assert described["type_name"] == TWIST
    assert [f["name"] for f in described["fields"]] == ["linear", "angular"]
    assert answers[1]["successful"] is False
    assert "not RIHS01_000" in answers[1]["failure_reason"]
    assert answers[2]["successful"] is False
    assert "does not publish" in answers[2]["failure_reason"]


# -- more than one node: each is asked in turn ---------------------------------------------
BAD_MODES = {
    "--describe-silent": "type_description_timeout",
    "--describe-refuse": "type_description_refused",
    "--describe-wrong": "type_hash_mismatch",
}


def named_talker(sdk: Callable[..., SdkNode], node: str, flag: str) -> SdkNode:
    return talker(sdk, NESTED, NESTED_VALUES, flag, "--node", node)


async def wait_for_describers(client: rmb.Client, *nodes: str) -> None:
    """Until every node's get_type_description and the talkers' topic are in the graph."""
    wanted = {f"/{node}/get_type_description" for node in nodes}
    await wait_until(
        lambda: (
            wanted <= {s.name for s in client.services}
            and any(t.name == "/described" for t in client.topics)
        ),
        timeout=15.0,
        what="the describing nodes",
    )


@pytest.mark.parametrize("flag", sorted(BAD_MODES))
async def test_when_the_first_node_fails_the_next_one_is_asked(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int, flag: str
) -> None:
    """Two nodes publish the type; the one asked first (publishers are asked
    in the order of their node names, so ``sdk_a_bad`` before ``sdk_b_good``)
    times out, refuses or answers another hash; the other is then asked and
    the messages decode. The failure is counted by kind and named per node."""
    bad = named_talker(sdk, "sdk_a_bad", flag)
    good = named_talker(sdk, "sdk_b_good", "--describe")
    # two talkers at 50 Hz for the 3 s the silent one is waited for: hold them all
    opts = options(zenoh_domain, type_description_timeout=3.0, type_description_hold=2048)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        await wait_for_describers(client, "sdk_a_bad", "sdk_b_good")
        got = await first_messages(client, 5)
        rejections = client.rejections
    assert [m.decode_error for m in got] == [None] * 5
    assert got[0].data.basic_types_value.int32_value == -42
    assert rejections == {BAD_MODES[flag]: 1}  # the bad node was asked, first, once
    assert good.described() == [NESTED]
    if flag != "--describe-silent":  # a silent node never says it was asked
        assert bad.described() == [NESTED]


async def test_when_every_node_fails_the_error_names_each_and_why(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    for node, flag in (
        ("sdk_a_silent", "--describe-silent"),
        ("sdk_b_refuse", "--describe-refuse"),
        ("sdk_c_wrong", "--describe-wrong"),
    ):
        named_talker(sdk, node, flag)
    opts = options(zenoh_domain, type_description_timeout=3.0)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        await wait_for_describers(client, "sdk_a_silent", "sdk_b_refuse", "sdk_c_wrong")
        with anyio.fail_after(20), pytest.raises(rmb.SchemaError) as caught:
            await client.fetch_definition(NESTED)
        assert client.rejections == {
            "type_description_timeout": 1,
            "type_description_refused": 1,
            "type_hash_mismatch": 1,
        }
    error = caught.value
    assert list(error.failures) == ["/sdk_a_silent", "/sdk_b_refuse", "/sdk_c_wrong"]
    assert "within 3 s (type_description_timeout)" in error.failures["/sdk_a_silent"]
    assert "sdk_b_refuse refuses to describe" in error.failures["/sdk_b_refuse"]
    assert "described another" in error.failures["/sdk_c_wrong"]
    text = str(error)
    for node, why in error.failures.items():
        assert f"node {node} {why}" in text
    assert "Client.register_type" in text


async def test_a_type_no_node_described_is_fetched_again_when_a_new_node_uses_it(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    """The only node answers another hash: messages arrive raw. A second,
    honest node starts publishing the type: it is asked (the first is not
    asked again) and the messages decode from then on."""
    bad = named_talker(sdk, "sdk_a_wrong", "--describe-wrong")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await wait_for_describers(client, "sdk_a_wrong")
        async with client.subscribe("/described") as sub:
            with anyio.fail_after(20):
                first = await anext(aiter(sub))
                assert isinstance(first.data, memoryview)
                assert client.rejections == {"type_hash_mismatch": 1}
                with pytest.raises(rmb.SchemaError) as caught:
                    await client.fetch_definition(NESTED)
                assert list(caught.value.failures) == ["/sdk_a_wrong"]
            good = await anyio.to_thread.run_sync(
                lambda: named_talker(sdk, "sdk_b_good", "--describe")
            )
            await wait_for_describers(client, "sdk_b_good")
            with anyio.fail_after(20):
                async for message in sub:
                    if message.decode_error is None:
                        break
        assert message.data.basic_types_value.int32_value == -42
        assert await client.fetch_definition(NESTED) is True
        assert client.rejections == {"type_hash_mismatch": 1}
    assert bad.described() == [NESTED]
    assert good.described() == [NESTED]
