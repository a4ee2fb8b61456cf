"""Transient-local (latched) publishers in the forms released ``rmw_zenoh_cpp``
versions give them, and a subscriber of the current form, built from raw
eclipse-zenoh: the stand-ins for ROS 2 nodes on rmw_zenoh in the
latched-topic tests.

No ``rmw_zenoh_cpp`` build is reachable here, and zenoh-ros2-sdk's
publishers keep no history (its ``ROS2Publisher`` is a plain zenoh publisher
whatever its QoS), so these follow, part for part, what rmw_zenoh's
``rmw_publisher_data.cpp`` and ``rmw_subscription_data.cpp`` declare at
its release tags (see ``ros_mobile_bridge/adapters/_zenoh_latched.py`` for
the versions):

* ``form="advanced"`` (Jazzy 0.2.2 and later, Kilted, Rolling 0.4.0 and
  later): zenoh-ext's advanced publisher on the data key, with a cache of
  ``depth`` samples and publisher detection when the QoS is transient local,
  a sporadic 500 ms heartbeat when it is also reliable; samples carry the
  33-byte attachment of Jazzy 0.2.4 and later.
* ``form="publication_cache"`` (Jazzy 0.2.0 and 0.2.1, Rolling 0.3.x): a
  plain publisher and zenoh-ext's ``PublicationCache`` with history =
  ``depth``, a complete queryable and the queryable prefix = the session's
  zid. The Python wheel has no ``PublicationCache``, so a complete queryable
  on ``<zid>/<data key>`` answers the last ``depth`` samples on their own
  key, as it does; samples carry the 77-byte keyed attachment those
  releases send.

The liveliness token is written here by hand in rmw_zenoh's form
(``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/MP/%/%/<node>/<topic>/<DDS
type>/<hash>/<qos>``), the QoS part as its ``qos_to_keyexpr`` writes it:
reliability and durability empty when default (reliable, volatile), ``1``
for TRANSIENT_LOCAL, ``2`` for BEST_EFFORT, then ``,<depth>``. The gid is
rmw_zenoh's (XXH3-128 of the token key). The CDR payloads come from this
project's codec (what they hold is not under test here)."""

from __future__ import annotations

import collections
import json
import struct
import threading
import time
from typing import Any

from ros_mobile_bridge.codec import CodecRegistry, type_hash
from ros_mobile_bridge.wire import rmw_zenoh as rz

_FIXED = struct.Struct("<qqB16s")
_KEYED = struct.Struct("<16sq17sq12s16s")


def _session(locator: str) -> Any:
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([locator]))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("timestamping/enabled", "true")  # as rmw_zenoh's session config
    return zenoh.open(config)


def _names(domain: int, topic: str, type_name: str) -> tuple[str, str, str]:
    """(data key, DDS type name, hash) as rmw_zenoh writes them."""
    pkg, kind, name = type_name.split("/")
    dds = f"{pkg}::{kind}::dds_::{name}_"
    hash_ = type_hash(CodecRegistry(), type_name)
    return f"{domain}/{topic.lstrip('/')}/{dds}/{hash_}", dds, hash_


def qos_part(*, reliable: bool, transient_local: bool, depth: int) -> str:
    """The token's QoS part, as rmw_zenoh's ``qos_to_keyexpr`` writes it."""
    return f"{'' if reliable else '2'}:{'1' if transient_local else ''}:,{depth}:,:,:,,"


class RmwPublisher:
    """One rmw_zenoh publisher (see the module docstring) in its own client
    session; ``publish(fields)``, ``close()``; a context manager."""

    def __init__(
        self,
        locator: str,
        domain: int,
        topic: str,
        type_name: str = "std_msgs/msg/String",
        *,
        depth: int = 1,
        form: str = "advanced",
        transient_local: bool = True,
        reliable: bool = True,
        cache: bool | None = None,
        node: str = "latched_talker",
    ) -> None:
        """``cache`` (default: ``transient_local``) keeps the history whatever
        the token says (a publisher whose token says VOLATILE and that keeps
        samples all the same: nobody should ask it)."""
        import zenoh
        import zenoh.ext as zext

        if form not in ("advanced", "publication_cache"):
            raise ValueError(form)
        keep = transient_local if cache is None else cache
        self._session = session = _session(locator)
        self.zid = str(session.zid())
        self.key, dds, hash_ = _names(domain, topic, type_name)
        self._encode = CodecRegistry().encoder(type_name, "cdr")
        self._form = form
        qos = qos_part(reliable=reliable, transient_local=transient_local, depth=depth)
        self.token_key = f"@ros2_lv/{domain}/{self.zid}/0/10/MP/%/%/{node}/{rz.mangle(topic)}/{dds}/{hash_}/{qos}"
        self.gid = rz.entity_gid(self.token_key)
        self._seq = 0
        self._kept: collections.deque[tuple[bytes, bytes]] = collections.deque(maxlen=depth)
        self._lock = threading.Lock()
        self._declared: list[Any] = []
        reliability = zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT
        if form == "advanced":
            self._pub = zext.declare_advanced_publisher(
                session,
                self.key,
                reliability=reliability,
                congestion_control=zenoh.CongestionControl.DROP,
                cache=zext.CacheConfig(depth) if keep else None,
                publisher_detection=keep or None,
                sample_miss_detection=(
                    zext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=0.5)
                    if keep and reliable
                    else None
                ),
            )
        else:
            if keep:
                self._declared.append(
                    session.declare_queryable(f"{self.zid}/{self.key}", self._answer, complete=True)
                )
            self._pub = session.declare_publisher(
                self.key, reliability=reliability, congestion_control=zenoh.CongestionControl.DROP
            )
        self._declared.append(self._pub)
        self._declared.append(session.liveliness().declare_token(self.token_key))

    def _answer(self, query: Any) -> None:
        with self._lock:
            kept = list(self._kept)
        for payload, attachment in kept:
            query.reply(self.key, payload, attachment=attachment)
        query.drop()

    def publish(self, fields: dict[str, Any]) -> int:
        """Put one message; returns its sequence number (from 1, as rmw_zenoh)."""
        self._seq += 1
        stamp = time.time_ns()
        if self._form == "advanced":
            attachment = _FIXED.pack(self._seq, stamp, 16, self.gid)
        else:
            attachment = _KEYED.pack(
                b"\x0fsequence_number", self._seq, b"\x10source_timestamp", stamp,
                b"\x0asource_gid\x10", self.gid,
            )  # fmt: skip
        payload = bytes(self._encode(fields))
        self._pub.put(payload, attachment=attachment)
        with self._lock:
            self._kept.append((payload, attachment))
        return self._seq

    def close(self) -> None:
        for declared in reversed(self._declared):
            declared.undeclare()
        self._declared.clear()
        self._session.close()

    def __enter__(self) -> RmwPublisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RmwSubscriber:
    """An rmw_zenoh transient-local subscription of the current releases:
    zenoh-ext's advanced subscriber with history (late publishers detected,
    ``depth`` samples each) and recovery by heartbeat, as a RELIABLE +
    TRANSIENT_LOCAL one is made. ``received`` lists (payload, attachment) in
    arrival order; ``session`` is its zenoh session."""

    def __init__(
        self,
        locator: str,
        domain: int,
        topic: str,
        type_name: str = "std_msgs/msg/String",
        *,
        depth: int = 1,
    ) -> None:
        import zenoh.ext as zext

        self.session = session = _session(locator)
        self.key, _dds, _hash = _names(domain, topic, type_name)
        self.received: list[tuple[bytes, bytes | None]] = []
        self._lock = threading.Lock()
        self._sub = zext.declare_advanced_subscriber(
            session,
            self.key,
            self._on_sample,
            history=zext.HistoryConfig(detect_late_publishers=True, max_samples=depth),
            recovery=zext.RecoveryConfig(periodic_queries=None, heartbeat=True),
            subscriber_detection=True,
        )

    def _on_sample(self, sample: Any) -> None:
        attachment = sample.attachment
        with self._lock:
            self.received.append(
                (sample.payload.to_bytes(), None if attachment is None else attachment.to_bytes())
            )

    def messages(self, type_name: str = "std_msgs/msg/String") -> list[Any]:
        """What arrived so far, decoded (this project's codec)."""
        decode = CodecRegistry().decoder(type_name, "cdr")
        with self._lock:
            return [decode(memoryview(payload)) for payload, _ in self.received]

    def close(self) -> None:
        self._sub.undeclare()
        self.session.close()

    def __enter__(self) -> RmwSubscriber:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
