"""Signals end the work the structured way: ``rmb.cancel_on_signals`` turns
SIGINT, SIGTERM and SIGHUP into cancellation of its scope (in-process, both
backends), and every ``rmb`` command, killed the way ``timeout``, systemd,
``docker stop`` or a closed terminal kill it, still sends the zero Twist and
exits 128 + signal. The robot is the demo robot (the official Foxglove SDK
server), recording every velocity command it receives."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until, wait_until_sync
from peers.rosbridge import RosBridge, RosGraph
from ros_mobile_bridge.demo import DemoRobot

pytest_plugins = ["peers.ros_fixtures"]

ROOT = Path(__file__).resolve().parent.parent
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]
BACKENDS = ["asyncio", "trio", "uvloop"]  # rmb --backend; uvloop: asyncio on uvloop
TWIST_03 = '{"linear": {"x": 0.3}}'


# -- the library helper, in-process ----------------------------------------------------------


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
async def test_a_signal_cancels_the_scope_and_names_itself(sig: signal.Signals) -> None:
    before = signal.getsignal(sig)
    reached_end = False
    async with rmb.cancel_on_signals() as stop:
        assert stop.signal is None
        os.kill(os.getpid(), sig)
        await anyio.sleep(10)
        reached_end = True
    assert not reached_end
    assert stop.signal == sig
    assert stop.exit_code == 128 + sig
    assert signal.getsignal(sig) == before  # the previous handler is back


async def test_the_teardown_of_a_connection_inside_runs(caplog: pytest.LogCaptureFixture) -> None:
    with DemoRobot() as robot:
        async with (
            rmb.cancel_on_signals() as stop,
            rmb.connect(robot.url, options=rmb.ClientOptions(advertise_settle=0.0)) as client,
        ):
            await client.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.3}})
            os.kill(os.getpid(), signal.SIGTERM)
            await anyio.sleep(10)
        assert stop.signal == signal.SIGTERM
        await wait_until(
            lambda: [c.linear_x for c in robot.received_cmd_vel()] == [0.3, 0.0],
            5,
            what=lambda: f"the 0.3 then the zero Twist, got {robot.received_cmd_vel()}",
        )


async def test_a_scope_without_a_signal_reports_none() -> None:
    async with rmb.cancel_on_signals(signal.SIGUSR1) as stop:
        await anyio.sleep(0)
    assert stop.signal is None and stop.exit_code is None


async def test_only_the_chosen_signals_are_taken() -> None:
    received: list[int] = []
    previous = signal.signal(signal.SIGUSR2, lambda n, _f: received.append(n))
    try:
        async with rmb.cancel_on_signals(signal.SIGUSR1) as stop:
            os.kill(os.getpid(), signal.SIGUSR2)
            await wait_until(lambda: received, what="SIGUSR2 at its own handler")
            os.kill(os.getpid(), signal.SIGUSR1)
            await anyio.sleep(10)
    finally:
        signal.signal(signal.SIGUSR2, previous)
    assert stop.signal == signal.SIGUSR1
    assert received == [signal.SIGUSR2]


async def test_exceptions_from_the_body_pass_through_unwrapped() -> None:
    with pytest.raises(KeyError, match="boom"):
        async with rmb.cancel_on_signals():
            raise KeyError("boom")
    with pytest.raises(SystemExit) as exited:
        async with rmb.cancel_on_signals():
            sys.exit(3)
    assert exited.value.code == 3


async def test_an_outer_cancellation_is_not_a_signal() -> None:
    with anyio.CancelScope() as outer:
        async with rmb.cancel_on_signals() as stop:
            outer.cancel()
            await anyio.sleep(10)
    assert outer.cancelled_caught and stop.signal is None


async def test_bad_signal_arguments_are_refused_at_once() -> None:
    with pytest.raises(TypeError):
        async with rmb.cancel_on_signals("SIGTERM"):  # type: ignore[arg-type]
            pass
    with pytest.raises(ValueError, match="12345"):
        async with rmb.cancel_on_signals(12345):
            pass


async def test_the_signal_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, "ros_mobile_bridge")
    async with rmb.cancel_on_signals():
        os.kill(os.getpid(), signal.SIGTERM)
        await anyio.sleep(10)
    assert "SIGTERM received: stopping" in caplog.text


# -- a second signal, in a process of its own ----------------------------------------------

STUCK = """
import anyio, sys
import ros_mobile_bridge as rmb

async def main():
    async with rmb.cancel_on_signals() as stop:
        print("ready", flush=True)
        try:
            await anyio.sleep_forever()
        finally:
            with anyio.CancelScope(shield=True):
                print("winding down", flush=True)
                await anyio.sleep(60)  # a teardown stuck on a dead network
    return stop.exit_code

loop = sys.argv[1]
uvloop = {"use_uvloop": True} if loop == "uvloop" else None
sys.exit(anyio.run(main, backend="asyncio" if uvloop else loop, backend_options=uvloop))
"""


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_second_signal_exits_at_once(backend: str) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(STUCK), backend],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "ready"
        proc.send_signal(signal.SIGTERM)
        assert proc.stdout.readline().strip() == "winding down"
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=20)  # instead of the 60 s the teardown would take
    finally:
        proc.kill()
        proc.communicate()
    assert proc.returncode == -signal.SIGTERM


# -- rmb, killed -----------------------------------------------------------------------------


def rmb_cli(backend: str, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "ros_mobile_bridge", "--backend", backend, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_rmb_pub_killed_sends_the_zero_twist_and_exits_128_plus_signal(
    robot: DemoRobot, backend: str, sig: signal.Signals
) -> None:
    before = len(robot.received_cmd_vel())
    proc = rmb_cli(
        backend, "pub", "-r", "10", robot.url, "/cmd_vel", "geometry_msgs/msg/Twist", TWIST_03
    )
    try:
        wait_until_sync(lambda: len(robot.received_cmd_vel()) - before >= 3, 20)
        proc.send_signal(sig)
        _out, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err
    wait_until_sync(lambda: robot.received_cmd_vel()[-1].linear_x == 0.0, 5)
    got = [c.linear_x for c in robot.received_cmd_vel()[before:]]
    assert got[-1] == 0.0 and set(got[:-1]) == {0.3}, got


@pytest.mark.parametrize("backend", BACKENDS)
def test_rmb_pub_killed_stops_a_ros_robot_through_rosbridge(
    rosbridge: RosBridge, ros_graph: RosGraph, backend: str
) -> None:
    ros_graph.command({"cmd": "clear", "topic": "/cmd_vel"})

    def received() -> list[float]:
        return [
            m["linear"]["x"] for m in ros_graph.command({"cmd": "received", "topic": "/cmd_vel"})
        ]

    proc = rmb_cli(
        backend, "pub", "-r", "10", rosbridge.url, "/cmd_vel", "geometry_msgs/msg/Twist", TWIST_03
    )
    try:
        wait_until_sync(lambda: len(received()) >= 3, 20, interval=0.02)
        proc.send_signal(signal.SIGTERM)
        _out, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err
    wait_until_sync(lambda: received()[-1] == 0.0, 10, interval=0.02)  # DDS may still be delivering
    got = received()
    assert set(got[:-1]) == {0.3}, got


@pytest.mark.parametrize("backend", BACKENDS)
def test_rmb_echo_killed_exits_128_plus_signal(robot: DemoRobot, backend: str) -> None:
    proc = rmb_cli(backend, "echo", robot.url, "/status", "--json")
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("{")
        proc.send_signal(signal.SIGTERM)
        _out, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "Traceback" not in err


@pytest.mark.parametrize("backend", BACKENDS)
def test_rmb_demo_serve_stops_on_sigterm(backend: str) -> None:
    proc = rmb_cli(backend, "demo", "--serve")
    try:
        assert proc.stdout is not None
        assert "serving" in proc.stdout.readline()
        proc.send_signal(signal.SIGTERM)
        _out, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "Traceback" not in err


# -- a closed stdout ---------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_rmb_pub_whose_stdout_closes_still_stops_the_robot(robot: DemoRobot, backend: str) -> None:
    before = len(robot.received_cmd_vel())
    proc = rmb_cli(
        backend, "pub", "-r", "10", robot.url, "/cmd_vel", "geometry_msgs/msg/Twist", TWIST_03
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("publishing #1")
        proc.stdout.close()  # like `| head -1`
        proc.wait(timeout=20)
    finally:
        proc.kill()
        assert proc.stderr is not None
        err = proc.stderr.read()
        proc.stderr.close()
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert proc.returncode == 128 + signal.SIGPIPE
    wait_until_sync(lambda: robot.received_cmd_vel()[-1].linear_x == 0.0, 5)
    got = [c.linear_x for c in robot.received_cmd_vel()[before:]]
    assert got[-1] == 0.0 and 0.3 in got, got


@pytest.mark.parametrize("backend", BACKENDS)
def test_rmb_echo_into_head_ends_without_a_traceback(robot: DemoRobot, backend: str) -> None:
    shell = (
        f"{sys.executable} -m ros_mobile_bridge --backend {backend} echo {robot.url} /status"
        " --json | head -1; echo status=${PIPESTATUS[0]} >&2"
    )
    result = subprocess.run(
        ["bash", "-c", shell], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.stdout.startswith("{") and len(result.stdout.splitlines()) == 1
    assert "Traceback" not in result.stderr and "Exception ignored" not in result.stderr
    assert f"status={128 + signal.SIGPIPE}" in result.stderr, result.stderr
