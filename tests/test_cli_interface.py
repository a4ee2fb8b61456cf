"""``rmb interface list|packages|package|show|proto`` with no robot: the
bundled ROS 2 Jazzy interfaces and a local workspace, printed as ``ros2
interface`` prints them (comments, constants, nested types indented)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from _cli_run import cli_env
from _cli_run import rmb as run_rmb


def rmb(*args: str, ament: str | None = None) -> subprocess.CompletedProcess[str]:
    env = cli_env(drop=["AMENT_PREFIX_PATH"])
    if ament is not None:
        env["AMENT_PREFIX_PATH"] = ament
    return run_rmb("interface", *args, env=env)


def ok(*args: str, ament: str | None = None) -> list[str]:
    result = rmb(*args, ament=ament)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    return result.stdout.splitlines()


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A colcon-like install prefix with one package of its own."""
    prefix = tmp_path_factory.mktemp("install")
    share = prefix / "share" / "my_robot_msgs"
    (share / "msg").mkdir(parents=True)
    (share / "srv").mkdir()
    (share / "msg" / "Wheel.msg").write_text(
        "# one wheel\nfloat64 speed # rad/s\nuint8 MODE_IDLE=0\n"
    )
    (share / "msg" / "Status.msg").write_text(
        'std_msgs/Header header\nWheel[4] wheels\nstring label "a#b"\n'
    )
    (share / "srv" / "Reset.srv").write_text("bool hard\n---\nbool ok\n")
    return prefix


def test_show_prints_comments_and_nested_types() -> None:
    lines = ok("show", "geometry_msgs/msg/Twist")
    assert lines[0].startswith("# ")
    at = lines.index("Vector3  linear")
    assert lines[at + 1 : at + 4] == ["\tfloat64 x", "\tfloat64 y", "\tfloat64 z"]
    assert not any(line.startswith("\t#") for line in lines)  # nested comments hidden


def test_show_keeps_defaults_and_constants() -> None:
    assert "float64 w 1" in ok("show", "geometry_msgs/msg/Quaternion")
    error = "\n".join(ok("show", "tf2_msgs/msg/TF2Error"))
    assert "NO_ERROR" in error and "TIMEOUT_ERROR" in error


def test_no_comments_and_all_comments() -> None:
    bare = ok("show", "sensor_msgs/msg/Imu", "--no-comments")
    assert bare and not any("#" in line for line in bare)
    assert "" not in bare
    everything = ok("show", "sensor_msgs/msg/Imu", "--all-comments")
    assert any(line.startswith("\t#") for line in everything)  # the Header's own comments
    default = ok("show", "sensor_msgs/msg/Imu")
    assert len(bare) < len(default) < len(everything)


def test_services_and_actions_show_their_parts() -> None:
    add = ok("show", "example_interfaces/srv/AddTwoInts", "--no-comments")
    assert add == ["int64 a", "int64 b", "---", "int64 sum"]
    fib = ok("show", "example_interfaces/action/Fibonacci", "--no-comments")
    assert fib.count("---") == 2 and fib[0] == "int32 order"


def test_an_unknown_interface_is_one_line_with_the_nearest() -> None:
    result = rmb("show", "geometry_msgs/msg/Twits")
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rmb: unknown interface")
    assert "geometry_msgs/msg/Twist" in lines[0]


def test_list_packages_and_package() -> None:
    lines = ok("list")
    assert lines[0] == "Messages:"
    assert "    std_msgs/msg/String" in lines
    assert "    example_interfaces/srv/AddTwoInts" in lines
    assert lines.index("Services:") < lines.index("Actions:")
    services = ok("list", "-s")
    assert services[0] == "Services:" and "Messages:" not in services
    assert all(line.split("/")[1] == "srv" for line in services[1:])
    packages = ok("packages")
    for package in ("example_interfaces", "tf2_msgs", "statistics_msgs", "lifecycle_msgs"):
        assert package in packages
    assert ok("package", "std_srvs") == [
        "std_srvs/srv/Empty",
        "std_srvs/srv/SetBool",
        "std_srvs/srv/Trigger",
    ]
    assert rmb("package", "nosuch_msgs").returncode == 1


def test_proto_prints_a_yaml_prototype() -> None:
    lines = ok("proto", "geometry_msgs/msg/Twist")
    assert lines[0] == '"linear:'
    assert "  x: 0.0" in lines


def test_every_interface_verb_prints_json_lines() -> None:
    def objects(*args: str) -> list[dict[str, object]]:
        result = rmb(*args, "--json")
        assert result.returncode == 0, result.stderr
        return [json.loads(line) for line in result.stdout.splitlines()]

    listed = objects("list", "-s")
    assert {"name": "std_srvs/srv/SetBool", "kind": "srv"} in listed
    assert {o["kind"] for o in listed} == {"srv"}
    assert {"package": "std_srvs"} in objects("packages")
    assert {"name": "std_srvs/srv/Trigger", "kind": "srv"} in objects("package", "std_srvs")
    (shown,) = objects("show", "std_srvs/srv/SetBool")
    assert shown["type"] == "std_srvs/srv/SetBool" and shown["origin"] == "bundled"
    assert shown["text"] == "\n".join(ok("show", "std_srvs/srv/SetBool"))
    (proto,) = objects("proto", "geometry_msgs/msg/Twist")
    assert proto["prototype"] == {
        "linear": {"x": 0.0, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.0},
    }


def test_a_workspace_by_option_and_by_ament_prefix_path(workspace: Path) -> None:
    by_option = ok("show", "my_robot_msgs/msg/Status", "--interface-path", str(workspace))
    assert by_option[0] == "std_msgs/Header header"
    assert by_option[1].startswith("\t")  # the bundled Header, nested
    wheel = by_option.index("Wheel[4] wheels")
    assert by_option[wheel + 1] == "\tfloat64 speed"
    assert 'string label "a#b"' in by_option
    by_env = ok("show", "my_robot_msgs/msg/Wheel", ament=str(workspace))
    assert by_env == ["# one wheel", "float64 speed # rad/s", "uint8 MODE_IDLE=0"]
    listed = ok("list", "-m", ament=str(workspace))
    assert "    my_robot_msgs/msg/Wheel" in listed
    assert "my_robot_msgs" in ok("packages", "--interface-path", str(workspace))
    assert ok("show", "my_robot_msgs/srv/Reset", ament=str(workspace)) == [
        "bool hard",
        "---",
        "bool ok",
    ]
