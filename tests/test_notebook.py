"""``open_client``: a client opened in one task and used and closed from
others (what a notebook's cells do), on asyncio and trio, against the demo
robot; and ``examples/notebook.ipynb`` executed by a real Jupyter kernel."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import sys
from collections.abc import AsyncIterator, Iterator
from functools import partial
from pathlib import Path
from typing import Any

import anyio
import pytest
import trio

import ros_mobile_bridge as rmb
from ros_mobile_bridge._sync import _background
from ros_mobile_bridge.demo import DemoRobot

pytestmark = pytest.mark.peer

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK = ROOT / "examples" / "notebook.ipynb"
TWIST = "geometry_msgs/msg/Twist"


@pytest.fixture(scope="module")
def robot() -> Iterator[DemoRobot]:
    """conftest's ``robot`` at 50 Hz (its default is 20 Hz)."""
    with DemoRobot(rate_hz=50.0) as bot:
        yield bot


options = partial(rmb.ClientOptions, connect_timeout=5.0, teardown_timeout=2.0, reconnect=None)


def commands_since(robot: DemoRobot, before: int) -> list[tuple[float, float]]:
    return [(c.linear_x, c.angular_z) for c in robot.received_cmd_vel()[before:]]


# -- open_client ---------------------------------------------------------------------


async def test_a_client_opened_in_one_task_is_used_and_closed_from_others(
    robot: DemoRobot,
) -> None:
    before = len(robot.received_cmd_vel())
    opened: list[rmb.ClientHandle] = []

    async def cell_open() -> None:
        opened.append(await rmb.open_client(robot.url, options=options()))

    async with anyio.create_task_group() as tg:  # the opening task ends here
        tg.start_soon(cell_open)
    (handle,) = opened
    assert handle.status == "connected" and not handle.closed
    assert isinstance(handle.client, rmb.Client)
    assert "publish" in dir(handle)
    received: list[rmb.Message] = []

    async def cell_use() -> None:
        async with handle.subscribe("/odom") as sub:
            async for msg in sub:
                received.append(msg)
                if len(received) == 3:
                    break
        await handle.publish("/cmd_vel", TWIST, {"linear": {"x": 0.3}}, priority="control")
        assert (await handle.call_service("/set_led", {"data": True})).success is True

    async def cell_close() -> None:
        await handle.aclose()

    async with anyio.create_task_group() as tg:
        tg.start_soon(cell_use)
    assert [m.topic for m in received] == ["/odom"] * 3
    async with anyio.create_task_group() as tg:
        tg.start_soon(cell_close)
    assert handle.closed and handle.status == "closed"
    assert commands_since(robot, before) == [(0.3, 0.0), (0.0, 0.0)]


async def test_aclose_is_idempotent_and_a_closed_handle_refuses_new_work(
    robot: DemoRobot,
) -> None:
    async with await rmb.open_client(robot.url, options=options()) as handle:
        assert handle.protocol == "foxglove-ws"
    await handle.aclose()
    assert handle.closed and "closed" in repr(handle)
    with pytest.raises(rmb.NotConnected, match="aclose"):
        await handle.publish("/cmd_vel", TWIST, {})
    with pytest.raises(rmb.NotConnected, match="aclose"):
        handle.subscribe("/odom")
    with pytest.raises(AttributeError):
        _ = handle._no_such_private_name


async def test_open_client_raises_what_connect_raises() -> None:
    quick = rmb.ClientOptions(connect_timeout=2.0, reconnect=None)
    with pytest.raises(rmb.ConnectError):
        await rmb.open_client("127.0.0.1:1", options=quick)
    with pytest.raises(ValueError, match="invalid port"):
        await rmb.open_client("127.0.0.1:http")
    with pytest.raises(TypeError, match="no_such_option"):
        await rmb.open_client("127.0.0.1", no_such_option=1)  # type: ignore[call-arg]


async def test_cancelling_open_client_while_connecting_drops_the_connection(
    anyio_backend: str,
) -> None:
    """A server that accepts the TCP connection and never answers the
    handshake: cancelling the caller also ends the background task, so the
    server sees the connection close."""
    closed = anyio.Event()

    async def silent(stream: anyio.abc.SocketStream) -> None:
        async with stream:
            try:
                while await stream.receive():
                    pass
            except (anyio.EndOfStream, anyio.BrokenResourceError):
                pass
        closed.set()

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with listener, anyio.create_task_group() as tg:
        tg.start_soon(listener.serve, silent)
        with anyio.move_on_after(0.5) as scope:
            slow = rmb.ClientOptions(connect_timeout=60.0, reconnect=None)
            await rmb.open_client(f"127.0.0.1:{port}", options=slow)
        assert scope.cancelled_caught
        with anyio.fail_after(5):  # long before the connect timeout
            await closed.wait()
        if anyio_backend == "asyncio":
            names = {t.get_name() for t in asyncio.all_tasks()}
            assert "rmb-open-client" not in names
        tg.cancel_scope.cancel()


@pytest.mark.parametrize("loop", ["asyncio", "trio"])
def test_a_handle_left_open_is_torn_down_when_its_event_loop_ends(
    robot: DemoRobot, loop: str
) -> None:
    before = len(robot.received_cmd_vel())

    async def main() -> None:
        handle = await rmb.open_client(robot.url, options=options())
        await handle.publish("/cmd_vel", TWIST, {"linear": {"x": 0.2}}, priority="control")
        # returns without aclose(): the loop's shutdown cancels the owner task

    # the handle is dropped when main() returns, before the loop cancels the task
    run = (lambda: asyncio.run(main())) if loop == "asyncio" else (lambda: trio.run(main))
    with pytest.warns(ResourceWarning, match="without aclose"):
        run()
    assert commands_since(robot, before) == [(0.2, 0.0), (0.0, 0.0)]


def test_open_client_raises_not_connected_when_its_task_is_cancelled_before_connecting() -> None:
    """asyncio only: shutdown code that cancels every task (as an event
    loop's shutdown does) cancels the background task while the caller still
    waits for the handshake. (A trio system task is cancelled only once the
    main task has ended, when no caller can be waiting.)"""

    async def main() -> None:
        accepted = anyio.Event()

        async def silent(stream: anyio.abc.SocketStream) -> None:
            accepted.set()
            async with stream:
                with contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError):
                    while await stream.receive():
                        pass

        async def cancel_the_owner() -> None:
            await accepted.wait()
            names = [t for t in asyncio.all_tasks() if t.get_name() == "rmb-open-client"]
            assert len(names) == 1
            names[0].cancel()

        listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
        port = listener.extra(anyio.abc.SocketAttribute.local_port)
        async with listener, anyio.create_task_group() as tg:
            tg.start_soon(listener.serve, silent)
            tg.start_soon(cancel_the_owner)
            slow = rmb.ClientOptions(connect_timeout=60.0, reconnect=None)
            with anyio.fail_after(10), pytest.raises(rmb.NotConnected, match="cancelled before"):
                await rmb.open_client(f"127.0.0.1:{port}", options=slow)
            tg.cancel_scope.cancel()

    asyncio.run(main())


async def test_an_error_ending_the_block_on_its_own_is_logged_at_once(
    robot: DemoRobot, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A task inside the connection's block fails after open_client returned
    (as a client's own task would): the block ends while nobody awaits the
    handle. The error is logged then (WARNING), and aclose() raises it once."""
    real_connect = _background.connect

    @contextlib.asynccontextmanager
    async def failing_inside(target: str, **kwargs: Any) -> AsyncIterator[rmb.Client]:
        async def broken() -> None:
            raise RuntimeError("an inner task broke")

        async with real_connect(target, **kwargs) as client, anyio.create_task_group() as tg:
            tg.start_soon(broken)
            yield client

    monkeypatch.setattr(_background, "connect", failing_inside)
    with caplog.at_level(logging.WARNING, logger="ros_mobile_bridge"):
        handle = await rmb.open_client(robot.url, options=options())
        with anyio.fail_after(10):
            await handle._owner.done.wait()
    assert handle.closed
    (record,) = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert "an inner task broke" in record.getMessage()
    assert "aclose" in record.getMessage()
    # the task group's ExceptionGroup (the exceptiongroup backport on 3.10)
    with pytest.raises(Exception) as raised:  # noqa: PT011
        await handle.aclose()
    assert "RuntimeError('an inner task broke')" in repr(raised.value)
    await handle.aclose()  # raised once


# -- the example notebook, in a real kernel -------------------------------------------


def _kernel_spec(tmp: Path, env: dict[str, str]) -> Path:
    """A kernelspec running this interpreter's ipykernel, so the notebook
    runs on the venv under test, with ``env`` (the source path, the URL)."""
    kernel_dir = tmp / "kernels" / "rmb-test"
    kernel_dir.mkdir(parents=True)
    spec = {
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "ros-mobile-bridge tests",
        "language": "python",
        "env": env,
    }
    (kernel_dir / "kernel.json").write_text(json.dumps(spec), encoding="utf-8")
    return kernel_dir.parent


def _text(cell: Any) -> str:
    parts = []
    for output in cell.outputs:
        if output.output_type == "stream" and output.name == "stdout":
            parts.append(output.text)
        elif output.output_type == "error":
            parts.append(f"ERROR {output.ename}: {output.evalue}")
    return "".join(parts)


def test_the_example_notebook_runs_in_a_jupyter_kernel(
    robot: DemoRobot, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("JUPYTER_PLATFORM_DIRS", "1")
    import nbformat
    from nbclient import NotebookClient

    package_dir = Path(rmb.__file__).resolve().parent
    env = {
        "PYTHONPATH": str(package_dir.parent),  # the sources under test, not another install
        "RMB_URL": robot.url,
        "JUPYTER_PLATFORM_DIRS": "1",
        "PYTHONDONTWRITEBYTECODE": "1",
    }
    if "PATH" in os.environ:
        env["PATH"] = os.environ["PATH"]
    # the kernelspec is found on JUPYTER_PATH, ahead of any installed "python3"
    monkeypatch.setenv("JUPYTER_PATH", str(_kernel_spec(tmp_path, env).parent))

    nb = nbformat.read(NOTEBOOK, as_version=4)
    example_cells = len(nb.cells)
    probe = nbformat.v4.new_code_cell(
        "import sys, ros_mobile_bridge\nprint(sys.executable)\nprint(ros_mobile_bridge.__file__)"
    )
    nb.cells.insert(0, probe)
    before = len(robot.received_cmd_vel())
    NotebookClient(nb, timeout=60, kernel_name="rmb-test").execute(cwd=str(tmp_path))

    assert len(nb.cells) == example_cells + 1
    executable, module = _text(nb.cells[0]).splitlines()
    assert Path(executable) == Path(sys.executable)
    assert Path(module).resolve() == Path(rmb.__file__).resolve()
    code = [c for c in nb.cells[1:] if c.cell_type == "code"]
    outputs = [_text(c) for c in code]
    assert not [o for o in outputs if "ERROR" in o], outputs
    opened, odom, moving, led, closed, status = outputs
    assert opened.splitlines()[0] == "foxglove-ws connected"
    assert "/odom" in opened and "/cmd_vel" not in opened.splitlines()[0]
    lines = odom.splitlines()
    assert len(lines) == 3 and all(line.startswith("/odom x=") for line in lines)
    assert moving.startswith("moving: linear.x=0.20 angular.z=0.10")
    assert led.split() == ["True", "led", "on"]  # reply.success, reply.message
    assert closed.strip() == "closed"
    assert status.startswith("mode: ")
    # the robot saw the command, then the teardown's zero Twist, last
    assert commands_since(robot, before) == [(0.2, 0.1), (0.0, 0.0)]
