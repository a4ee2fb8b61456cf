"""Every code block of README.md and docs/ runs as written against the demo robot, or
says (in its text and with a marker) what it needs; the conventions are in
tests/_doc_blocks.py and CONTRIBUTING.md. Also: the README's extras table is
pyproject's, and every example is run by a test.

Plain (sync) tests: a block that awaits runs once on asyncio and once on trio."""

from __future__ import annotations

import ast
import inspect
import os
import re
import select
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _doc_blocks import (
    EXEMPT,
    PAGES,
    PYTHON,
    RECORDING,
    ROOT,
    SHELL,
    Block,
    all_blocks,
    commands,
    is_fragment,
    localise,
    problem,
    python_source,
    read_page,
    runs_main_itself,
    uses_unbound,
)
from peers.rosbridge import RosBridge, RosGraph
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.demo import DemoRobot

if sys.version_info >= (3, 11):
    import tomllib
else:  # pytest's own dependency on 3.10
    import tomli as tomllib

pytest_plugins = ["peers.ros_fixtures"]

BLOCKS, MARKER_PROBLEMS = all_blocks()
BLOCK_S = 60.0
"""Deadline of a block that ends by itself."""
ODOMETRY = "nav_msgs/msg/Odometry"
UNTIL_S = 5.0
"""How long a ``block: until-stopped`` block runs before the harness stops it."""


def _runs_on_demo(block: Block) -> bool:
    return block.needs in (None, "recording") and block.include is None and block.lang not in EXEMPT


def _awaits(block: Block) -> bool:
    tree = ast.parse(python_source(block, BLOCKS))
    top_level = compile(
        python_source(block, BLOCKS), block.id, "exec", flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT
    )
    return bool(top_level.co_flags & inspect.CO_COROUTINE) or any(
        isinstance(node, ast.AsyncFunctionDef) for node in ast.walk(tree)
    )


def _python_cases(needs: str | None = None) -> list[Any]:
    """The python blocks that run against the demo robot (or, with ``needs``, against that
    peer), with the backends each runs on."""
    cases = []
    for block in BLOCKS:
        runs = _runs_on_demo(block) if needs is None else block.needs == needs
        if block.lang in PYTHON and block.include is None and runs:
            backends = ("asyncio", "trio") if _awaits(block) else ("sync",)
            cases += [pytest.param(block, b, id=f"{block.id}-{b}") for b in backends]
    return cases


# -- the inventory --------------------------------------------------------------------------


def test_every_block_runs_or_says_what_it_needs() -> None:
    assert MARKER_PROBLEMS == []
    assert [p for p in map(problem, BLOCKS) if p] == []


def test_the_inventory_reads_every_page() -> None:
    pages = {block.page for block in BLOCKS}
    assert {"README.md", "docs/cli.md", "docs/errors.md", "docs/recording.md"} <= pages
    assert len(PAGES) >= 20
    assert sum(b.lang in PYTHON and _runs_on_demo(b) for b in BLOCKS) >= 10
    assert sum(b.lang in SHELL and _runs_on_demo(b) for b in BLOCKS) >= 10


def _page(tmp_path: Path, text: str) -> tuple[list[Block], list[str]]:
    page = tmp_path / "page.md"
    page.write_text(text, encoding="utf-8")
    return read_page(page)


def test_a_block_neither_runnable_nor_marked_fails(tmp_path: Path) -> None:
    blocks, markers = _page(
        tmp_path,
        "Install it:\n\n```bash\npip install foo\n```\n\n"
        "From a clone of the repository:\n\n<!-- needs: checkout -->\n```bash\npip install .\n```\n"
        "\n```\nno language\n```\n\n<!-- needs: a-robot -->\n```python\nx = 1\n```\n\n"
        "Nothing said here.\n\n<!-- needs: rosbridge -->\n```python\nx = 2\n```\n\n"
        "```text\nexempt output\n```\n\n```console\n$ rmb topics\n/odom\n```\n",
    )
    found = [problem(block) for block in blocks]
    assert found[0] is not None and "pip install foo" in found[0]
    assert found[1] is None  # marked, and the text before it says so
    assert found[2] is not None and "without a language" in found[2]
    assert found[3] is None and len(markers) == 1 and "a-robot" in markers[0]
    assert found[4] is not None and "does not say so" in found[4]
    assert found[5:] == [None, None]
    assert [c.argv for c in commands(blocks[6])] == [("rmb", "topics")]


def test_a_marker_must_precede_a_block(tmp_path: Path) -> None:
    _, markers = _page(tmp_path, "<!-- needs: robot -->\nSome prose.\n\n```text\nx\n```\n")
    assert len(markers) == 1 and "not followed by a block" in markers[0]


def test_the_demo_address_is_replaced_and_others_are_not() -> None:
    url = "ws://127.0.0.1:4242"
    assert localise('connect("ws://robot.local:8765")', url) == f'connect("{url}")'
    assert localise('connect("robot.local")', url) == 'connect("127.0.0.1:4242")'
    assert localise("rmb echo 127.0.0.1:8765 /odom", url) == "rmb echo 127.0.0.1:4242 /odom"
    assert localise('connect("ws://robot.local:9090", protocol="rosbridge")', url) == (
        f'connect("{url}", protocol="rosbridge")'
    )
    router = "tcp/127.0.0.1:7000"
    assert localise('connect("tcp/robot.local:7447")', router) == f'connect("{router}")'
    assert localise("ws://robot:9090", url) == "ws://robot:9090"
    assert localise("wss://robot.example.com", url) == "wss://robot.example.com"


# -- python blocks ----------------------------------------------------------------------------


def test_every_python_block_compiles() -> None:
    """Marked blocks too (those against rosbridge or Zenoh are also run by the ros tests)."""
    for block in BLOCKS:
        if block.lang in PYTHON and block.include is None:
            source = python_source(block, BLOCKS)
            compile(source, block.id, "exec", flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT)


@pytest.mark.parametrize(("block", "backend"), _python_cases())
def test_python_block_runs_against_the_demo_robot(
    robot: DemoRobot, block: Block, backend: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)  # what a block writes (a recording) stays out of the checkout
    run_python(block, robot.url, backend, monkeypatch)


def run_python(block: Block, url: str, backend: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Run the block as tests/_doc_blocks.py says (``backend`` "sync" for a block that never
    awaits)."""
    source = localise(python_source(block, BLOCKS), url)
    tree = ast.parse(source)
    code = compile(source, block.id, "exec", flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT)
    namespace: dict[str, Any] = {"__name__": "__doc_block__"}
    if is_fragment(tree):
        namespace.update(anyio=anyio, rmb=rmb, url=url)
    wants_robot = uses_unbound(tree, "robot")
    until_stopped = "until-stopped" in block.flags
    real_run = anyio.run
    loop = "asyncio" if backend == "sync" else backend

    def bounded_run(func: Callable[..., Any], *args: Any, **_: Any) -> Any:
        """The block's own ``anyio.run(main)``, on this test's backend, with a deadline."""

        async def bounded() -> Any:
            with anyio.fail_after(BLOCK_S):
                return await func(*args)

        return real_run(bounded, backend=loop)

    monkeypatch.setattr(anyio, "run", bounded_run)

    if code.co_flags & inspect.CO_COROUTINE:

        async def body() -> None:
            scope = anyio.move_on_after(UNTIL_S) if until_stopped else anyio.fail_after(BLOCK_S)
            with scope:
                if wants_robot:
                    async with rmb.connect(url) as client:
                        namespace["robot"] = client
                        await eval(code, namespace)
                else:
                    await eval(code, namespace)
            assert not until_stopped or scope.cancelled_caught, "it stopped by itself"

        real_run(body, backend=loop)
        return
    assert not until_stopped, "only a block that awaits can be stopped by the harness"
    if wants_robot:
        with rmb.connect_sync(url, backend=loop) as client:  # type: ignore[arg-type]
            namespace["robot"] = client
            exec(code, namespace)
    else:
        exec(code, namespace)
    main = namespace.get("main")
    if inspect.iscoroutinefunction(main) and not runs_main_itself(tree):
        bounded_run(main)


# -- shell blocks -----------------------------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _argv(argv: tuple[str, ...], url: str) -> list[str]:
    """The command as this test runs it: ``rmb`` through this interpreter, an example by its
    path, the robot's address replaced, ``--port N`` on a free port."""
    args = [localise(arg, url) for arg in argv]
    for i, arg in enumerate(args[:-1]):
        if arg == "--port":
            args[i + 1] = str(_free_port())
    if args[0] == "rmb":
        return [sys.executable, "-m", "ros_mobile_bridge", *args[1:]]
    assert args[0] == "python", args
    return [sys.executable, str(ROOT / args[1]), *args[2:]]


def _started(proc: subprocess.Popen[str], what: str) -> None:
    """Wait for a background command's first line of output: it is up (a Ctrl-C before
    then would hit the interpreter's start-up, not the command)."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], BLOCK_S)
    assert ready, f"{what} printed nothing in {BLOCK_S} s"
    assert proc.stdout.readline(), f"{what} ended at once: {proc.communicate()}"


def _cpu_ticks(pid: int) -> int | None:
    """The process's CPU time so far in clock ticks (Linux), else None."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return int(fields[11]) + int(fields[12])  # utime + stime


def _settled(proc: subprocess.Popen[str]) -> None:
    """Wait until the program has started and waits (its CPU time unchanged
    over 0.3 s: the interpreter's start-up and its imports are over), at
    most BLOCK_S: a Ctrl-C before then would hit the start-up, not the
    program, on a machine busy enough to make the start-up slow."""
    deadline = time.monotonic() + BLOCK_S
    last = _cpu_ticks(proc.pid)
    while last is not None and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.3)
        now = _cpu_ticks(proc.pid)
        if now == last:
            return
        last = now


def _stop(proc: subprocess.Popen[str], what: str) -> None:
    """SIGINT (Ctrl-C); it must end cleanly (0, or rmb's 130). A program that
    already ended cleanly is fine: a stdio server ends at the end of its
    input, which is closed here."""
    if proc.poll() is not None:
        out, err = proc.communicate()
        assert proc.returncode in (0, 130), f"{what} ended early ({proc.returncode}): {err}"
        return
    proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise AssertionError(f"{what} did not stop on Ctrl-C") from None
    assert proc.returncode in (0, 130), f"{what}: exit {proc.returncode}\n{out}\n{err}"


@pytest.mark.parametrize(
    "block",
    [
        pytest.param(b, id=b.id)
        for b in BLOCKS
        if b.lang in SHELL and _runs_on_demo(b) and problem(b) is None
    ],
)
def test_shell_block_runs_against_the_demo_robot(
    robot: DemoRobot, block: Block, tmp_path: Path
) -> None:
    run_shell(block, robot.url, tmp_path)


def run_shell(block: Block, url: str, tmp_path: Path) -> None:
    """Run the block's commands in order, in ``tmp_path``, with ``$RMB_URL`` set to ``url``."""
    env = dict(os.environ, RMB_URL=url)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), *filter(None, [env.get("PYTHONPATH")])])
    until_stopped = "until-stopped" in block.flags
    background: list[tuple[subprocess.Popen[str], str]] = []
    if block.needs == "recording":
        made = subprocess.run(
            _argv(("rmb", "record", "/odom", "/battery", "-o", RECORDING, "--duration", "2"), url),
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=BLOCK_S,
            check=False,
        )
        assert made.returncode == 0, made.stderr
    try:
        for command in commands(block):
            if command.argv[0] == "export":
                continue  # the harness's $RMB_URL stands for the docs' own
            what = " ".join(command.argv)
            proc = subprocess.Popen(
                _argv(command.argv, url),
                cwd=tmp_path,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            if command.background:
                background.append((proc, what))
                _started(proc, what)
                continue
            try:
                out, err = proc.communicate(timeout=UNTIL_S if until_stopped else BLOCK_S)
            except subprocess.TimeoutExpired:
                if not until_stopped:
                    proc.kill()
                    proc.communicate()
                    raise AssertionError(
                        f"{what} did not end (mark `block: until-stopped`)"
                    ) from None
                _settled(proc)
                _stop(proc, what)
                continue
            assert proc.returncode == 0, f"{what}: exit {proc.returncode}\n{out}\n{err}"
        for proc, what in background:
            _stop(proc, what)
    finally:
        for proc, _ in background:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()


# -- blocks that need rosbridge or Zenoh, against the peers of tests/peers/ (marked ros) -------


@pytest.fixture(scope="module")
def camera(ros_graph: RosGraph) -> Iterator[str]:
    """An image publisher on the graph, for the blocks that read ``/camera/image_raw``."""
    topic = "/camera/image_raw"
    ros_graph.command({"cmd": "image", "topic": topic, "hz": 10, "width": 64, "height": 48})
    yield topic
    ros_graph.command({"cmd": "stop", "topic": topic})


@pytest.mark.parametrize(("block", "backend"), _python_cases("rosbridge"))
def test_python_block_runs_against_rosbridge(
    rosbridge: RosBridge,
    camera: str,
    block: Block,
    backend: str,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
) -> None:
    monkeypatch.chdir(tmp_path)
    run_python(block, rosbridge.url, backend, monkeypatch)


@pytest.mark.parametrize(
    "block",
    [pytest.param(b, id=b.id) for b in BLOCKS if b.lang in SHELL and b.needs == "rosbridge"],
)
def test_shell_block_runs_against_rosbridge(
    rosbridge: RosBridge, block: Block, tmp_path: Path
) -> None:
    run_shell(block, rosbridge.url, tmp_path)


@pytest.mark.parametrize(("block", "backend"), _python_cases("zenoh"))
def test_python_block_runs_against_zenoh(
    sdk: Callable[..., Any],
    ros_share: Path,
    zenoh_router: Any,
    block: Block,
    backend: str,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
) -> None:
    """The docs' Zenoh robot: odometry and the tutorial's ``/add_two_ints`` on domain 0
    (zenoh-ros2-sdk nodes on the test's own router; example_interfaces from the
    supplement, as tests/test_interfaces.py does)."""
    odom = '{"header": {"frame_id": "odom"}, "pose": {"pose": {"position": {"x": 1.0}}}}'
    sdk(
        "talker", "--topic", "/odom", "--type", ODOMETRY, "--values", odom, "--rate", "20", domain=0
    )
    definitions = tmp_path / "definitions"
    definitions.mkdir()
    for package in ros_share.iterdir():
        (definitions / package.name).symlink_to(package)
    (definitions / "example_interfaces").symlink_to(
        ROOT / "scripts" / "interfaces" / "example_interfaces"
    )
    adder = SdkNode(zenoh_router.locator, 0, definitions, "add_two_ints", "--name", "/add_two_ints")
    try:
        monkeypatch.chdir(tmp_path)
        run_python(block, zenoh_router.locator, backend, monkeypatch)
    finally:
        adder.stop()


@pytest.mark.parametrize(
    "block",
    [pytest.param(b, id=b.id) for b in BLOCKS if b.lang in SHELL and b.needs == "zenoh"],
)
def test_shell_block_runs_against_zenoh(
    sdk: Callable[..., Any], zenoh_router: Any, block: Block, tmp_path: Path
) -> None:
    """The docs' Zenoh talker: ``/chatter`` Strings on domain 0 (a zenoh-ros2-sdk node)."""
    sdk(
        "talker",
        "--topic",
        "/chatter",
        "--type",
        "std_msgs/msg/String",
        "--values",
        '{"data": "hello"}',
        "--rate",
        "20",
        domain=0,
    )
    run_shell(block, zenoh_router.locator, tmp_path)


def test_every_transport_block_is_run_by_a_peer_test() -> None:
    """A block marked for another transport is python or shell, and one of the tests above
    runs it (python or shell, against rosbridge or Zenoh)."""
    for block in BLOCKS:
        if block.needs in ("rosbridge", "zenoh"):
            assert block.lang in PYTHON or block.lang in SHELL, block.id


# -- the extras table -------------------------------------------------------------------------

_ROW = re.compile(r"^\| `\[(?P<name>[a-z-]+)\]` \| (?P<installs>[^|]*) \| (?P<needs>[^|]+) \|$")


def _requirement_name(requirement: str) -> str:
    return re.split(r"[\s<>=!~;\[]", requirement, maxsplit=1)[0].lower()


def _extras_table(text: str) -> dict[str, tuple[set[str], set[str], str]]:
    """``| `[name]` | `pkg`, ..., and `[extra,...]` | what needs it |`` rows:
    name -> (packages, extras it includes, what needs it)."""
    rows: dict[str, tuple[set[str], set[str], str]] = {}
    for line in text.splitlines():
        m = _ROW.match(line)
        if m:
            packages = {p.lower() for p in re.findall(r"`([A-Za-z0-9_.\-]+)`", m["installs"])}
            included = {
                extra for group in re.findall(r"`\[([^\]]+)\]`", m["installs"])
                for extra in group.split(",")
            }  # fmt: skip
            rows[m["name"]] = (packages, included, m["needs"].strip())
    return rows


def _pyproject_extras() -> dict[str, tuple[set[str], set[str]]]:
    """pyproject's extras: name -> (packages, extras of this project it includes)."""
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"][
        "optional-dependencies"
    ]
    found: dict[str, tuple[set[str], set[str]]] = {}
    for name, requirements in extras.items():
        packages = {_requirement_name(r) for r in requirements} - {"ros-mobile-bridge"}
        included = {
            extra
            for r in requirements
            if _requirement_name(r) == "ros-mobile-bridge"
            for extra in re.findall(r"\[([^\]]+)\]", r)[0].split(",")
        }
        found[name] = (packages, included)
    return found


@pytest.mark.parametrize("page", ["README.md", "docs/index.md"])
def test_the_extras_table_is_pyprojects(page: str) -> None:
    """Every extra, what it installs (its own packages and the extras it pulls in) and
    what needs it: the table and pyproject.toml say the same."""
    table = _extras_table((ROOT / page).read_text(encoding="utf-8"))
    extras = _pyproject_extras()
    assert list(table) == list(extras)  # the same extras, in pyproject's order
    for name, (packages, included) in extras.items():
        shown, shown_included, needs = table[name]
        assert (shown, shown_included) == (packages, included), name
        assert needs, name


def test_the_extras_table_reader_sees_a_wrong_row() -> None:
    table = _extras_table(
        "| `[trio]` | `trio`, `anyio` | trio |\n| `[dev]` | `ruff`, and `[test,docs]` | dev |\n"
    )
    assert table == {
        "trio": ({"trio", "anyio"}, set(), "trio"),
        "dev": ({"ruff"}, {"test", "docs"}, "dev"),
    }
    assert table["trio"][0] != _pyproject_extras()["trio"][0]


# -- the examples -----------------------------------------------------------------------------


def test_every_example_is_run_by_a_test() -> None:
    tests = "".join(
        p.read_text(encoding="utf-8")
        for p in (ROOT / "tests").glob("*.py")  # the tests and their helpers (_recording.py)
        if p.name not in (Path(__file__).name, "_doc_blocks.py")
    )
    for example in sorted((ROOT / "examples").iterdir()):
        if example.suffix in (".py", ".ipynb"):
            assert f'"{example.name}"' in tests, f"no test runs examples/{example.name}"
