"""Parameters over rosbridge, the parameters part of
:class:`~._rosbridge.RosbridgeAdapter`:
read and written through the bridge's ``/rosapi/*_param*`` services, and
watched through the nodes' ``/parameter_events``
(``rcl_interfaces/msg/ParameterEvent``), which every rclpy and rclcpp node
publishes on each change.

Contract of the watch:

* :meth:`~RosbridgeParameters.subscribe_parameters` adds names written
  ``/node:param`` (a ``ValueError`` at once for any other form), the form
  ``get_parameters`` and ``set_parameters`` use; the first watched name
  sends one ``subscribe`` to ``/parameter_events`` with an id of its own,
  and :meth:`~RosbridgeParameters.unsubscribe_parameters` unsubscribes that
  id when no name is left.
* The subscription is not one of the user's topic subscriptions (no route,
  no topic state, no stats). A user subscription to ``/parameter_events``
  lives beside it: the bridge sends one message per topic to a client, so
  each message feeds both; the watch asks for the user's compression and,
  when it ends, sends the user's ``subscribe`` again (and when the user's
  ends, the watch's again), so neither changes the other's encoding.
* Each event's new and changed watched parameters become one
  ``ParameterValues`` event, their values converted as ``get_parameters``
  returns them (plain JSON values); a watched deleted parameter is reported
  as ``None``. Events naming no watched parameter are dropped quietly.
* As over Foxglove and Zenoh, watching reads no current value.
* A message that does not decode, or is not a ``ParameterEvent``, is
  counted (``Client.rejections``: ``decode``, ``malformed``) and skipped.
* After a reconnect the router restores the watch on the new adapter."""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import Any, Protocol

from .._errors import DecodeError, ParameterError, SchemaError
from .._options import ClientOptions
from ..codec import CodecRegistry
from ..flow import Decoder
from ..transport import WebSocket
from ..wire import rosbridge as rb
from ._parameter_events import PARAMETER_EVENT_TYPE, PARAMETER_EVENTS, by_node, watched_values
from ._rosbridge_calls import RosbridgeCalls
from ._rosbridge_discovery import names_in
from ._seam import ParameterValues
from ._shared import EventSource


class SentSubscription(Protocol):
    """What the adapter sent for a subscription (its ``_WireSub``)."""

    @property
    def id(self) -> str: ...
    @property
    def type(self) -> str | None: ...
    @property
    def throttle_rate(self) -> int: ...
    @property
    def queue_length(self) -> int: ...
    @property
    def compression(self) -> str | None: ...


class RosbridgeParameters:
    """Getting, setting and watching parameters (``Adapter.parameters``)."""

    def __init__(
        self,
        ws: WebSocket,
        engine: rb.RosbridgeEngine,
        calls: RosbridgeCalls,
        codecs: CodecRegistry,
        events: EventSource,
        options: ClientOptions,
        *,
        subscriptions: Mapping[str, SentSubscription],
        decoders: Mapping[tuple[str, str], Decoder | None],
        send_subscribe: Callable[[str, SentSubscription], Awaitable[None]],
    ) -> None:
        """``subscriptions`` and ``decoders`` are the adapter's tables of
        the user's subscriptions (read only: the watch follows the user's
        ``/parameter_events`` encoding), ``send_subscribe`` sends one of
        them again."""
        self._ws = ws
        self._engine = engine
        self._calls = calls
        self._codecs = codecs
        self._events = events
        self._options = options
        self._subs = subscriptions
        self._decoders = decoders
        self._send_subscribe = send_subscribe
        self._watched: set[str] = set()
        self._sub_id: str | None = None  # the watch's subscribe id while it exists

    async def get_parameters(self, names: Sequence[str]) -> dict[str, Any]:
        if not names:
            answer = await self._param_call("/rosapi/get_param_names", {})
            names = names_in(answer, "names")
        values: dict[str, Any] = {}
        for name in names:
            answer = await self._param_call("/rosapi/get_param", {"name": name})
            if not isinstance(answer, dict) or answer.get("successful") is False:
                continue  # "Parameter not found": the client raises ParameterError for it
            raw = answer.get("value")
            if isinstance(raw, str) and raw:
                try:  # the value is a JSON document in a string
                    values[name] = json.loads(raw)
                except ValueError:
                    values[name] = raw
        return values

    async def set_parameters(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Set each value through ``/rosapi/set_param``; ``ParameterError``
        after all of them with each refused name and the bridge's reason."""
        reasons: dict[str, str] = {}
        for name, value in values.items():
            answer = await self._param_call(
                "/rosapi/set_param", {"name": name, "value": json.dumps(value)}
            )
            if isinstance(answer, dict) and answer.get("successful") is False:
                reasons[name] = str(answer.get("reason") or "refused")
        after = await self.get_parameters(list(values))
        if reasons:
            raise ParameterError(reasons, after)
        return after

    async def _param_call(self, service: str, args: Any) -> Any:
        return await self._calls.call(service, args, self._options.service_timeout)

    # -- watching: /parameter_events ------------------------------------------------
    @property
    def parameter_events_subscribed(self) -> bool:
        """Whether the watch's ``/parameter_events`` subscription exists (it
        does while at least one parameter is watched)."""
        return self._sub_id is not None

    async def subscribe_parameters(self, names: Sequence[str]) -> None:
        by_node(names)  # ValueError for a name that is not /node:param
        if self._sub_id is None and names:
            sub_id = self._calls.next_id(f"subscribe:{PARAMETER_EVENTS}:parameters")
            self._sub_id = sub_id
            try:
                await self._send_parameter_subscribe(sub_id)
            except BaseException:
                self._sub_id = None
                raise
        self._watched.update(names)

    async def unsubscribe_parameters(self, names: Sequence[str]) -> None:
        self._watched.difference_update(names)
        sub_id = self._sub_id
        if sub_id is None or self._watched:
            return
        self._sub_id = None
        if self._ws.closed:
            return
        await self._ws.send(self._engine.unsubscribe(PARAMETER_EVENTS, id=sub_id))
        user = self._subs.get(PARAMETER_EVENTS)
        if user is not None:  # its encoding again (the engine forgot cbor-raw)
            await self._send_subscribe(PARAMETER_EVENTS, user)

    async def _send_parameter_subscribe(self, sub_id: str) -> None:
        """The watch's ``subscribe``, in the user's compression when the user
        subscribes to ``/parameter_events`` too (the bridge keeps one
        encoding per topic: the last asked for)."""
        user = self._subs.get(PARAMETER_EVENTS)
        await self._ws.send(
            self._engine.subscribe(
                PARAMETER_EVENTS,
                id=sub_id,
                type=PARAMETER_EVENT_TYPE,
                compression=user.compression if user is not None else None,
            )
        )

    async def user_left_parameter_events(self) -> None:
        """The user's subscription to ``/parameter_events`` ended: while the
        watch lives, ask for its own encoding again."""
        sub_id = self._sub_id
        if sub_id is not None and not self._ws.closed:
            await self._send_parameter_subscribe(sub_id)

    def on_parameter_event(self, event: rb.Publish) -> None:
        """One message on ``/parameter_events`` while the watch lives (see
        the module's contract), whatever its encoding."""
        kind = event.kind
        try:
            if kind == "parsed":
                message = event.message
            elif kind == "json":
                message = rb.decode_json_msg(event.payload)
            elif kind == "cbor":
                message = rb.decode_cbor_msg(event.payload)
            else:  # cbor-raw, asked for by the user's subscription
                decode = self._decoders.get((PARAMETER_EVENTS, kind))
                if decode is None:  # the user's is not built yet
                    decode = self._codecs.decoder(PARAMETER_EVENT_TYPE, "cdr")
                message = decode(event.payload)
        except (DecodeError, SchemaError, ValueError, RecursionError) as exc:
            self._events.reject("decode", f"{PARAMETER_EVENTS}: {exc}")
            return
        values = watched_values(message, self._watched)
        if values is None:
            self._events.reject("malformed", f"{PARAMETER_EVENTS}: not a {PARAMETER_EVENT_TYPE}")
        elif values:
            self._events.emit(ParameterValues(values))
