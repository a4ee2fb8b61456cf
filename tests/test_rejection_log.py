"""The rejections' log: every input counted, the log bounded to a line per
reason a second (past a burst), and the lines adding up to the counts once flushed. A fake
clock makes every assertion exact."""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge._core._rejection_log import LOG_BURST, LOG_EVERY, RejectionLog

LOGGER = logging.getLogger("tests.test_rejection_log")


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


@pytest.fixture
def lines() -> Iterator[list[str]]:
    handler = Lines()
    LOGGER.addHandler(handler)
    LOGGER.setLevel(logging.WARNING)
    try:
        yield handler.lines
    finally:
        LOGGER.removeHandler(handler)


def logged_count(line: str) -> int:
    match = re.match(r"skipped (\d+) inputs", line)
    return int(match.group(1)) if match else 1


def test_a_flood_of_one_reason_is_a_few_lines_a_second(lines: list[str]) -> None:
    clock = Clock()
    log = RejectionLog(LOGGER, clock)
    for i in range(3000):  # 1,000 a second for 3 s
        clock.now = 100.0 + i / 1000
        log.add("attachment", f"/chatter: sample {i} without an attachment")
    assert log.counts == {"attachment": 3000}
    # each second: the first LOG_BURST one by one, then one line for the rest
    first = [
        f"skipped input from the server (attachment): /chatter: sample {i} without an attachment"
        for i in range(LOG_BURST)
    ]
    assert lines[:LOG_BURST] == first
    assert lines[LOG_BURST] == (
        f"skipped {1000 - LOG_BURST} inputs from the server (attachment) in the last 1.0 s, "
        f"past the {LOG_BURST} logged one by one"
    )
    assert lines[LOG_BURST + 1].endswith("sample 1000 without an attachment")
    assert len(lines) == 3 * LOG_BURST + 2
    log.flush()  # the client closes: the rest is logged, and the lines add up
    assert lines[-1].startswith(f"skipped {1000 - LOG_BURST} inputs from the server (attachment)")
    assert sum(logged_count(line) for line in lines) == 3000
    log.flush()
    assert len(lines) == 3 * LOG_BURST + 3  # nothing twice


def test_reasons_are_limited_separately(lines: list[str]) -> None:
    clock = Clock()
    log = RejectionLog(LOGGER, clock)
    for i in range(LOG_BURST + 5):
        log.add("malformed", f"m{i}")
    log.add("json_depth", "deep", count=5)  # another reason still logs
    assert lines[-1] == "skipped 5 inputs from the server (json_depth): deep"
    assert len(lines) == LOG_BURST + 1
    clock.now += 10.0
    log.add("malformed", "late")  # a new window: what waited, then this one
    assert lines[-2].startswith("skipped 5 inputs from the server (malformed) in the last 10.0 s")
    assert lines[-1] == "skipped input from the server (malformed): late"
    assert log.counts == {"malformed": LOG_BURST + 6, "json_depth": 5}
    assert (LOG_EVERY, LOG_BURST) == (1.0, 10)


def test_details_are_truncated(lines: list[str]) -> None:
    log = RejectionLog(LOGGER, Clock())
    log.add("malformed", "x" * 100_000)
    assert len(lines[0]) < 1000
    assert "100000" in lines[0]


@settings(max_examples=examples(200), deadline=None)
@given(
    steps=st.lists(
        st.tuples(
            st.floats(min_value=0.0, max_value=0.7),
            st.sampled_from(["malformed", "attachment", "channel_limit"]),
            st.integers(min_value=1, max_value=50),
        ),
        min_size=1,
        max_size=200,
    )
)
def test_the_lines_add_up_to_the_counts_and_stay_bounded(
    steps: list[tuple[float, str, int]],
) -> None:
    clock = Clock()
    handler = Lines()
    logger = logging.getLogger(f"tests.test_rejection_log.{id(steps)}")
    logger.addHandler(handler)
    logger.propagate = False
    log = RejectionLog(logger, clock)
    start = clock.now
    for dt, reason, count in steps:
        clock.now += dt
        log.add(reason, "d", count)
    span = clock.now - start
    before_flush = list(handler.lines)
    log.flush()
    logger.removeHandler(handler)
    totals: dict[str, int] = {}
    for line in handler.lines:
        reason = re.search(r"\((\w+)\)", line)
        assert reason is not None
        totals[reason.group(1)] = totals.get(reason.group(1), 0) + logged_count(line)
    assert totals == log.counts
    for reason in log.counts:  # per window: LOG_BURST lines and one for the rest
        mine = [line for line in before_flush if f"({reason})" in line]
        assert len(mine) <= (LOG_BURST + 1) * (1 + span / LOG_EVERY)
