"""The bundled ROS 2 Jazzy interfaces and the local interface paths.

The bundle (``codec/_interfaces.json.gz``, written by ``scripts/gen-interfaces``)
holds every standard interface's text and the official hash of every type it
defines or derives: our ``type_hash`` must agree with each one, every text must
parse, and nothing may be read at import. Local interface files (a colcon
install prefix, a share directory, a package source directory, or what
``$AMENT_PREFIX_PATH`` lists) are found by name, win over the bundle, and are
read within their bounds. The ``ros`` tests hold the bundle to the peer
environment's own type descriptions and the generator to its committed output.
"""

from __future__ import annotations

import gzip
import json
import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from peers.ros_env import PeerEnv
from ros_mobile_bridge._errors import SchemaError
from ros_mobile_bridge.adapters._shared import codec_registry
from ros_mobile_bridge.codec import (
    CodecRegistry,
    InterfacePaths,
    bundled_hash,
    bundled_interface,
    bundled_interface_names,
    find_interface,
    interface_names,
    type_hash,
)
from ros_mobile_bridge.codec._bundled import DATA_FILE, bundled_packages
from ros_mobile_bridge.codec._interface import interface_definitions
from ros_mobile_bridge.interfaces.example_interfaces.action import Fibonacci
from ros_mobile_bridge.interfaces.example_interfaces.srv import AddTwoInts

pytest_plugins = ["peers.ros_fixtures"]

ROOT = Path(__file__).resolve().parent.parent
BUNDLE: dict[str, Any] = json.loads(gzip.decompress(DATA_FILE.read_bytes()))
ADD_TWO_INTS = "example_interfaces/srv/AddTwoInts"
# rmw_zenoh's design document gives this key for the ROS 2 tutorial service
ADD_TWO_INTS_OFFICIAL = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
SUPPLEMENT = ("example_interfaces", "statistics_msgs", "tf2_msgs")


# -- the bundle ------------------------------------------------------------------------------


def test_the_bundle_holds_the_standard_packages_and_the_supplement() -> None:
    packages = bundled_packages()
    for wheel in ("std_msgs", "geometry_msgs", "sensor_msgs", "nav_msgs", "std_srvs"):
        assert packages[wheel][0].isdigit(), wheel
    for name in SUPPLEMENT:
        assert packages[name] == "supplement"
    # test artefacts stay out: the tests use test_msgs as an unknown package
    assert "test_msgs" not in packages
    assert "rosapi_msgs" not in packages
    names = bundled_interface_names()
    assert names == sorted(names)
    assert len(names) == len(BUNDLE["interfaces"]) > 200
    assert not any(n.startswith(("test_msgs/", "rosapi_msgs/")) for n in names)
    assert {ADD_TWO_INTS, "tf2_msgs/action/LookupTransform", "tf2_msgs/srv/FrameGraph"} <= set(
        names
    )


def test_every_bundled_hash_is_our_type_hash() -> None:
    """Every type in the data file, derived ones included (``_Request``,
    ``_Event``, ``_SendGoal``, the action and service types themselves)."""
    registry = CodecRegistry()
    hashes: dict[str, str] = BUNDLE["hashes"]
    derived = [n for n in hashes if n not in BUNDLE["interfaces"]]
    assert len(hashes) > 300
    assert any(n.endswith("_Event") for n in derived)
    assert any(n.endswith("_SendGoal_Request") for n in derived)
    mismatched = {n: h for n, h in hashes.items() if type_hash(registry, n) != h}
    assert mismatched == {}


def test_the_tutorial_service_has_its_official_hash() -> None:
    assert bundled_hash(ADD_TWO_INTS) == ADD_TWO_INTS_OFFICIAL
    assert bundled_hash("example_interfaces/AddTwoInts") == ADD_TWO_INTS_OFFICIAL
    assert type_hash(CodecRegistry(), ADD_TWO_INTS) == ADD_TWO_INTS_OFFICIAL
    assert bundled_hash("test_msgs/msg/Builtins") is None
    assert bundled_hash("not a name") is None


def test_every_bundled_interface_parses_and_builds_its_codecs() -> None:
    registry = CodecRegistry()
    built = 0
    for name, text in BUNDLE["interfaces"].items():
        defs = interface_definitions(name, text)
        assert defs, name
        for type_name in defs:
            if any(f.base == "wstring" for f in defs[type_name].fields):
                continue  # rosbags' CDR codec has no wstring
            registry.template(type_name)
            registry.decoder(type_name, "cdr")
            built += 1
    assert built > 250


def test_a_wstring_type_is_refused_with_a_schema_error() -> None:
    with pytest.raises(SchemaError, match="WString"):
        CodecRegistry().decoder("example_interfaces/msg/WString", "cdr")


def test_lookups_are_tolerant() -> None:
    found = bundled_interface("std_msgs/String")
    assert found is not None
    assert (found.name, found.kind, found.origin) == ("std_msgs/msg/String", "msg", "bundled")
    service = bundled_interface("std_srvs/SetBool")
    assert service is not None
    assert (service.name, service.kind) == ("std_srvs/srv/SetBool", "srv")
    action = bundled_interface("example_interfaces/action/Fibonacci")
    assert action is not None
    assert action.kind == "action"
    assert bundled_interface("test_msgs/msg/Builtins") is None
    assert bundled_interface("") is None


def test_comments_constants_and_defaults_are_kept() -> None:
    quaternion = bundled_interface("geometry_msgs/msg/Quaternion")
    assert quaternion is not None
    assert "# This represents an orientation in free space" in quaternion.text
    assert "float64 w 1" in quaternion.text
    template = CodecRegistry().template("geometry_msgs/msg/Quaternion")
    assert template == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert isinstance(template["w"], float)
    error = bundled_interface("tf2_msgs/msg/TF2Error")
    assert error is not None
    assert error.text.startswith("# Written from the interface's fields")
    assert "uint8 TRANSFORM_ERROR = 6" in error.text
    (definition,) = interface_definitions(error.name, error.text).values()
    assert definition.constants[0] == ("NO_ERROR", "uint8", 0)
    assert len(definition.constants) == 7
    cancel = CodecRegistry().definition("action_msgs/srv/CancelGoal_Response")
    assert [f.name for f in cancel] == ["return_code", "goals_canceling"]


def test_ros2msg_text_is_the_files_text_in_the_concatenated_form() -> None:
    text = CodecRegistry().ros2msg_text("geometry_msgs/msg/PoseStamped")
    blocks = text.split("=" * 80 + "\n")
    assert blocks[0].startswith("# A Pose with reference coordinate frame and timestamp")
    headers = [b.partition("\n")[0] for b in blocks[1:]]
    assert headers == [
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
        "MSG: geometry_msgs/Pose",
        "MSG: geometry_msgs/Point",
        "MSG: geometry_msgs/Quaternion",
    ]
    assert blocks[-1].endswith("float64 w 1\n")
    # a type derived from a service is generated from its fields
    assert CodecRegistry().ros2msg_text(f"{ADD_TWO_INTS}_Request") == "int64 a\nint64 b\n"


def test_ros2msg_text_reads_back_with_mcap_ros2() -> None:
    from mcap_ros2._dynamic import generate_dynamic

    registry = CodecRegistry()
    text = registry.ros2msg_text("geometry_msgs/msg/PoseStamped")
    decoders = generate_dynamic("geometry_msgs/msg/PoseStamped", text)
    payload = registry.encoder("geometry_msgs/msg/PoseStamped", "cdr")(
        {"header": {"frame_id": "map"}, "pose": {"position": {"x": 1.5}}}
    )
    message = decoders["geometry_msgs/PoseStamped"](payload)
    assert message.header.frame_id == "map"
    assert message.pose.position.x == 1.5
    assert message.pose.orientation.w == 1.0


def test_add_two_ints_encodes_and_decodes_cdr() -> None:
    registry = CodecRegistry()
    request = registry.encoder(f"{ADD_TWO_INTS}_Request", "cdr")({"a": 2, "b": -3})
    assert request == bytes([0, 1, 0, 0]) + (2).to_bytes(8, "little") + (-3).to_bytes(
        8, "little", signed=True
    )
    decode_request = registry.decoder(f"{ADD_TWO_INTS}_Request", "cdr")
    assert decode_request(memoryview(request)) == AddTwoInts.Request(a=2, b=-3)
    response = registry.encoder(f"{ADD_TWO_INTS}_Response", "cdr")({"sum": -1})
    decode_response = registry.decoder(f"{ADD_TWO_INTS}_Response", "cdr")
    assert decode_response(memoryview(response)) == AddTwoInts.Response(sum=-1)


def test_an_action_goal_encodes_and_decodes_cdr() -> None:
    registry = CodecRegistry()
    name = "example_interfaces/action/Fibonacci_SendGoal_Request"
    value = {"goal_id": {"uuid": list(range(16))}, "goal": {"order": 7}}
    payload = registry.encoder(name, "cdr")(value)
    decoded = registry.decoder(name, "cdr")(memoryview(payload))
    assert list(decoded.goal_id.uuid) == list(range(16))
    assert decoded.goal == Fibonacci.Goal(order=7)


def test_importing_the_package_reads_no_interface_file() -> None:
    """In a fresh interpreter: the package, its options and connect load
    nothing of the bundle; the first lookup loads it once."""
    code = textwrap.dedent(
        """
        import sys
        opened = []
        def hook(event, args):
            if event == "open" and str(args[0]).endswith("_interfaces.json.gz"):
                opened.append(args[0])
        sys.addaudithook(hook)
        import ros_mobile_bridge as rmb
        rmb.ClientOptions(); rmb.connect
        from ros_mobile_bridge.codec import _bundled
        before = (len(opened), _bundled.loaded())
        _bundled.bundled_interface("std_msgs/msg/String")
        _bundled.bundled_hash("std_msgs/msg/String")
        print(before, (len(opened), _bundled.loaded()))
        """
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    assert out.stdout.split() == ["(0,", "False)", "(1,", "True)"]


# -- local interface files -------------------------------------------------------------------

INNER = "# an inner type\nfloat64 x 1.5\nstring label\n"
OUTER = "Inner inner\nInner[] many\nstd_msgs/Header header\nuint8 MODE_FAST = 2\n"
MOVE = "Outer target\n---\nbool ok\nstring message\n"
DOCK = "string station\n---\nbool docked\n---\nfloat32 progress\n"


def make_package(root: Path, name: str = "my_robot_msgs", **extra: str) -> Path:
    """A package's interface folder under ``root`` (``root/<name>/msg/...``)."""
    package = root / name
    files = {"msg/Inner.msg": INNER, "msg/Outer.msg": OUTER, "srv/Move.srv": MOVE}
    files["action/Dock.action"] = DOCK
    files.update(extra)
    for relative, text in files.items():
        path = package / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return package


@pytest.fixture
def prefix(tmp_path: Path) -> Path:
    """A colcon install prefix holding one custom package."""
    make_package(tmp_path / "install" / "share")
    return tmp_path / "install"


def check_custom_types(registry: CodecRegistry) -> None:
    outer = registry.template("my_robot_msgs/msg/Outer")
    assert outer["inner"] == {"x": 1.5, "label": ""}
    value = {"inner": {"x": 2.0}, "many": [{"label": "a"}], "header": {"frame_id": "f"}}
    payload = registry.encoder("my_robot_msgs/msg/Outer", "cdr")(value)
    decoded = registry.decoder("my_robot_msgs/msg/Outer", "cdr")(memoryview(payload))
    assert decoded.inner.to_dict() == {"x": 2.0, "label": ""}
    assert [m.to_dict() for m in decoded.many] == [{"x": 1.5, "label": "a"}]
    assert decoded.header.frame_id == "f"
    request = registry.encoder("my_robot_msgs/srv/Move_Request", "cdr")({})
    moved = registry.decoder("my_robot_msgs/srv/Move_Request", "cdr")(memoryview(request))
    assert moved.target.inner.to_dict() == {"x": 1.5, "label": ""}  # the defaults
    assert list(moved.target.many) == []
    goal = "my_robot_msgs/action/Dock_SendGoal_Request"
    payload = registry.encoder(goal, "cdr")({"goal": {"station": "s1"}})
    assert registry.decoder(goal, "cdr")(memoryview(payload)).goal.to_dict() == {"station": "s1"}
    assert type_hash(registry, "my_robot_msgs/srv/Move").startswith("RIHS01_")


def test_interface_paths_find_a_custom_package_in_an_install_prefix(prefix: Path) -> None:
    options = rmb.ClientOptions(interface_paths=[prefix], ament_prefix_path=False)
    assert options.interface_paths == (str(prefix),)
    check_custom_types(codec_registry(options))
    found = find_interface("my_robot_msgs/Outer", [prefix], ament_prefix_path=False)
    assert found is not None
    assert found.origin == str(prefix / "share" / "my_robot_msgs" / "msg" / "Outer.msg")
    assert (found.name, found.kind, found.text) == ("my_robot_msgs/msg/Outer", "msg", OUTER)
    names = interface_names([prefix], ament_prefix_path=False)
    assert {"my_robot_msgs/action/Dock", "my_robot_msgs/srv/Move", ADD_TWO_INTS} <= set(names)
    assert names == sorted(names)


def test_without_the_paths_the_custom_types_are_unknown(prefix: Path) -> None:
    registry = codec_registry(rmb.ClientOptions(ament_prefix_path=False))
    assert not registry.has_schema("my_robot_msgs/msg/Outer")
    with pytest.raises(SchemaError, match="unknown type"):
        registry.decoder("my_robot_msgs/msg/Outer", "cdr")
    assert find_interface("my_robot_msgs/msg/Outer", ament_prefix_path=False) is None


def test_ament_prefix_path_is_searched_unless_turned_off(
    prefix: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("AMENT_PREFIX_PATH", os.pathsep.join([str(tmp_path / "none"), str(prefix)]))
    check_custom_types(codec_registry(rmb.ClientOptions()))
    found = find_interface("my_robot_msgs/srv/Move")
    assert found is not None
    assert found.origin.endswith("Move.srv")
    off = codec_registry(rmb.ClientOptions(ament_prefix_path=False))
    assert not off.has_schema("my_robot_msgs/msg/Outer")


def test_a_share_dir_and_a_package_source_dir_are_found(tmp_path: Path) -> None:
    make_package(tmp_path / "share")
    source = make_package(tmp_path / "src", "source_dir_name")
    (source / "package.xml").write_text("<package><name>src_msgs</name></package>")
    paths = InterfacePaths([tmp_path / "share", source])
    assert "my_robot_msgs/msg/Outer" in paths.names()
    assert "src_msgs/srv/Move" in paths.names()
    check_custom_types(CodecRegistry(interfaces=paths))
    src = CodecRegistry(interfaces=paths).template("src_msgs/msg/Outer")
    assert src["inner"]["x"] == 1.5


def test_a_local_definition_wins_over_the_bundled_one(tmp_path: Path) -> None:
    make_package(tmp_path / "share", "std_msgs", **{"msg/String.msg": "string data\nint32 n\n"})
    registry = CodecRegistry(interfaces=InterfacePaths([tmp_path]))
    assert [f.name for f in registry.definition("std_msgs/msg/String")] == ["data", "n"]
    assert registry.ros2msg_text("std_msgs/msg/String") == "string data\nint32 n\n"
    assert [f.name for f in CodecRegistry().definition("std_msgs/msg/String")] == ["data"]
    # an earlier path wins over a later one
    make_package(tmp_path / "b" / "share", "std_msgs", **{"msg/String.msg": "int8 b\n"})
    first = CodecRegistry(interfaces=InterfacePaths([tmp_path / "b", tmp_path]))
    assert [f.name for f in first.definition("std_msgs/msg/String")] == ["b"]
    # a server's schema wins over the local one
    registry.add_schema("std_msgs/msg/String", "ros2msg", "string data\n")
    assert [f.name for f in registry.definition("std_msgs/msg/String")] == ["data"]


def test_the_file_bound_is_enforced_and_counted(prefix: Path) -> None:
    paths = InterfacePaths([prefix], max_files=2)
    assert len(paths.names()) == 2
    assert paths.skipped == 2
    assert paths.max_files == 2


def test_the_byte_bound_is_enforced_and_counted(
    prefix: Path, caplog: pytest.LogCaptureFixture
) -> None:
    paths = InterfacePaths([prefix], max_bytes=len(INNER) + 1)
    with caplog.at_level(logging.WARNING, "ros_mobile_bridge"):
        assert paths.find("my_robot_msgs/msg/Inner") is not None
        assert paths.find("my_robot_msgs/msg/Outer") is None
        assert paths.find("my_robot_msgs/srv/Move") is None
    assert (paths.files_read, paths.bytes_read, paths.skipped) == (1, len(INNER), 2)
    assert sum("max_bytes" in r.getMessage() for r in caplog.records) == 1


def test_unreadable_and_bad_files_are_logged_counted_and_skipped(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    package = make_package(tmp_path / "share")
    (package / "msg" / "Binary.msg").write_bytes(b"\xff\xfe int32 x\n")
    (package / "msg" / "Broken.msg").write_text("this is not a field\n")
    (package / "msg" / "Uses.msg").write_text("Broken b\n")
    paths = InterfacePaths([tmp_path])
    registry = CodecRegistry(interfaces=paths)
    with caplog.at_level(logging.WARNING, "ros_mobile_bridge"):
        assert paths.find("my_robot_msgs/msg/Binary") is None
        assert not registry.has_schema("my_robot_msgs/msg/Broken")
        with pytest.raises(SchemaError, match="Broken"):
            registry.decoder("my_robot_msgs/msg/Uses", "cdr")
        check_custom_types(registry)
    assert paths.unreadable == 2
    assert sum("interface paths" in r.getMessage() for r in caplog.records) >= 2


def test_interface_paths_are_checked_at_construction(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="sequence of paths"):
        rmb.ClientOptions(interface_paths=str(tmp_path))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"str or os\.PathLike"):
        rmb.ClientOptions(interface_paths=[1])  # type: ignore[list-item]
    with pytest.raises(TypeError, match="sequence of paths"):
        rmb.ClientOptions(interface_paths=None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="empty"):
        rmb.ClientOptions(interface_paths=[""])
    with pytest.raises(TypeError, match="ament_prefix_path"):
        rmb.ClientOptions(ament_prefix_path="yes")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        InterfacePaths([b"/opt"])  # type: ignore[list-item]
    assert rmb.ClientOptions(interface_paths=(tmp_path, "x")).interface_paths == (
        str(tmp_path),
        "x",
    )


async def test_a_local_type_crosses_zenoh(
    prefix: Path, zenoh_router: Any, zenoh_domain: int
) -> None:
    """Over Zenoh every type must be known: two clients with the workspace's
    path publish and receive a custom message."""
    options = rmb.ClientOptions(
        domain_id=zenoh_domain, interface_paths=[prefix], ament_prefix_path=False
    )
    outer = "my_robot_msgs/msg/Outer"
    async with (
        rmb.connect(zenoh_router.locator, options=options) as a,
        rmb.connect(zenoh_router.locator, options=options) as b,
        b.subscribe("/outer", schema=outer, buffer=10) as sub,
    ):
        await wait_until(lambda: any(t.name == "/outer" for t in a.topics), 10, what="/outer")
        for i in range(3):
            await a.publish("/outer", outer, {"inner": {"x": float(i)}})
        got = []
        with anyio.fail_after(10):
            async for message in sub:
                got.append(message)
                if len(got) == 3:
                    break
    assert [m.data.inner.to_dict() for m in got] == [{"x": float(i), "label": ""} for i in range(3)]
    assert {m.schema_name for m in got} == {outer}


# -- against the peer environment (ros) -------------------------------------------------------


@pytest.fixture
def adder(ros_peer_env: PeerEnv, zenoh_router: Any, zenoh_domain: int, tmp_path: Path) -> Any:
    """A zenoh-ros2-sdk node serving ``/add_two_ints`` (AddTwoInts), fed the
    Jazzy wheels' files plus the supplement's example_interfaces."""
    pytest.importorskip("zenoh_ros2_sdk")
    from peers.zenoh_sdk_node import SdkNode

    definitions = tmp_path / "definitions"
    definitions.mkdir()
    for package in (ros_peer_env.prefix / "share").iterdir():
        (definitions / package.name).symlink_to(package)
    (definitions / "example_interfaces").symlink_to(
        ROOT / "scripts" / "interfaces" / "example_interfaces"
    )
    node = SdkNode(
        zenoh_router.locator, zenoh_domain, definitions, "add_two_ints", "--name", "/add_two_ints"
    )
    try:
        yield node
    finally:
        node.stop()


async def test_we_call_the_tutorial_service_over_zenoh(
    adder: Any, zenoh_router: Any, zenoh_domain: int
) -> None:
    """The sdk hashes the supplement's AddTwoInts.srv itself: the same
    official hash, and our calls reach it (before the bundle, the type was
    unknown over Zenoh)."""
    assert adder.hashes[ADD_TWO_INTS] == ADD_TWO_INTS_OFFICIAL
    options = rmb.ClientOptions(domain_id=zenoh_domain, ament_prefix_path=False)
    async with rmb.connect(zenoh_router.locator, options=options) as client:
        await wait_until(
            lambda: any(s.name == "/add_two_ints" for s in client.services), 15, what="the service"
        )
        assert {s.name: s.type for s in client.services}["/add_two_ints"] == ADD_TWO_INTS
        sums = [
            await client.call_service("/add_two_ints", {"a": a, "b": b}, timeout=5)
            for a, b in ((2, 3), (-7, 4), (2**40, 1))
        ]
    assert sums == [AddTwoInts.Response(sum=s) for s in (5, -3, 2**40 + 1)]


def test_the_bundled_hashes_are_the_peer_envs_official_ones(ros_peer_env: PeerEnv) -> None:
    """Every type_hashes entry of every share/*.json of the wheel packages."""
    share = Path(ros_peer_env.prefix) / "share"
    official: dict[str, str] = {}
    for package, version in bundled_packages().items():
        if version == "supplement":
            assert not (share / package).exists()
            continue
        for path in sorted((share / package).glob("*/*.json")):
            for entry in json.loads(path.read_text())["type_hashes"]:
                official[entry["type_name"]] = entry["hash_string"]
    assert len(official) > 250
    ours = {name: BUNDLE["hashes"].get(name) for name in official}
    assert ours == official


def test_the_generator_is_deterministic_and_the_committed_file_is_current(
    ros_peer_env: PeerEnv, tmp_path: Path
) -> None:
    out = tmp_path / "interfaces.json.gz"
    for _ in range(2):
        subprocess.run(
            [
                sys.executable,
                str(ROOT / "scripts" / "gen-interfaces"),
                "--peer-env",
                str(ros_peer_env.prefix),
                "--out",
                str(out),
            ],
            check=True,
            capture_output=True,
        )
        assert out.read_bytes() == DATA_FILE.read_bytes()
