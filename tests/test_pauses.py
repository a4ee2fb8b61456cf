"""``PauseSchedule``, the bookkeeping of ``save_bandwidth`` shared by the
Foxglove and Zenoh adapters, on its own (the adapters' behaviour against
real servers is in test_save_bandwidth.py and test_zenoh_save_bandwidth.py)."""

from __future__ import annotations

import anyio

from _util import wait_until
from ros_mobile_bridge.adapters._pauses import PauseSchedule


def test_only_the_first_message_after_a_resumption_is_checked_for_a_replay() -> None:
    p: PauseSchedule[str] = PauseSchedule()
    p.set_rate("/t", 5.0)
    same = memoryview(b"same")
    assert p.take("/t", 0.0, same)  # nothing delivered yet: delivered
    p.pause("/t", 0.0, "key")
    assert p.paused["/t"] == (0.2, "key")
    p.paused.pop("/t")
    p.resumed("/t", 0.2)
    assert not p.take("/t", 0.21, memoryview(b"same"))  # the replay
    assert p.take("/t", 0.25, memoryview(b"same"))  # alike, but new
    p.pause("/t", 0.25, "key")
    # the next resumption is as much earlier as that message took to come
    assert abs(p.paused["/t"][0] - (0.25 + 0.2 - 0.05)) < 1e-9


def test_without_a_payload_nothing_is_checked_and_the_wait_is_bounded() -> None:
    p: PauseSchedule[None] = PauseSchedule()
    p.set_rate("/t", 10.0)
    assert p.take("/t", 0.0)
    p.resumed("/t", 1.0)
    assert p.take("/t", 5.0)  # waited 4 s: counted as half the interval at most
    p.pause("/t", 5.0, None)
    assert abs(p.paused["/t"][0] - (5.0 + 0.1 - 0.05)) < 1e-9


def test_unpause_and_forget_drop_the_topic_state() -> None:
    p: PauseSchedule[str] = PauseSchedule()
    p.set_rate("/t", 5.0)
    p.take("/t", 0.0, memoryview(b"x"))
    p.pause("/t", 0.0, "k")
    assert p.unpause("/t") == (0.2, "k")
    assert p.unpause("/t") is None
    p.resumed("/t", 1.0)
    assert p.take("/t", 1.0, memoryview(b"x"))  # the payload was forgotten: delivered
    p.set_rate("/t", None)
    assert "/t" not in p.rates
    p.set_rate("/t", 5.0)
    p.pause("/t", 0.0, "k")
    p.forget("/t")
    assert not p.paused and not p.rates


async def test_run_resumes_each_topic_when_due_and_not_before() -> None:
    p: PauseSchedule[str] = PauseSchedule()
    resumed: list[tuple[str, str]] = []

    async def resume(topic: str, key: str) -> None:
        resumed.append((topic, key))

    p.set_rate("/a", 50.0)
    p.set_rate("/b", 1.0)
    async with anyio.create_task_group() as tg:
        tg.start_soon(p.run, resume)
        now = anyio.current_time()
        p.pause("/a", now, "ka")  # due in 20 ms
        p.pause("/b", now, "kb")  # due in 1 s
        await wait_until(lambda: resumed, 5, what="a resume")
        assert resumed == [("/a", "ka")]
        assert "/a" not in p.paused and "/b" in p.paused
        p.forget("/b")  # left while paused: never resumed
        await anyio.sleep(0.05)
        tg.cancel_scope.cancel()
    assert resumed == [("/a", "ka")]


async def test_a_pause_due_sooner_than_the_awaited_one_is_resumed_on_time() -> None:
    """run waits for the earliest due pause; a pause due sooner, made while
    it waits, wakes it: that topic is resumed while the other is still
    paused (without the wake both would be resumed together, later)."""
    p: PauseSchedule[str] = PauseSchedule()
    resumed: list[tuple[str, bool]] = []

    async def resume(topic: str, key: str) -> None:
        resumed.append((topic, "/slow" in p.paused))

    p.set_rate("/slow", 0.2)  # due in 5 s
    p.set_rate("/fast", 50.0)  # due in 20 ms
    async with anyio.create_task_group() as tg:
        tg.start_soon(p.run, resume)
        p.pause("/slow", anyio.current_time(), "ks")
        await anyio.wait_all_tasks_blocked()  # run now waits for /slow
        p.pause("/fast", anyio.current_time(), "kf")
        await wait_until(lambda: resumed, 4, what="a resume")
        tg.cancel_scope.cancel()
    assert resumed == [("/fast", True)]
