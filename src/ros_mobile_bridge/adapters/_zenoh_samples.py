"""The data samples of the user's subscriptions to frames
(:class:`ZenohSamples`, a part of :class:`~._zenoh.ZenohAdapter` its
reader hands every data sample to): the hot path of a Zenoh connection.

Contract:

* A sample's attachment must be one a released rmw_zenoh sends (the fixed
  33 bytes, or the older keyed form); otherwise it is counted
  (``attachment``) and skipped, as ``rmw_zenoh_cpp`` subscribers do.
* A sample's key names its type and RIHS01 hash: the first sample on a key
  is parsed (``malformed`` when it is not a data key of the topic and
  domain) and the key's decoder chosen: ours when our definition has the
  key's hash; while the robot is asked for the type's description
  (``_zenoh_describe``) the topic's samples are held, in order and bounded
  (``type_description_hold``, past it counted), and handed up when the
  fetch ends (:meth:`ZenohSamples.release`); with no definition that has
  the key's hash, the messages are delivered raw, with a warning.
  :data:`_MAX_KEYS_PER_TOPIC` keys per topic are cached.
* Each frame is appended to the :class:`~._shared.EventSource`'s
  ``pending`` list; the reader hands it up."""

from __future__ import annotations

import struct
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from .._errors import SchemaError
from ..flow import RawFrame
from ..wire import rmw_zenoh as rz
from ..wire._limits import truncate_for_log
from ._seam import Replayed
from ._zenoh_describe import ZenohDescriptions
from ._zenoh_node import ZenohNode
from ._zenoh_values import Subscription, fresh

__all__ = ["ZenohSamples"]

_FIXED: Final = rz.ATTACHMENT_SIZE
_GID_SIZE: Final = 16
_HEAD: Final = struct.Struct("<qqB")
"""The fixed attachment form's head: sequence number, source timestamp, gid length."""
_MAX_KEYS_PER_TOPIC: Final = 16
"""Distinct (type, hash) keys remembered per subscribed topic; a sample on a
further key is decoded without the cache (a hostile peer cannot grow it)."""
_HOLD: Final = object()
""":meth:`ZenohSamples._decoder_for`: hold the samples, the type is being fetched."""


@dataclass(slots=True)
class _Held:
    """The samples of one topic (key, payload, attachment), in order, held
    while the type of one of its keys is being described."""

    type_name: str
    type_hash: str
    samples: list[tuple[str, bytes, bytes | None]]


class ZenohSamples:
    """Data samples to :class:`~ros_mobile_bridge.flow.RawFrame`\\ s (see the
    module docstring)."""

    def __init__(
        self,
        node: ZenohNode,
        descriptions: ZenohDescriptions,
        subscriptions: Mapping[str, Subscription],
    ) -> None:
        """``subscriptions`` are the user's, by topic (the adapter's): where
        held samples go once their type is described."""
        self._events = node.events
        self._options = node.options
        self._log = node.log
        self._domain = node.domain
        self._codecs = node.codecs
        self._type_hash = node.type_hash
        self._descriptions = descriptions
        self._subs = subscriptions
        self._held: dict[str, _Held] = {}  # topic -> samples waiting for a description

    def on_samples(
        self, sub: Subscription, samples: list[rz.SampleData], receive_time_ns: int
    ) -> None:
        """A batch of one subscription's data samples to frames, in order.
        The common case is read here: a key seen before, the topic's type not
        being described, the fixed attachment form (one ``unpack_from``);
        anything else goes through :meth:`_on_sample`."""
        keys = sub.keys
        held = self._held
        topic = sub.topic
        unpack = _HEAD.unpack_from
        latched = sub.seen is not None  # each sample checked against the record
        for key, payload, attachment in samples:
            entry = keys.get(key)
            if (
                latched
                or entry is None
                or attachment is None
                or len(attachment) != _FIXED
                or (held and topic in held)
            ):
                self._on_sample(sub, key, payload, attachment, receive_time_ns)
                continue
            sequence, stamp, gid_size = unpack(attachment)
            if gid_size != _GID_SIZE:
                self._on_sample(sub, key, payload, attachment, receive_time_ns)
                continue
            # self._events.pending each time: an event handed up in between replaces it
            self._events.pending.append(
                RawFrame(
                    topic,
                    entry[0],
                    "cdr",
                    memoryview(payload),
                    stamp if stamp > 0 else None,
                    receive_time_ns,
                    entry[1],
                    sequence,
                )
            )

    def _on_sample(
        self,
        sub: Subscription,
        key: str,
        payload: bytes,
        attachment: bytes | None,
        receive_time_ns: int | None = None,
    ) -> None:
        """One data sample to a frame (or held, or skipped and counted): the
        general case of :meth:`on_samples`, and the held samples' replay."""
        if attachment is not None and len(attachment) == _FIXED and attachment[16] == _GID_SIZE:
            sequence, stamp, _ = _HEAD.unpack_from(attachment)
            gid = attachment[17:]
        else:  # the older keyed form, or nothing readable
            try:
                older = rz.decode_attachment(attachment)
            except rz.MalformedAttachment:
                self._events.reject(
                    "attachment",
                    f"{sub.topic}: a sample without a valid rmw_zenoh attachment "
                    f"({'none' if attachment is None else f'{len(attachment)} bytes'})",
                )
                return
            stamp, sequence, gid = older.timestamp_ns, older.sequence, older.gid
        if sub.seen is not None and not fresh(sub.seen, gid, sequence):
            self._events.emit(Replayed(sub.topic, len(payload)))  # delivered already
            return
        if self._held and sub.topic in self._held:  # its type is being described
            self._hold(sub.topic, self._held[sub.topic], key, payload, attachment)
            return
        entry = sub.keys.get(key)
        if entry is None:
            built = self._key_entry(sub.topic, key)
            if built is None:
                return
            if built[1] is _HOLD:
                parsed = rz.parse_key(key)
                held = self._held[sub.topic] = _Held(parsed.type_name, parsed.type_hash, [])
                self._hold(sub.topic, held, key, payload, attachment)
                return
            entry = built
            if len(sub.keys) < _MAX_KEYS_PER_TOPIC:
                sub.keys[key] = entry
        schema, decode = entry
        self._events.pending.append(
            RawFrame(
                sub.topic,
                schema,
                "cdr",
                memoryview(payload),
                stamp if stamp > 0 else None,
                time.time_ns() if receive_time_ns is None else receive_time_ns,
                decode,
                sequence,
            )
        )

    def on_kept(
        self, sub: Subscription, key: str, payload: bytes, attachment: bytes | None
    ) -> None:
        """A sample a transient-local publisher kept (a reply to a history
        query of ``_zenoh_latched``): checked and delivered as a live one."""
        self._on_sample(sub, key, payload, attachment)

    def _hold(
        self, topic: str, held: _Held, key: str, payload: bytes, attachment: bytes | None
    ) -> None:
        limit = self._options.type_description_hold
        if len(held.samples) >= limit:
            self._events.reject(
                "description_hold_overflow",
                f"{topic}: more than {limit} samples arrived "
                f"while the description of {held.type_name} was fetched "
                "(type_description_hold)",
            )
            return
        held.samples.append((key, payload, attachment))

    def reconsider(self, type_name: str, type_hash: str) -> None:
        """(type, hash) is being fetched again: the keys of that type whose
        samples went raw choose their decoder again at their next sample
        (held, then decoded once the fetch succeeds)."""
        for sub in self._subs.values():
            for key, (_schema, decode) in list(sub.keys.items()):
                if decode is not None:
                    continue
                try:
                    parsed = rz.parse_key(key)
                except rz.MalformedKey:
                    continue
                if (parsed.type_name, parsed.type_hash) == (type_name, type_hash):
                    del sub.keys[key]

    def release(self, type_name: str, type_hash: str) -> None:
        """A fetch of (type, hash) ended: the samples held for it are decoded
        (or delivered raw, when it failed), in order, and handed up."""
        for topic, held in list(self._held.items()):
            if (held.type_name, held.type_hash) != (type_name, type_hash):
                continue
            del self._held[topic]
            sub = self._subs.get(topic)
            if sub is None:
                continue
            for key, payload, attachment in held.samples:
                self._on_sample(sub, key, payload, attachment)
        self._events.post()

    def forget(self, topic: str) -> None:
        """``topic`` is no longer subscribed: drop what is held for it."""
        self._held.pop(topic, None)

    def _key_entry(self, topic: str, key: str) -> tuple[str, Any] | None:
        """The type and decoder for samples on ``key``; None (counted) for a
        key that is not a well-formed rmw_zenoh data key of ``topic``."""
        try:
            parsed = rz.parse_key(key)
        except rz.MalformedKey as exc:
            self._events.reject("malformed", f"{topic}: data key {key!r}: {exc}")
            return None
        if parsed.name != topic or parsed.domain != self._domain:
            self._events.reject("malformed", f"{topic}: data key {key!r} names another topic")
            return None
        return parsed.type_name, self._decoder_for(parsed)

    def _decoder_for(self, parsed: rz.TopicKey) -> Any:
        """A decoder when we know a definition whose hash is the key's;
        :data:`_HOLD` while the robot is asked for it (hold the samples);
        None (messages delivered raw, with a warning) otherwise: decoding
        with another definition of the same name would deliver garbage."""
        descriptions = self._descriptions
        if descriptions.knows(parsed.type_name, parsed.type_hash):
            return self._codecs.decoder(parsed.type_name, "cdr")
        name, hash_ = parsed.type_name, parsed.type_hash
        if (
            descriptions.failed(name, hash_) is None
            and descriptions.describers(name, hash_)
            and descriptions.want(name, hash_)
        ):
            return _HOLD
        try:
            ours = self._type_hash(parsed.type_name)
            if ours != parsed.type_hash:
                self._log.warning(
                    "%s: the publisher's %s has hash %s, ours %s (another definition);"
                    " messages are delivered raw",
                    parsed.name,
                    parsed.type_name,
                    parsed.type_hash,
                    ours,
                )
                return None
            return self._codecs.decoder(parsed.type_name, "cdr")
        except SchemaError as exc:
            self._log.warning(
                "%s: no decoder for %s, messages will be delivered raw: %s",
                parsed.name,
                parsed.type_name,
                truncate_for_log(str(exc)),
            )
            return None
