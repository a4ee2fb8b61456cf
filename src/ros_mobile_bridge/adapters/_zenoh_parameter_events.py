"""Parameter updates over Zenoh, as a mixin of :class:`~._zenoh.ZenohAdapter`:
every ROS node publishes its parameter changes on ``/parameter_events``
(``rcl_interfaces/msg/ParameterEvent``), so watching parameters is one
internal subscription to that topic, shared by every watched name.

Contract:

* :meth:`subscribe_parameters` adds names written ``/node:param`` (a
  ``ValueError`` at once for any other form) and declares the subscription
  when the first name is watched; :meth:`unsubscribe_parameters` removes
  names and undeclares it when none is left.
* Each event's new and changed parameters whose ``/node:param`` name is
  watched become one ``ParameterValues`` event; a watched deleted parameter
  is reported with the value ``None`` (as the Foxglove adapter reports a
  parameter the server sends without a value). Events naming no watched
  parameter are dropped quietly.
* As over Foxglove, watching reads no current value: the first update is
  the first change the node publishes after the watch began.
* A sample without a valid rmw_zenoh attachment, on another type or hash
  than ours, or that does not decode as a ``ParameterEvent`` is counted
  (``Client.rejections``) and skipped.
* The subscription is not one of the user's topic subscriptions: it has no
  route, no topic state and no stats of its own; after a reconnect the
  router restores the watch on the new adapter."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING

import anyio

from .._errors import DecodeError
from ..codec import CodecRegistry
from ..flow import Decoder
from ..transport._zenoh import ZenohSession
from ._parameter_events import PARAMETER_EVENT_TYPE, PARAMETER_EVENTS, by_node, watched_values
from ._seam import ParameterValues
from ._shared import EventSource
from ._zenoh_values import Subscription, valid_attachment

__all__ = ["PARAMETER_EVENTS", "PARAMETER_EVENT_TYPE", "ZenohParameterEvents"]


class ZenohParameterEvents:
    """Watching parameters through ``/parameter_events`` (a mixin of
    :class:`~._zenoh.ZenohAdapter`)."""

    _session: ZenohSession
    codecs: CodecRegistry
    domain: int
    _tags: Iterator[int]  # inbox tags
    _by_tag: dict[int, Subscription]
    _watched_parameters: set[str]
    _parameter_sub: Subscription | None
    _parameter_key: str  # the exact data key of our ParameterEvent type
    _parameter_decode: Decoder | None

    _events: EventSource

    if TYPE_CHECKING:  # the adapter's core and EventSource provide these

        def _key(self, name: str, type_name: str) -> str: ...

    def _init_parameter_events(self) -> None:
        self._watched_parameters = set()
        self._parameter_sub = None
        self._parameter_key = ""
        self._parameter_decode = None

    @property
    def parameter_events_subscribed(self) -> bool:
        """Whether the internal ``/parameter_events`` subscription exists
        (it does while at least one parameter is watched)."""
        return self._parameter_sub is not None

    async def subscribe_parameters(self, names: Sequence[str]) -> None:
        by_node(names)  # ValueError for a name that is not /node:param
        if self._parameter_sub is None and names:
            if self._parameter_decode is None:
                # the type's hash and decoder, built off the event loop (the
                # first build generates code)
                def build() -> tuple[str, Decoder]:
                    key = self._key(PARAMETER_EVENTS, PARAMETER_EVENT_TYPE)
                    return key, self.codecs.decoder(PARAMETER_EVENT_TYPE, "cdr")

                self._parameter_key, self._parameter_decode = await anyio.to_thread.run_sync(build)
            if self._parameter_sub is None:  # not declared meanwhile
                tag = next(self._tags)
                selector = f"{self.domain}/{PARAMETER_EVENTS.lstrip('/')}/*/*"
                handle = self._session.subscribe(selector, tag)
                sub = Subscription(PARAMETER_EVENTS, tag, handle, parameter_events=True)
                self._parameter_sub = sub
                self._by_tag[tag] = sub
        self._watched_parameters.update(names)

    async def unsubscribe_parameters(self, names: Sequence[str]) -> None:
        self._watched_parameters.difference_update(names)
        sub = self._parameter_sub
        if sub is not None and not self._watched_parameters:
            self._parameter_sub = None
            self._by_tag.pop(sub.tag, None)
            if sub.handle is not None:
                self._session.undeclare(sub.handle)

    def _on_parameter_event(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        """One ``/parameter_events`` sample (see the module's contract)."""
        if not valid_attachment(attachment):
            self._events.reject(
                "attachment", f"{PARAMETER_EVENTS}: a sample without a valid attachment"
            )
            return
        decode = self._parameter_decode
        if key != self._parameter_key or decode is None:
            self._events.reject(
                "malformed",
                f"{PARAMETER_EVENTS}: data key {key[:200]!r} is not {PARAMETER_EVENT_TYPE}",
            )
            return
        try:
            event = decode(memoryview(payload))
        except DecodeError as exc:
            self._events.reject("decode", f"{PARAMETER_EVENTS}: {exc}")
            return
        values = watched_values(event, self._watched_parameters)
        if values is None:
            self._events.reject("malformed", f"{PARAMETER_EVENTS}: not a {PARAMETER_EVENT_TYPE}")
        elif values:
            self._events.emit(ParameterValues(values))
