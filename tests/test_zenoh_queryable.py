"""The Zenoh session's queryable (the transport under serving a service over
Zenoh), through a real eclipse-zenoh router, queried by a bare eclipse-zenoh
session: each query reaches the inbox as a ``Request``, is answered once by
``reply`` or ``reply_error``, queries past the open-query bound are answered
with an error at once and counted, and the queries still open when the
queryable is undeclared or the session closes are answered with an error."""

from __future__ import annotations

import threading
from typing import Any

import anyio
import pytest

from _util import routed, unrouted, wait_until
from ros_mobile_bridge.transport._zenoh import DEFAULT_MAX_OPEN_QUERIES, ZenohSession
from ros_mobile_bridge.wire import rmw_zenoh as rz

zenoh = pytest.importorskip("zenoh")

KEY = "7/svc/std_srvs::srv::dds_::Trigger_/RIHS01_" + "0" * 64


async def open_session(router: Any, **kw: Any) -> ZenohSession:
    return await ZenohSession.open(
        router.locator, connect_timeout=5.0, max_items=1000, max_bytes=1 << 20, **kw
    )


class Caller:
    """Queries sent with a bare session; each one's replies, once it ended."""

    def __init__(self, raw: Any) -> None:
        self._raw = raw
        self._lock = threading.Lock()
        self.done: dict[int, list[tuple[str, bytes, bytes | None]]] = {}

    def get(self, n: int, payload: bytes, attachment: bytes | None = None) -> None:
        replies: list[tuple[str, bytes, bytes | None]] = []

        def on_reply(reply: Any) -> None:
            if reply.ok is not None:
                att = reply.ok.attachment
                replies.append(
                    ("ok", reply.ok.payload.to_bytes(), None if att is None else att.to_bytes())
                )
            else:
                replies.append(("err", reply.err.payload.to_bytes(), None))

        def on_done() -> None:
            with self._lock:
                self.done[n] = replies

        self._raw.get(
            KEY,
            zenoh.handlers.Callback(on_reply, on_done),
            payload=payload,
            attachment=attachment,
            target=zenoh.QueryTarget.ALL_COMPLETE,
            timeout=20.0,
        )

    def count(self) -> int:
        with self._lock:
            return len(self.done)


async def requests(session: ZenohSession, count: int) -> list[rz.Request]:
    got: list[rz.Request] = []
    with anyio.fail_after(10):
        while len(got) < count:
            got.extend(i for i in await session.inbox.get_batch() if type(i) is rz.Request)
    return got


async def test_each_query_is_a_request_answered_once_in_order(zenoh_router: Any, raw: Any) -> None:
    session = await open_session(zenoh_router)
    try:
        session.declare_queryable(KEY, tag=5)
        await routed(raw, KEY, queryable=True)  # the declaration reaches the router
        caller = Caller(raw)
        attachment = rz.encode_attachment(1, 2, bytes(range(16)))
        for n in range(3):
            caller.get(n, f"q{n}".encode(), attachment)
        got = await requests(session, 3)
        assert [r.payload for r in got] == [b"q0", b"q1", b"q2"]
        assert {r.tag for r in got} == {5} and all(r.key == KEY for r in got)
        assert all(r.attachment == attachment for r in got)
        assert len({r.query_id for r in got}) == 3
        assert session.open_queries == 3
        assert session.reply(got[0].query_id, KEY, b"a0", attachment)
        assert session.reply_error(got[1].query_id, "refused: no")
        assert session.reply(got[2].query_id, KEY, b"a2", attachment)
        assert not session.reply(got[0].query_id, KEY, b"again", attachment)  # once only
        assert not session.reply_error(got[1].query_id, "again")
        await wait_until(lambda: caller.count() == 3, timeout=10.0)
        assert caller.done == {
            0: [("ok", b"a0", attachment)],
            1: [("err", b"refused: no", None)],
            2: [("ok", b"a2", attachment)],
        }
        assert session.open_queries == 0
    finally:
        await session.aclose()


async def test_queries_past_the_bound_are_refused_and_counted(zenoh_router: Any, raw: Any) -> None:
    assert DEFAULT_MAX_OPEN_QUERIES == 256
    session = await open_session(zenoh_router, max_open_queries=2)
    try:
        session.declare_queryable(KEY, tag=1)
        await routed(raw, KEY, queryable=True)
        caller = Caller(raw)
        for n in range(5):
            caller.get(n, b"x")
        await wait_until(
            lambda: caller.count() == 3, timeout=10.0
        )  # the three over the bound, at once
        got = await requests(session, 2)
        assert session.refused_queries == 3
        assert session.open_queries == 2
        refused = list(caller.done.values())
        assert len(refused) == 3 and all(
            r == [("err", b"2 calls already wait for an answer", None)] for r in refused
        )
        for request in got:
            assert session.reply(request.query_id, KEY, b"ok", b"att")
        await wait_until(lambda: caller.count() == 5, timeout=10.0)
        caller.get(9, b"y")  # room again
        (late,) = await requests(session, 1)
        assert session.refused_queries == 3
        assert session.reply(late.query_id, KEY, b"ok9", b"att")
        await wait_until(lambda: 9 in caller.done, timeout=10.0)
        assert caller.done[9] == [("ok", b"ok9", b"att")]
    finally:
        await session.aclose()


async def test_a_bad_bound_is_refused_at_once(zenoh_router: Any) -> None:
    for bad in (0, -1, True, 1.5):
        with pytest.raises(ValueError, match="max_open_queries"):
            await open_session(zenoh_router, max_open_queries=bad)


async def test_undeclare_and_close_answer_the_open_queries(zenoh_router: Any, raw: Any) -> None:
    session = await open_session(zenoh_router)
    try:
        handle = session.declare_queryable(KEY, tag=1)
        await routed(raw, KEY, queryable=True)
        caller = Caller(raw)
        caller.get(0, b"a")
        caller.get(1, b"b")
        got = await requests(session, 2)
        session.undeclare(handle)
        await wait_until(lambda: caller.count() == 2, timeout=10.0)
        assert caller.done == {
            0: [("err", b"the service is no longer served", None)],
            1: [("err", b"the service is no longer served", None)],
        }
        assert session.open_queries == 0
        assert not session.reply(got[0].query_id, KEY, b"late", b"")
        await unrouted(raw, KEY, queryable=True)  # (lingers a while: routed would see it)
        session.declare_queryable(KEY, tag=2)
        await routed(raw, KEY, queryable=True)
        caller.get(2, b"c")
        (open_,) = await requests(session, 1)
        assert open_.tag == 2
    finally:
        await session.aclose()
    await wait_until(lambda: caller.count() == 3, timeout=10.0)
    assert caller.done[2] == [("err", b"the server closed its session", None)]


def test_the_key_value_attachment_is_zenoh_ext_serialization() -> None:
    """The 77-byte form read by ``decode_attachment`` is what zenoh-ext
    serializes for the three key-value pairs the first Jazzy releases of
    rmw_zenoh_cpp wrote."""
    from zenoh.ext import Int64, z_serialize

    gid = bytes(range(16, 32))
    parts = (
        ("sequence_number", Int64(42)),
        ("source_timestamp", Int64(-7)),
        ("source_gid", gid),
    )
    data = b"".join(z_serialize(k).to_bytes() + z_serialize(v).to_bytes() for k, v in parts)
    assert len(data) == rz.KEYED_ATTACHMENT_SIZE
    assert rz.decode_attachment(data) == rz.Attachment(42, -7, gid)
