"""``connect_sync``: the blocking client, from plain (not async) test functions,
against the demo robot (the official Foxglove SDK server), with the worker
thread's event loop on asyncio and on trio."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import signal
import socket
import subprocess
import sys
import textwrap
import threading
from collections.abc import Iterator
from functools import partial
from pathlib import Path

import anyio
import pytest
import sniffio
import trio

import ros_mobile_bridge as rmb
from _util import wait_until
from ros_mobile_bridge._sync import _client as _sync
from ros_mobile_bridge.demo import DemoRobot
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool

pytestmark = pytest.mark.peer

ROOT = Path(__file__).resolve().parent.parent
TWIST = "geometry_msgs/msg/Twist"


@pytest.fixture(scope="module")
def robot() -> Iterator[DemoRobot]:
    """conftest's ``robot`` at 50 Hz (its default is 20 Hz)."""
    with DemoRobot(rate_hz=50.0) as bot:
        yield bot


@pytest.fixture(params=["asyncio", "trio", "uvloop"])
def backend(request: pytest.FixtureRequest) -> str:
    """The worker thread's loop (``uvloop``: asyncio on uvloop)."""
    return str(request.param)


options = partial(rmb.ClientOptions, connect_timeout=5.0, teardown_timeout=2.0, reconnect=None)


def sync_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("rmb-sync-")]


def commands_since(robot: DemoRobot, before: int) -> list[tuple[float, float]]:
    return [(c.linear_x, c.angular_z) for c in robot.received_cmd_vel()[before:]]


def test_messages_arrive_publish_reaches_the_robot_and_close_sends_zero_twist_last(
    robot: DemoRobot, backend: str
) -> None:
    before = len(robot.received_cmd_vel())
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
        assert client.status == "connected"
        assert client.protocol == "foxglove-ws"
        assert client.worker_thread.name == f"rmb-sync-{backend}"
        assert client.wait_for_topic("/odom", timeout=5).schema_name == "nav_msgs/msg/Odometry"
        with client.subscribe("/odom", timeout=5) as sub:
            first = sub.get()
            rest = [next(sub), next(sub)]
            assert sub.state == "active"
            assert sub.stats.delivered == 3
            batch = sub.get_batch(max_size=4)
            assert 1 <= len(batch) <= 4 and {m.topic for m in batch} == {"/odom"}
            assert sub.stats.delivered == 3 + len(batch)
            with pytest.raises(ValueError, match="max_size"):
                sub.get_batch(max_size=0)
        received = [first, *rest]
        assert [m.topic for m in received] == ["/odom"] * 3
        assert [m.schema_name for m in received] == ["nav_msgs/msg/Odometry"] * 3
        stamps = [m.receive_time_ns for m in received]
        assert stamps == sorted(stamps) and len(set(stamps)) == 3
        assert isinstance(received[0].data, Odometry)

        client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.3}}, priority="control")
        client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.2}, "angular": {"z": 0.1}})
        assert client.call_service("/set_led", {"data": True}) == SetBool.Response(
            success=True, message="led on"
        )
        assert client.set_parameters({"max_speed": 0.75}) == {"max_speed": 0.75}
        assert client.get_parameters(["max_speed"]) == {"max_speed": 0.75}
        assert client.list_parameters()["robot_name"] == "rmb-demo-robot"
        assert client.schema_template(TWIST)["linear"] == {"x": 0.0, "y": 0.0, "z": 0.0}
        assert [f.name for f in client.schema_definition(TWIST)] == ["linear", "angular"]
        assert client.run(lambda c: c.call_service("/set_led", {"data": False})) == (
            SetBool.Response(success=True, message="led off")
        )
        thread = client.worker_thread
    assert client.closed and client.status == "closed"
    assert commands_since(robot, before) == [(0.3, 0.0), (0.2, 0.1), (0.0, 0.0)]
    assert not thread.is_alive()
    assert thread not in threading.enumerate()
    assert sync_threads() == []


def test_close_without_with_is_idempotent_and_later_calls_raise_not_connected(
    robot: DemoRobot, backend: str
) -> None:
    before = len(robot.received_cmd_vel())
    client = rmb.connect_sync(robot.url, backend=backend, options=options())
    client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.1}}, priority="control")
    client.close()
    client.close()
    assert commands_since(robot, before) == [(0.1, 0.0), (0.0, 0.0)]
    assert not client.worker_thread.is_alive()
    with pytest.raises(rmb.NotConnected, match="closed"):
        client.publish("/cmd_vel", TWIST, {})
    with pytest.raises(rmb.NotConnected, match="closed"):
        client.subscribe("/odom")


def test_an_exception_inside_with_still_sends_the_zero_twist(
    robot: DemoRobot, backend: str
) -> None:
    before = len(robot.received_cmd_vel())
    with (
        pytest.raises(ZeroDivisionError),
        rmb.connect_sync(robot.url, backend=backend, options=options()) as client,
    ):
        client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.4}}, priority="control")
        with client.subscribe("/odom", timeout=5) as sub:
            sub.get()
            _ = 1 / 0
    assert commands_since(robot, before) == [(0.4, 0.0), (0.0, 0.0)]
    assert client.status == "closed"
    assert sync_threads() == []


def test_keyboard_interrupt_in_a_blocking_receive_cancels_it_and_tears_down(
    robot: DemoRobot, backend: str
) -> None:
    """Ctrl-C while the main thread waits for a message (no timeout) on a
    topic that never comes: the wait ends with KeyboardInterrupt, leaving the
    ``with`` blocks unsubscribes and sends the zero Twist."""
    assert threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    main = threading.main_thread().ident
    assert main is not None
    before = len(robot.received_cmd_vel())
    timer = threading.Timer(0.5, signal.pthread_kill, (main, signal.SIGINT))
    try:
        with (
            pytest.raises(KeyboardInterrupt),
            rmb.connect_sync(robot.url, backend=backend, options=options()) as client,
        ):
            client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.5}}, priority="control")
            with client.subscribe("/never_published") as sub:
                timer.start()
                sub.get()  # waits until interrupted
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert commands_since(robot, before) == [(0.5, 0.0), (0.0, 0.0)]
    assert client.status == "closed"
    assert not client.worker_thread.is_alive()


async def _count_tasks(_client: rmb.Client) -> int:
    """The tasks alive in the worker's event loop (this one included)."""
    return _tasks_now()


def _tasks_now() -> int:
    """The tasks alive in the running event loop."""
    if sniffio.current_async_library() == "asyncio":
        return len(asyncio.all_tasks())
    count, stack = 0, [trio.lowlevel.current_root_task()]
    while stack:
        task = stack.pop()
        count += 1
        for nursery in task.child_nurseries:
            stack.extend(nursery.child_tasks)
    return count


def test_keyboard_interrupt_cancels_the_interrupted_call_in_the_loop(
    robot: DemoRobot, backend: str
) -> None:
    """The wait that Ctrl-C interrupted does not linger in the worker: its
    task ends, and the client goes on working."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    main = threading.main_thread().ident
    assert main is not None
    timer = threading.Timer(0.5, signal.pthread_kill, (main, signal.SIGINT))
    try:
        with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
            with client.subscribe("/never_published") as sub:
                baseline = client.run(_count_tasks)
                timer.start()
                with pytest.raises(KeyboardInterrupt):
                    sub.get()

                async def settled(_client: rmb.Client) -> int:
                    await wait_until(
                        lambda: _tasks_now() <= baseline,
                        5,
                        what=lambda: f"the tasks to drop to {baseline} (now {_tasks_now()})",
                    )
                    return _tasks_now()

                assert client.run(settled) == baseline
            assert client.call_service("/set_led", {"data": True}).success is True
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)


def test_keyboard_interrupt_while_connecting_abandons_the_connection(backend: str) -> None:
    """Ctrl-C while connect_sync waits for a server that never answers the
    handshake: KeyboardInterrupt, the connection attempt is cancelled (the
    server sees it close long before the connect timeout), no thread left."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    closed = threading.Event()

    def silent() -> None:
        conn, _ = server.accept()
        with conn:
            conn.settimeout(30)
            with contextlib.suppress(OSError):
                while conn.recv(4096):
                    pass
        closed.set()

    acceptor = threading.Thread(target=silent, daemon=True)
    acceptor.start()
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    main = threading.main_thread().ident
    assert main is not None
    timer = threading.Timer(0.5, signal.pthread_kill, (main, signal.SIGINT))
    slow = rmb.ClientOptions(connect_timeout=60.0, reconnect=None)
    try:
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            rmb.connect_sync(f"127.0.0.1:{port}", backend=backend, options=slow)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
        server.close()
    assert closed.wait(10)
    assert sync_threads() == []


def test_a_receive_timeout_raises_timeout_error_and_loses_nothing(
    robot: DemoRobot, backend: str
) -> None:
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
        with client.subscribe("/never_published", timeout=0.2) as quiet:
            with pytest.raises(TimeoutError, match="receive on /never_published"):
                quiet.get()
            with pytest.raises(TimeoutError):
                next(iter(quiet))
            with pytest.raises(TimeoutError):
                quiet.get(timeout=0.1)  # a timeout per call wins
            assert quiet.state == "pending"
        with client.subscribe("/status") as status:
            got = status.get(timeout=5)  # 2 Hz: one comes
            assert got.topic == "/status" and "mode" in got.data
            with pytest.raises(TimeoutError):
                client.wait_for_topic("/never_published", timeout=0.2)
        # after a timed-out call the client still works
        assert client.call_service("/set_led", {"data": True}).success is True


def test_timed_out_receives_lose_no_message(robot: DemoRobot, backend: str) -> None:
    """Receives that time out while /status (2 Hz) is quiet take nothing
    from the queue: every message decoded is one that a get() returned."""
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
        with client.subscribe("/status") as sub:
            got: list[rmb.Message] = []
            timeouts = 0
            for _ in range(400):
                try:
                    got.append(sub.get(timeout=0.02))
                except TimeoutError:
                    timeouts += 1
                if len(got) == 3:
                    break
            assert len(got) == 3 and timeouts > 0
            assert sub.stats.delivered == 3


def test_several_threads_share_one_client(robot: DemoRobot, backend: str) -> None:
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
        replies: list[object] = []
        errors: list[BaseException] = []

        def worker(flag: bool) -> None:
            try:
                for _ in range(5):
                    replies.append(client.call_service("/set_led", {"data": flag}, timeout=5))
            except BaseException as exc:
                errors.append(exc)

        threads = [threading.Thread(target=worker, args=(i % 2 == 0,)) for i in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        assert errors == []
        assert len(replies) == 20
        assert all(isinstance(r, SetBool.Response) and r.success is True for r in replies)


def test_a_blocking_call_from_the_worker_loop_raises_instead_of_deadlocking(
    robot: DemoRobot, backend: str
) -> None:
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:

        async def reenter(_c: rmb.Client) -> object:
            return client.call_service("/set_led", {"data": True})

        with pytest.raises(RuntimeError, match="own event loop"):
            client.run(reenter, timeout=5)
        assert client.connected


def test_iteration_ends_when_the_subscription_is_closed(robot: DemoRobot, backend: str) -> None:
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
        sub = client.subscribe("/odom", timeout=5)
        with sub:
            assert sub.get().topic == "/odom"
        assert list(sub) == []
        with pytest.raises(rmb.NotConnected, match="ended"):
            sub.get()


def test_a_dead_worker_loop_makes_calls_raise_not_connected(robot: DemoRobot, backend: str) -> None:
    """The loop stops under a waiting call (no timeout): the wait ends with
    NotConnected, and so does every later call; close() still returns."""
    client = rmb.connect_sync(robot.url, backend=backend, options=options())
    try:
        with client.subscribe("/never_published") as sub:
            killer = threading.Timer(0.3, client._worker.stop, (5.0,))
            killer.start()
            with pytest.raises(rmb.NotConnected, match=r"closed while it was running|stopped"):
                sub.get()
            killer.join()
        assert not client.worker_thread.is_alive()
        with pytest.raises(rmb.NotConnected, match="worker thread has stopped"):
            client.publish("/cmd_vel", TWIST, {})
        with pytest.raises(rmb.NotConnected, match="worker thread has stopped"):
            client.call_service("/set_led", {"data": True})
    finally:
        client.close()
    assert sync_threads() == []


def test_connect_errors_and_bad_arguments_raise_at_once_and_leave_no_thread(
    backend: str,
) -> None:
    quick = rmb.ClientOptions(connect_timeout=2.0, reconnect=None)
    with pytest.raises(rmb.ConnectError):
        rmb.connect_sync("127.0.0.1:1", backend=backend, options=quick)
    with pytest.raises(ValueError, match="invalid port"):
        rmb.connect_sync("127.0.0.1:http", backend=backend)
    with pytest.raises(ValueError, match="backend"):
        rmb.connect_sync("127.0.0.1", backend="curio")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="no_such_option"):
        rmb.connect_sync("127.0.0.1", no_such_option=1)  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="options"):
        rmb.connect_sync("127.0.0.1", options={"teardown_timeout": 1})  # type: ignore[arg-type]
    assert sync_threads() == []


@pytest.mark.parametrize("loop", ["trio", "uvloop"])
def test_a_worker_without_its_loop_installed_says_which_extra(
    monkeypatch: pytest.MonkeyPatch, loop: str
) -> None:
    monkeypatch.setitem(sys.modules, loop, None)  # importing it now fails
    with pytest.raises(ImportError, match=rf"pip install 'ros-mobile-bridge\[{loop}\]'"):
        rmb.connect_sync("127.0.0.1", backend=loop)  # type: ignore[arg-type]
    assert sync_threads() == []


def test_a_uvloop_worker_runs_on_uvloop(robot: DemoRobot) -> None:
    """``backend="uvloop"`` is asyncio on uvloop, not asyncio's own loop."""
    pytest.importorskip("uvloop")

    async def loop_class(_client: rmb.Client) -> str:
        import asyncio

        return type(asyncio.get_running_loop()).__module__

    with rmb.connect_sync(robot.url, backend="uvloop", options=options()) as client:
        assert client.run(loop_class).startswith("uvloop")


def test_bad_arguments_to_methods_raise_at_once(robot: DemoRobot, backend: str) -> None:
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
        with pytest.raises(ValueError, match="priority"):
            client.publish("/cmd_vel", TWIST, {}, priority="urgent")  # type: ignore[arg-type]
        with pytest.raises(rmb.SchemaError):
            client.publish("/cmd_vel", "std_msgs/msg/String", {"data": "go"})
        with pytest.raises(ValueError, match="compression"):
            client.subscribe("/odom", compression="zip")  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="timeout"):
            client.subscribe("/odom", timeout=0)
        with pytest.raises(ValueError, match="finite"):
            client.subscribe("/odom", timeout=math.inf)
        with pytest.raises(ValueError, match="finite"):
            client.call_service("/set_led", {"data": True}, timeout=math.inf)
        with pytest.raises(TypeError, match="timeout"):
            client.run(_count_tasks, timeout="5")  # type: ignore[arg-type]
        with pytest.raises(rmb.ServiceError):
            client.call_service("/no_such_service", {})
        with pytest.raises(RuntimeError, match="enter"):
            client.subscribe("/odom").get()
        assert client.connected


def test_a_client_left_open_is_closed_at_interpreter_exit(robot: DemoRobot) -> None:
    """A script that never closes its client: the atexit hook runs the
    teardown, so the robot still gets the zero Twist last."""
    before = len(robot.received_cmd_vel())
    script = textwrap.dedent(
        f"""
        import ros_mobile_bridge as rmb
        robot = rmb.connect_sync({robot.url!r})
        robot.publish("/cmd_vel", {TWIST!r}, {{"linear": {{"x": 0.25}}}}, priority="control")
        print("published", flush=True)
        """
    )
    result = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "published"
    assert commands_since(robot, before) == [(0.25, 0.0), (0.0, 0.0)]


def test_a_bad_close_timeout_raises_at_once_and_a_later_close_still_tears_down(
    robot: DemoRobot, backend: str
) -> None:
    """close(timeout=<bad>) raises before anything is closed: the client
    stays connected and registered for the atexit hook, and the next
    close() sends the zero Twist and stops the thread."""
    before = len(robot.received_cmd_vel())
    client = rmb.connect_sync(robot.url, backend=backend, options=options())
    try:
        client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.15}}, priority="control")
        with pytest.raises(TypeError, match="timeout"):
            client.close(timeout="3")  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="timeout"):
            client.close(timeout=0)
        with pytest.raises(ValueError, match="finite"):
            client.close(timeout=math.inf)
        assert not client.closed and client.connected
        assert client in _sync._open_clients
    finally:
        client.close()
    assert client.closed and client not in _sync._open_clients
    assert commands_since(robot, before) == [(0.15, 0.0), (0.0, 0.0)]
    assert not client.worker_thread.is_alive()


def test_close_from_inside_run_raises_and_leaves_the_client_open(
    robot: DemoRobot, backend: str
) -> None:
    before = len(robot.received_cmd_vel())
    client = rmb.connect_sync(robot.url, backend=backend, options=options())
    try:
        client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.35}}, priority="control")

        async def close_inside(_c: rmb.Client) -> None:
            client.close()

        with pytest.raises(RuntimeError, match="own event loop"):
            client.run(close_inside, timeout=5)
        assert not client.closed and client.connected
        assert client.call_service("/set_led", {"data": True}, timeout=5).success is True
    finally:
        client.close()
    assert commands_since(robot, before) == [(0.35, 0.0), (0.0, 0.0)]
    assert not client.worker_thread.is_alive()


def test_close_logs_a_subscription_that_fails_to_leave_and_still_tears_down(
    robot: DemoRobot,
    backend: str,
    caplog: pytest.LogCaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    before = len(robot.received_cmd_vel())
    client = rmb.connect_sync(robot.url, backend=backend, options=options())
    sub = client.subscribe("/odom", timeout=5).__enter__()
    assert sub.get().topic == "/odom"

    def broken_exit(timeout: float) -> None:
        raise RuntimeError("leaving broke")

    monkeypatch.setattr(sub._held, "exit", broken_exit)  # the async block's leaving
    client.publish("/cmd_vel", TWIST, {"linear": {"x": 0.45}}, priority="control")
    with caplog.at_level(logging.WARNING, logger="ros_mobile_bridge"):
        client.close()
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert [r.getMessage() for r in warnings] == [
        "close: leaving <SyncSubscription /odom> failed: RuntimeError('leaving broke')"
    ]
    assert commands_since(robot, before) == [(0.45, 0.0), (0.0, 0.0)]
    assert not client.worker_thread.is_alive()


def test_wait_active_defaults_to_the_subscriptions_timeout(robot: DemoRobot, backend: str) -> None:
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
        with client.subscribe("/never_published", timeout=0.2) as sub:
            # a backstop so that a wait without a bound fails (NotConnected) instead of hanging
            backstop = threading.Timer(10, client.close)
            backstop.start()
            try:
                with pytest.raises(TimeoutError, match="wait_active"):
                    sub.wait_active()
            finally:
                backstop.cancel()
            assert sub.state == "pending"
        with client.subscribe("/odom", timeout=5) as odom:
            odom.wait_active()
            assert odom.state == "active"


def test_fetch_definition_runs_the_async_one_in_the_worker(
    robot: DemoRobot, backend: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the plumbing, with a stand-in for Client.fetch_definition (whether or
    # not Client has its own yet): the call, its result, the thread it ran in
    calls: list[tuple[str, str]] = []

    async def fetch_definition(self: rmb.Client, name: str) -> bool:
        calls.append((name, threading.current_thread().name))
        await anyio.sleep(0)
        return name == TWIST

    monkeypatch.setattr(rmb.Client, "fetch_definition", fetch_definition, raising=False)
    with rmb.connect_sync(robot.url, backend=backend, options=options()) as client:
        assert client.fetch_definition(TWIST, timeout=5) is True
        assert client.fetch_definition("pkg/msg/Unknown") is False
    assert calls == [(TWIST, f"rmb-sync-{backend}"), ("pkg/msg/Unknown", f"rmb-sync-{backend}")]
    with pytest.raises(rmb.NotConnected, match="closed"):
        client.fetch_definition(TWIST)
