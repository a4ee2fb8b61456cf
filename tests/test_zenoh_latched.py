"""Latched (transient-local) topics over Zenoh, through a real eclipse-zenoh
router: a subscription that joins late receives what transient-local
publishers keep, in both forms released rmw_zenoh_cpp versions use, and again
after a router restart without duplicates; our ``advertise(latch=True)``
keeps history that an rmw_zenoh-form subscriber, a zenoh-ros2-sdk subscriber
and a second client read.

The rmw_zenoh-form publishers and subscribers are raw eclipse-zenoh
stand-ins (``tests/peers/rmw_zenoh_latched.py``): no rmw_zenoh_cpp build is
reachable here, and zenoh-ros2-sdk's publishers keep no history."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from _util import zenoh_options as options
from ros_mobile_bridge.codec import CodecRegistry, type_hash
from ros_mobile_bridge.wire import rmw_zenoh as rz

zenoh = pytest.importorskip("zenoh")
from peers.rmw_zenoh_latched import RmwPublisher, RmwSubscriber  # noqa: E402

pytest_plugins = ["peers.ros_fixtures"]  # sdk (zenoh-ros2-sdk nodes)

STRING = "std_msgs/msg/String"
FORMS = ["advanced", "publication_cache"]


class Collector:
    """Every message of a subscription, in a task of its own: ``data``."""

    def __init__(self, sub: rmb.Subscription) -> None:
        self.sub = sub
        self.data: list[str] = []

    async def run(self) -> None:
        async for message in self.sub:
            self.data.append(message.data.data)


def kept(raw: Any, domain: int, topic: str) -> list[str]:
    """What the advanced-form caches of ``topic`` keep now (a raw query, as
    an rmw_zenoh subscriber asks): our publishes go out through the client's
    writer task, so a test waits until the cache has them."""
    key = rz.format_key(rz.TopicKey(domain, topic, STRING, type_hash(CodecRegistry(), STRING)))
    replies = raw.get(
        f"{key}/@adv/pub/**",
        target=zenoh.QueryTarget.ALL,
        consolidation=zenoh.ConsolidationMode.NONE,
        accept_replies=zenoh.ReplyKeyExpr.ANY,
        timeout=5.0,
    )
    decode = CodecRegistry().decoder(STRING, "cdr")
    return [decode(memoryview(r.ok.payload.to_bytes())).data for r in replies if r.ok]


async def publisher_token(session: Any, domain: int) -> rz.Token:
    """The one publisher token of ``domain``, as a raw zenoh ``session`` reads
    it, once the router has it."""

    def publishers() -> list[rz.Token]:
        replies = session.liveliness().get(rz.liveliness_selector(domain), timeout=5.0)
        tokens = [rz.parse_token(str(r.ok.key_expr)) for r in replies if r.ok is not None]
        return [t for t in tokens if t.kind is rz.EntityKind.PUBLISHER]

    (token,) = await wait_until(publishers, timeout=10.0, what="the publisher token")
    return token


async def seen_publisher(client: rmb.Client, topic: str, count: int = 1) -> None:
    await wait_until(
        lambda: sum(1 for q in client._conn.adapter.offered_qos(topic)) >= count,  # type: ignore[attr-defined]
        timeout=15.0,
        what=f"{count} publisher(s) of {topic} in the graph",
    )


@pytest.mark.parametrize("form", FORMS)
async def test_a_late_subscription_receives_the_kept_message_then_live_ones(
    zenoh_router: Any, zenoh_domain: int, form: str
) -> None:
    with RmwPublisher(zenoh_router.locator, zenoh_domain, "/map_meta", depth=1, form=form) as pub:
        pub.publish({"data": "old"})
        pub.publish({"data": "latched"})  # depth 1: only this one is kept
        async with (
            rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
            anyio.create_task_group() as tg,
        ):
            await seen_publisher(client, "/map_meta")
            async with client.subscribe("/map_meta", schema=STRING) as sub:
                got = Collector(sub)
                tg.start_soon(got.run)
                await wait_until(lambda: got.data, timeout=10.0, what="the kept message")
                assert got.data == ["latched"]
                pub.publish({"data": "live"})
                await wait_until(lambda: len(got.data) == 2, timeout=10.0, what="the live one")
                assert got.data == ["latched", "live"]
                assert sub.stats.dropped_replay == 0
                assert client.rejections == {}
            tg.cancel_scope.cancel()


async def test_two_latched_publishers_each_deliver_what_they_keep(
    zenoh_router: Any, zenoh_domain: int
) -> None:
    locator = zenoh_router.locator
    with (
        RmwPublisher(locator, zenoh_domain, "/tf_static", form="advanced", node="a") as a,
        RmwPublisher(locator, zenoh_domain, "/tf_static", form="publication_cache", node="b") as b,
    ):
        a.publish({"data": "from a"})
        b.publish({"data": "from b"})
        async with (
            rmb.connect(locator, options=options(zenoh_domain)) as client,
            anyio.create_task_group() as tg,
        ):
            await seen_publisher(client, "/tf_static", 2)
            async with client.subscribe("/tf_static", schema=STRING) as sub:
                got = Collector(sub)
                tg.start_soon(got.run)
                await wait_until(lambda: len(got.data) == 2, timeout=10.0, what="both messages")
                assert sorted(got.data) == ["from a", "from b"]
                assert client.rejections == {}
            tg.cancel_scope.cancel()


async def test_volatile_publishers_are_not_asked_for_history(
    zenoh_router: Any, zenoh_domain: int
) -> None:
    locator = zenoh_router.locator
    opts = options(zenoh_domain)
    # a publisher whose token says VOLATILE but which keeps a cache all the
    # same: only the token counts, so nobody asks it
    with RmwPublisher(
        locator, zenoh_domain, "/status", transient_local=False, cache=True
    ) as stand_in:
        stand_in.publish({"data": "old, cached"})
        async with (
            rmb.connect(locator, options=opts) as talker,
            rmb.connect(locator, options=opts) as client,
            anyio.create_task_group() as tg,
        ):
            await talker.advertise("/status", STRING)  # volatile
            await talker.publish("/status", STRING, {"data": "old, ours"})
            await seen_publisher(client, "/status", 2)
            async with client.subscribe("/status", schema=STRING) as sub:
                got = Collector(sub)
                tg.start_soon(got.run)
                await wait_until(
                    lambda: any(t.name == "/status" for t in talker.topics),
                    timeout=10.0,
                    what="the talker sees the subscription",
                )
                with anyio.fail_after(10):
                    while not got.data:  # until the route exists
                        await talker.publish("/status", STRING, {"data": "new"})
                        stand_in.publish({"data": "new"})
                        await anyio.sleep(0.05)
                await talker.publish("/status", STRING, {"data": "last"})
                await wait_until(lambda: "last" in got.data, timeout=10.0, what="the last one")
                assert set(got.data) == {"new", "last"}
                assert sub.stats.dropped_replay == 0
            tg.cancel_scope.cancel()


@pytest.mark.parametrize("form", FORMS)
async def test_a_router_restart_brings_the_history_again_without_duplicates(
    zenoh_domain: int, form: str
) -> None:
    from peers.zenoh_router import ZenohRouter

    opts = options(
        zenoh_domain,
        connect_timeout=2.0,
        keepalive_interval=0.2,
        keepalive_timeout=0.6,
        reconnect=rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.3),
    )
    router = ZenohRouter().start()
    try:
        with RmwPublisher(router.locator, zenoh_domain, "/map", depth=2, form=form) as pub:
            pub.publish({"data": "m1"})
            async with (
                rmb.connect(router.locator, options=opts) as client,
                anyio.create_task_group() as tg,
            ):
                await seen_publisher(client, "/map")
                async with client.subscribe("/map", schema=STRING) as sub:
                    got = Collector(sub)
                    tg.start_soon(got.run)
                    await wait_until(lambda: got.data == ["m1"], timeout=10.0, what="m1")
                    router.stop()
                    await wait_until(
                        lambda: client.status == "reconnecting", timeout=10.0, what="reconnecting"
                    )
                    # published while nobody hears it: only the cache has it
                    pub.publish({"data": "m2"})
                    router = ZenohRouter(port=router.port).start()
                    await wait_until(
                        lambda: client.status == "connected", timeout=20, what="reconnected"
                    )
                    # the cache answers m1 (a duplicate, skipped) and m2
                    await wait_until(
                        lambda: "m2" in got.data and sub.stats.dropped_replay >= 1,
                        timeout=20.0,
                        what=lambda: f"m2 and m1 skipped: {got.data}, {sub.stats}",
                    )
                    assert got.data == ["m1", "m2"]
                tg.cancel_scope.cancel()
    finally:
        router.stop()


# -- our latched publisher ------------------------------------------------------------------
async def test_our_latched_topic_is_kept_for_a_client_that_joins_later(
    zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    opts = options(zenoh_domain)
    async with rmb.connect(zenoh_router.locator, options=opts) as publisher:
        await publisher.advertise("/robot_description", STRING, latch=True, queue_size=2)
        for text in ("v1", "v2", "v3"):
            await publisher.publish("/robot_description", STRING, {"data": text})
        await wait_until(
            lambda: kept(raw, zenoh_domain, "/robot_description") == ["v2", "v3"],
            timeout=10.0,
            what="the two kept",
        )
        # its token says TRANSIENT_LOCAL with the depth, as rmw_zenoh's would
        token = await publisher_token(raw, zenoh_domain)
        assert token.qos == rz.Qos(reliable=True, transient_local=True, depth=2)
        async with (
            rmb.connect(zenoh_router.locator, options=opts) as late,
            anyio.create_task_group() as tg,
        ):
            await seen_publisher(late, "/robot_description")
            async with late.subscribe("/robot_description", schema=STRING) as sub:
                got = Collector(sub)
                tg.start_soon(got.run)
                await wait_until(lambda: len(got.data) == 2, timeout=10.0, what="the kept two")
                assert got.data == ["v2", "v3"]
                await publisher.publish("/robot_description", STRING, {"data": "v4"})
                await wait_until(lambda: len(got.data) == 3, timeout=10.0, what="the live one")
                assert got.data == ["v2", "v3", "v4"]
                assert sub.stats.dropped_replay == 0
            tg.cancel_scope.cancel()


async def test_our_latched_topic_is_read_by_an_rmw_zenoh_subscriber_that_joins_later(
    zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await client.advertise("/map", STRING, latch=True)
        await client.publish("/map", STRING, {"data": "first"})
        await client.publish("/map", STRING, {"data": "kept"})
        await wait_until(lambda: kept(raw, zenoh_domain, "/map") == ["kept"], 10.0, "kept")
        gid = client._conn.adapter._pubs["/map"].gid  # type: ignore[attr-defined]
        with RmwSubscriber(zenoh_router.locator, zenoh_domain, "/map") as sub:
            await wait_until(lambda: sub.received, timeout=10.0, what="the kept message")
            assert [m.data for m in sub.messages()] == ["kept"]
            (attachment,) = [a for _, a in sub.received]
            assert rz.decode_attachment(attachment).gid == gid
            assert rz.decode_attachment(attachment).sequence == 2


async def test_our_latched_topic_is_read_by_a_late_zenoh_ros2_sdk_subscriber(
    sdk: Callable[..., Any], zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await client.advertise("/initialpose_note", STRING, latch=True)
        await client.publish("/initialpose_note", STRING, {"data": "set once"})
        topic = "/initialpose_note"
        await wait_until(lambda: kept(raw, zenoh_domain, topic) == ["set once"], 10.0, "kept")
        listener = sdk("listener", "--topic", "/initialpose_note", "--qos", ":1:,1:,:,:,,")
        await wait_until(listener.messages, timeout=15.0, what="the sdk listener's message")
        assert listener.messages() == [{"data": "set once"}]


async def test_best_effort_publishing_says_so_in_its_token_and_arrives(
    zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    opts = options(zenoh_domain)
    async with (
        rmb.connect(zenoh_router.locator, options=opts) as a,
        rmb.connect(zenoh_router.locator, options=opts) as b,
        b.subscribe("/scan_note", schema=STRING) as sub,
        anyio.create_task_group() as tg,
    ):
        await a.advertise("/scan_note", STRING, best_effort=True, queue_size=5)
        token = await publisher_token(raw, zenoh_domain)
        assert token.qos == rz.Qos(reliable=False, transient_local=False, depth=5)
        got = Collector(sub)
        tg.start_soon(got.run)
        with anyio.fail_after(10):
            while not got.data:
                await a.publish("/scan_note", STRING, {"data": "hi"})
                await anyio.sleep(0.05)
        assert set(got.data) == {"hi"}
        tg.cancel_scope.cancel()


async def test_a_reconnect_restores_the_latched_publisher_with_its_qos(zenoh_domain: int) -> None:
    from peers.zenoh_router import ZenohRouter

    opts = options(
        zenoh_domain,
        connect_timeout=2.0,
        keepalive_interval=0.2,
        keepalive_timeout=0.6,
        reconnect=rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.3),
    )
    router = ZenohRouter().start()
    try:
        async with rmb.connect(router.locator, options=opts) as client:
            await client.advertise("/map", STRING, latch=True, queue_size=3)
            router.stop()
            await wait_until(
                lambda: client.status == "reconnecting", timeout=10.0, what="reconnecting"
            )
            router = ZenohRouter(port=router.port).start()
            await wait_until(lambda: client.status == "connected", timeout=20, what="reconnected")
            await client.publish("/map", STRING, {"data": "after"})
            with RmwSubscriber(router.locator, zenoh_domain, "/map", depth=3) as sub:
                await wait_until(lambda: sub.received, timeout=10.0, what="the kept message")
                assert [m.data for m in sub.messages()] == ["after"]
                token = await publisher_token(sub.session, zenoh_domain)
                assert token.qos == rz.Qos(transient_local=True, depth=3)
    finally:
        router.stop()


async def test_publisher_options_are_checked_at_once(zenoh_router: Any, zenoh_domain: int) -> None:
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        with pytest.raises(ValueError, match="queue_size must be between 1 and 10000, got 0"):
            await client.advertise("/a", STRING, queue_size=0)
        with pytest.raises(TypeError, match="queue_size must be an int or None, not bool"):
            await client.advertise("/a", STRING, queue_size=True)
        with pytest.raises(TypeError, match="best_effort must be a bool"):
            await client.advertise("/a", STRING, best_effort="yes")  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="latch must be a bool"):
            await client.advertise("/a", STRING, latch=1)  # type: ignore[arg-type]
        assert client.topics == []  # nothing was advertised


async def test_foxglove_refuses_best_effort_and_latched_publishing(server: Any) -> None:
    async with rmb.connect(f"ws://127.0.0.1:{server.port}", protocol="foxglove-ws") as client:
        with pytest.raises(rmb.NotSupportedError, match="no best-effort publishing"):
            await client.advertise("/a", STRING, best_effort=True)
        with pytest.raises(rmb.NotSupportedError, match="no latched publishing"):
            await client.advertise("/a", STRING, latch=True)


async def test_a_subscription_to_our_own_latched_topic_gets_it_once(
    zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
        anyio.create_task_group() as tg,
    ):
        await client.advertise("/own", STRING, latch=True)
        await client.publish("/own", STRING, {"data": "mine"})
        await wait_until(lambda: kept(raw, zenoh_domain, "/own") == ["mine"], 10.0, "kept")
        async with client.subscribe("/own", schema=STRING) as sub:
            got = Collector(sub)
            tg.start_soon(got.run)
            await wait_until(lambda: got.data, timeout=10.0, what="our kept message")
            await client.publish("/own", STRING, {"data": "next"})
            await wait_until(lambda: len(got.data) == 2, timeout=10.0, what="the next one")
            assert got.data == ["mine", "next"]
        tg.cancel_scope.cancel()


async def test_a_cache_that_answers_more_than_its_depth_is_cut_and_counted(
    zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    """Hostile input: a session whose token says transient local, depth 1, and
    whose cache answers three samples: one is taken, two are counted."""
    zid = str(raw.zid())
    hash_ = type_hash(CodecRegistry(), STRING)
    key = rz.format_key(rz.TopicKey(zenoh_domain, "/flood", STRING, hash_))
    encode = CodecRegistry().encoder(STRING, "cdr")

    def answer(query: Any) -> None:
        for seq in (1, 2, 3):
            payload = bytes(encode({"data": f"s{seq}"}))
            query.reply(key, payload, attachment=rz.encode_attachment(seq, 1, bytes(16)))
        query.drop()

    token = rz.Token(
        zenoh_domain, zid, 0, 1, rz.EntityKind.PUBLISHER, "/", "/", "flooder",
        "/flood", STRING, hash_, rz.Qos(transient_local=True, depth=1),
    )  # fmt: skip
    queryable = raw.declare_queryable(f"{key}/@adv/pub/{zid}/1/_", answer, complete=True)
    live = raw.liveliness().declare_token(rz.format_token(token))
    try:
        async with (
            rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
            anyio.create_task_group() as tg,
        ):
            await seen_publisher(client, "/flood")
            async with client.subscribe("/flood", schema=STRING) as sub:
                got = Collector(sub)
                tg.start_soon(got.run)
                await wait_until(
                    lambda: client.rejections.get("history_overflow") == 2,
                    timeout=10.0,
                    what=lambda: f"two counted: {client.rejections}",
                )
                await wait_until(lambda: got.data, timeout=10.0, what="the one taken")
                assert got.data == ["s1"]
            tg.cancel_scope.cancel()
    finally:
        live.undeclare()
        queryable.undeclare()
