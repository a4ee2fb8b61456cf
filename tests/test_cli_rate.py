"""``rmb hz``, ``bw``, ``delay`` (text and ``--json``) and ``echo --info``:
the arrival meter's arithmetic on its own, then each verb against the demo
robot (the official Foxglove SDK server) on both event loops."""

from __future__ import annotations

import json
import signal
from typing import Any

import pytest

from _cli_run import rmb, rmb_proc
from ros_mobile_bridge._cli._rate import ArrivalMeter, delay_figures, header_stamp_ns
from ros_mobile_bridge._types import new_message
from ros_mobile_bridge.demo import DemoRobot

BACKENDS = ["asyncio", "trio"]


def message(receive_ns: int, size: int = 10) -> Any:
    return new_message("/t", "x/msg/T", "cdr", b"", receive_ns, None, size, None, None)


# -- the meter ---------------------------------------------------------------------------------


def test_the_rate_counts_arrivals_not_the_frames_taken() -> None:
    meter = ArrivalMeter(window=1000)
    # 10 frames taken of 100 arrived per batch (the buffer dropped the rest)
    for second in range(4):
        batch = [message(second * 1_000_000_000 + i) for i in range(10)]
        meter.taken(batch, received=(second + 1) * 100, now_ns=second * 1_000_000_000)
    hz = meter.hz()
    assert hz is not None
    assert hz["rate_hz"] == pytest.approx(100.0)
    assert hz["window"] == 300
    bw = meter.bw()
    assert bw is not None
    assert bw["bytes_per_s"] == pytest.approx(1000.0)  # mean size x arrival rate
    assert (bw["min_bytes"], bw["max_bytes"], bw["messages"]) == (10, 10, 300)


def test_the_window_keeps_about_window_arrivals() -> None:
    meter = ArrivalMeter(window=100)
    for i in range(1, 11):  # 50 arrivals per 0.1 s, then 500 per 0.1 s
        received = 250 + (i - 5) * 500 if i > 5 else i * 50
        meter.taken([message(i)], received=received, now_ns=i * 100_000_000)
    # only the last checkpoints, spanning at least 100 arrivals, count
    assert meter.rate() == pytest.approx(5000.0)
    assert len(meter.checkpoints) == 2


def test_no_figures_before_two_checkpoints() -> None:
    meter = ArrivalMeter(window=10)
    assert meter.hz() is None
    assert meter.bw() is None
    meter.taken([message(1)], received=1, now_ns=1)
    assert meter.hz() is None


def test_delay_figures_and_the_header_stamp() -> None:
    assert header_stamp_ns({"header": {"stamp": {"sec": 2, "nanosec": 5}}}) == 2_000_000_005
    assert header_stamp_ns({"data": 1}) is None
    assert header_stamp_ns({"header": {"stamp": {"sec": "2", "nanosec": 0}}}) is None
    figures = delay_figures([1_000_000, 3_000_000])
    assert figures == {
        "delay_s": pytest.approx(0.002),
        "min_s": pytest.approx(0.001),
        "max_s": pytest.approx(0.003),
        "std_s": pytest.approx(0.001),
        "window": 2,
    }
    assert delay_figures([]) is None


# -- against the demo robot --------------------------------------------------------------------


def lines_of(*args: str, count: int) -> tuple[list[str], int]:
    """The first ``count`` stdout lines of ``rmb ARGS``, then Ctrl-C."""
    proc = rmb_proc(*args)
    assert proc.stdout is not None
    try:
        lines = [proc.stdout.readline() for _ in range(count)]
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.communicate(timeout=20)
        finally:
            proc.kill()
    return lines, proc.returncode


@pytest.mark.parametrize("backend", BACKENDS)
def test_hz_json(robot: DemoRobot, backend: str) -> None:
    lines, code = lines_of("--backend", backend, "-u", robot.url, "hz", "/odom", "--json", count=2)
    records = [json.loads(line) for line in lines]
    for record in records:
        assert set(record) == {
            "topic",
            "rate_hz",
            "min_s",
            "max_s",
            "std_s",
            "window",
            "received",
            "dropped",
        }
        assert record["topic"] == "/odom"
        assert 5.0 < record["rate_hz"] < 80.0  # the demo publishes /odom at 20 Hz
        assert record["dropped"] == 0
    assert records[1]["received"] > records[0]["received"]
    assert code == 130


@pytest.mark.parametrize("backend", BACKENDS)
def test_bw_json(robot: DemoRobot, backend: str) -> None:
    lines, code = lines_of("--backend", backend, "-u", robot.url, "bw", "/odom", "--json", count=1)
    record = json.loads(lines[0])
    assert set(record) == {
        "topic",
        "bytes_per_s",
        "messages",
        "mean_bytes",
        "min_bytes",
        "max_bytes",
        "received",
        "dropped",
    }
    assert record["min_bytes"] == record["max_bytes"] > 100  # one fixed-size Odometry
    assert record["bytes_per_s"] == pytest.approx(
        record["mean_bytes"] * record["messages"], rel=0.6
    )
    assert code == 130


@pytest.mark.parametrize("backend", BACKENDS)
def test_delay_text_and_json(robot: DemoRobot, backend: str) -> None:
    common = ("--backend", backend, "-u", robot.url, "delay", "/odom")
    lines, code = lines_of(*common, count=2)
    assert lines[0].startswith("average delay: ")
    assert lines[1].startswith("\tmin: ") and "window: " in lines[1]
    assert code == 130
    lines, code = lines_of(*common, "--json", count=1)
    record = json.loads(lines[0])
    assert set(record) == {"topic", "delay_s", "min_s", "max_s", "std_s", "window"}
    # stamped by the demo when published, received on loopback: well under a second
    assert 0.0 <= record["min_s"] <= record["delay_s"] <= record["max_s"] < 1.0
    assert code == 130


def test_delay_of_a_topic_without_header_is_one_line(robot: DemoRobot) -> None:
    result = rmb("-u", robot.url, "delay", "/status")
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "has no header.stamp" in lines[0], result.stderr


def test_echo_info(robot: DemoRobot) -> None:
    lines, _code = lines_of("-u", robot.url, "echo", "/odom", "--info", count=2)
    assert lines[0].startswith("# receive_time_ns: ")
    assert "log_time_ns: " in lines[0] and "byte_size: " in lines[0]
    assert "sequence" not in lines[0]  # Foxglove carries none
    assert lines[1] == "header:\n"


def test_info_json(robot: DemoRobot) -> None:
    def run(*args: str) -> Any:
        result = rmb("-u", robot.url, "info", *args, "--json")
        assert result.returncode == 0, result.stderr
        return json.loads(result.stdout)

    server = run()
    assert server["protocol"] == "foxglove-ws"
    assert server["topics"] == 5 and server["services"] == 2
    assert "services" in server["capabilities"]
    topic = run("/odom")
    assert topic == {
        "topic": "/odom",
        "type": "nav_msgs/msg/Odometry",
        "encoding": "cdr",
        "publishers": 1,  # from the demo robot's connection graph
        "subscriptions": 0,
    }
