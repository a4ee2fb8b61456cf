"""``rmb``'s help and start-up, no robot needed: every verb group's
``--help`` lists its verbs; ``--version`` and ``--help`` import no verb
module, no anyio, no client and no codec (checked by what is imported, not by
time); the index in ``_cli/_table.py`` is the verbs' own; a Ctrl-C while the
command line's modules load is exit 130 with no traceback; ``-v`` after a
verb is refused with where it goes."""

from __future__ import annotations

import importlib
import os
import pkgutil
import signal
import subprocess

import pytest

from _cli_run import PYTHON_SIGINT_DEFAULT, ROOT, rmb
from ros_mobile_bridge import _cli
from ros_mobile_bridge._cli import _app, _table

GROUPS = ["action", "bag", "interface", "node", "param", "service", "topic"]


@pytest.mark.parametrize("group", GROUPS)
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_every_group_help_lists_its_verbs_and_exits_0(group: str, flag: str) -> None:
    result = rmb(group, flag)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    listed = [
        line.split()[:2] for line in result.stdout.splitlines() if line.startswith(f"  {group} ")
    ]
    wanted = [list(e.path) for e in _table.ENTRIES if e.path[0] == group and len(e.path) > 1]
    assert listed == wanted and len(wanted) >= 1
    for line in result.stdout.splitlines():
        if line.startswith(f"  {group} "):
            assert len(line.split()) > 2, f"no help on the line: {line!r}"


def test_the_groups_are_the_ones_tested() -> None:
    assert _table.groups() == GROUPS


@pytest.mark.parametrize("group", GROUPS)
def test_a_group_without_a_verb_lists_its_verbs_on_stderr_and_exits_2(group: str) -> None:
    result = rmb(group)
    assert result.returncode == 2
    assert result.stdout == ""
    assert f"  {group} " in result.stderr and "Traceback" not in result.stderr


def test_service_help_lists_the_service_verbs() -> None:
    # "unknown command 'service' (did you mean service or services?)" before
    result = rmb("service", "--help")
    assert result.returncode == 0
    for verb in ("list", "call", "type", "find"):
        assert f"  service {verb} " in result.stdout


def test_an_unknown_verb_of_a_group_names_the_group_s_verbs() -> None:
    result = rmb("topic", "lst")
    assert result.returncode == 2
    assert "'topic' has no verb 'lst'; it has: list, echo" in result.stderr


def test_a_verb_s_own_help_still_shows_its_options() -> None:
    result = rmb("topic", "echo", "--help")
    assert result.returncode == 0
    assert "--csv" in result.stdout and "--flow-style" in result.stdout
    assert "usage: rmb topic echo [options] [URL] TOPIC [TYPE]" in result.stdout


def _modules_after(argv: list[str]) -> tuple[int, set[str], str]:
    code = (
        "import sys\n"
        "from ros_mobile_bridge.cli import main\n"
        f"rc = main({argv!r})\n"
        "print('MODULES ' + ' '.join(sorted(sys.modules)))\n"
        "sys.exit(rc)\n"
    )
    result = subprocess.run(
        [*PYTHON_SIGINT_DEFAULT, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    line = next(x for x in result.stdout.splitlines() if x.startswith("MODULES "))
    return result.returncode, set(line.split()[1:]), result.stdout


@pytest.mark.parametrize(
    "argv",
    [["--version"], ["--help"], ["topic", "--help"], ["param"], ["service", "-h"]],
)
def test_version_and_help_import_no_verb_module_nor_the_client(argv: list[str]) -> None:
    code, modules, stdout = _modules_after(argv)
    assert code in (0, 2)
    assert stdout.strip()  # it printed something
    heavy = {
        "anyio",
        "numpy",
        "yaml",
        "websockets",
        "ros_mobile_bridge._core",
        "ros_mobile_bridge._connect",
        "ros_mobile_bridge.codec",
        "ros_mobile_bridge._signals",
    }
    verb_modules = {f"ros_mobile_bridge._cli.{e.module}" for e in _table.ENTRIES}
    assert not modules & (heavy | verb_modules), sorted(modules & (heavy | verb_modules))


def test_the_index_is_the_verbs_own() -> None:
    indexed = {e.path: e for e in _table.ENTRIES}
    assert len(indexed) == len(_table.ENTRIES), "a verb is indexed twice"
    listed = {}
    # every module of the command line that lists verbs: a verb missing from the
    # index (a new module's, say) would never be found by rmb
    for info in pkgutil.iter_modules(_cli.__path__):
        module = importlib.import_module(f"ros_mobile_bridge._cli.{info.name}")
        for verb in getattr(module, "VERBS", ()):
            listed[verb.path] = (info.name, verb.help, verb.hidden)
    assert {p: (e.module, e.help, e.hidden) for p, e in indexed.items()} == listed
    for entry in _table.ENTRIES:
        assert _app.load_verb(entry).path == entry.path


def test_ctrl_c_while_a_verb_module_is_imported_is_exit_130_without_a_traceback() -> None:
    # the SIGINT lands exactly while parse() imports the verb's module
    code = (
        "import importlib, os, signal, sys\n"
        "from ros_mobile_bridge.cli import main\n"
        "real = importlib.import_module\n"
        "def interrupted(name, package=None):\n"
        "    if name.endswith('._topic'):\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "    return real(name, package)\n"
        "importlib.import_module = interrupted\n"
        "sys.exit(main(['echo', '/odom', '-u', '127.0.0.1:1']))\n"
    )
    result = subprocess.run(
        [*PYTHON_SIGINT_DEFAULT, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.returncode == 130, result.stderr
    assert result.stderr == ""


def test_ctrl_c_while_python_m_loads_the_command_is_exit_130_without_a_traceback() -> None:
    # -X importtime says when our first module is in: the signal then lands
    # in the imports of __main__ or of the verb's module
    proc = subprocess.Popen(
        [*PYTHON_SIGINT_DEFAULT, "-X", "importtime", "-m", "ros_mobile_bridge", "echo", "/odom"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env={**os.environ, "RMB_URL": "127.0.0.1:1"},
    )
    try:
        assert proc.stderr is not None
        for line in proc.stderr:
            if line.rstrip().endswith("ros_mobile_bridge._errors"):
                break
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err


def test_verbose_goes_before_the_verb() -> None:
    after = rmb("echo", "/odom", "-v", "-u", "127.0.0.1:1")
    assert after.returncode == 2
    assert "-v (log more) goes before the command" in after.stderr
    assert "Traceback" not in after.stderr
    log_level = rmb("echo", "--log-level", "debug", "--help")
    assert log_level.returncode == 0  # --log-level stays an option of every verb


@pytest.mark.parametrize(
    ("args", "hint"),
    [
        (("pub", "/cmd_vel", "geometry_msgs/msg/Twist", "linear:", "{x: 1}"), True),
        (("call", "/set_led", "std_srvs/srv/SetBool", "{data:", "false}"), True),
        (("echo", "/odom", "extra", "words"), False),
        (("echo", "/odom", "extra"), False),
        (("call", "/set_led", "std_srvs/srv/SetBool", "{data: false}", "more"), False),
    ],
)
def test_the_yaml_hint_only_for_yaml_the_shell_split(args: tuple[str, ...], hint: bool) -> None:
    result = rmb(*args, "-u", "127.0.0.1:1")
    assert result.returncode == 2
    assert "unexpected argument(s)" in result.stderr
    assert ("quote YAML or JSON as one argument" in result.stderr) is hint, result.stderr


def test_the_cli_page_lists_every_verb_next_to_ros2_and_hu() -> None:
    text = (ROOT / "docs" / "cli.md").read_text()
    table = text.split("## Every verb next to ros2 and hu", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in table.splitlines() if line.startswith("| `")]
    first_columns = " ".join(row.split(" | ")[0] for row in rows)
    for entry in _table.ENTRIES:
        if entry.hidden or entry.path == ("params",):
            continue
        words = " ".join(entry.path)
        group_form = f"`{entry.path[0]} " in first_columns and entry.path[-1] in first_columns
        assert f"`{words}" in first_columns or group_form, f"{words} is not in the table"
    for row in rows:
        assert len(row.split(" | ")) == 4, row  # rmb, ros2, hu, what differs


def test_graph_names_resolve_as_ros2_reads_them() -> None:
    from ros_mobile_bridge._cli._common import graph_name
    from ros_mobile_bridge._cli._format import UsageError

    assert graph_name("odom") == "/odom"
    assert graph_name("/odom") == "/odom"
    assert graph_name("camera/image") == "/camera/image"
    for bad in ("", " ", "~/private", "a b"):
        with pytest.raises(UsageError):
            graph_name(bad)


def test_a_type_matches_in_either_spelling_only() -> None:
    from ros_mobile_bridge._cli._common import check_type, same_type
    from ros_mobile_bridge._cli._format import UsageError

    assert same_type("nav_msgs/Odometry", "nav_msgs/msg/Odometry")
    assert same_type("nav_msgs/msg/Odometry", "nav_msgs/Odometry")
    assert not same_type("nav_msgs/msg/Path", "nav_msgs/msg/Odometry")
    assert not same_type("std_srvs/srv/Trigger", "std_srvs/msg/Trigger")
    check_type("msg", "/odom", "nav_msgs/msg/Odometry", None)  # the robot does not say
    with pytest.raises(UsageError, match="/odom is a nav_msgs/msg/Odometry, not a x/msg/Y"):
        check_type("msg", "/odom", "x/msg/Y", "nav_msgs/msg/Odometry")
    with pytest.raises(UsageError, match="not a ROS type"):
        check_type("msg", "/odom", "odometry", None)


def test_csv_line_flattens_as_ros2_does() -> None:
    from ros_mobile_bridge._cli._format import csv_line, plain

    message = {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "map"}, "ok": True}
    assert csv_line(plain({**message, "ranges": [0.5, 1.5], "empty": [], "n": 3})) == (
        "1,2,map,True,0.5,1.5,,3"
    )
    assert csv_line(plain({"data": [1, 2, 3, 4]}, truncate=2)) == "1,2,..."
