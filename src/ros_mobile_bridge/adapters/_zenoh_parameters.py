"""Parameters over Zenoh (:class:`ZenohParameters`, the parameters part of
:class:`~._zenoh.ZenohAdapter`). Each ROS node serves its own parameters:
the ``rcl_interfaces`` services under its name (``list_parameters``,
``get_parameters``, ``set_parameters``), called through the connection's
query engine; names are written ``/node:param`` as over rosbridge. Every
node publishes its parameter changes on ``/parameter_events``
(``rcl_interfaces/msg/ParameterEvent``), so watching parameters is one
internal subscription to that topic, shared by every watched name.

Contract:

* :meth:`~ZenohParameters.get_parameters` of no names lists every node
  that serves ``list_parameters``; a name on a node that serves no
  ``get_parameters`` is absent from the answer.
* :meth:`~ZenohParameters.set_parameters` sets every value on its node (one
  ``set_parameters`` call per node; rcl applies each parameter on its own)
  and raises ``ParameterError`` after all of them with each refused name.
* :meth:`~ZenohParameters.subscribe_parameters` adds names written
  ``/node:param`` (a ``ValueError`` at once for any other form) and
  declares the subscription when the first name is watched;
  :meth:`~ZenohParameters.unsubscribe_parameters` removes names and
  undeclares it when none is left.
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

from collections.abc import Mapping, Sequence
from typing import Any

import anyio

from .._errors import DecodeError, ParameterError, ServiceError
from ..flow import Decoder
from ..wire import rmw_zenoh as rz
from ._parameter_events import PARAMETER_EVENT_TYPE, PARAMETER_EVENTS, by_node, watched_values
from ._seam import ParameterValues
from ._zenoh_calls import ZenohQueries
from ._zenoh_node import ZenohNode
from ._zenoh_values import (
    Subscription,
    parameter_from_ros,
    parameter_to_ros,
    ros_field,
    valid_attachment,
)

__all__ = ["PARAMETER_EVENTS", "PARAMETER_EVENT_TYPE", "ZenohParameters"]


class ZenohParameters:
    """Reading, setting and watching the nodes' parameters (see the module
    docstring and :class:`~._seam.ParameterAccess`). The adapter's reader
    hands the ``/parameter_events`` samples to :meth:`on_samples`."""

    def __init__(self, node: ZenohNode, queries: ZenohQueries) -> None:
        self._node = node
        self._session = node.session
        self._graph = node.graph
        self._events = node.events
        self._queries = queries
        self._watched: set[str] = set()
        self._sub: Subscription | None = None
        self._key = ""  # the exact data key of our ParameterEvent type
        self._decode: Decoder | None = None

    # -- the nodes' services ----------------------------------------------------------------
    async def _node_call(self, node: str, service: str, request: Any) -> Any:
        name = f"{node}/{service}"
        srv_type = self._graph.service_type(name)
        if srv_type is None:
            raise ServiceError(name, f"node {node} offers no {service} service")
        timeout = self._node.options.service_timeout
        return await self._queries.request(name, srv_type, request, timeout)

    def _parameter_nodes(self) -> list[str]:
        suffix = "/list_parameters"
        return sorted(
            info.name[: -len(suffix)]
            for info in self._graph.service_infos
            if info.name.endswith(suffix) and info.type.endswith("/ListParameters")
        )

    async def get_parameters(self, names: Sequence[str]) -> dict[str, Any]:
        if not names:
            listed: list[str] = []
            for node in self._parameter_nodes():
                answer = await self._node_call(node, "list_parameters", {})
                found = ros_field(ros_field(answer, "result"), "names") or []
                listed.extend(f"{node}:{param}" for param in found)
            names = listed
        values: dict[str, Any] = {}
        for node, params in by_node(names).items():
            if self._graph.service_type(f"{node}/get_parameters") is None:
                continue  # no such node: absent here, the client raises ParameterError for it
            answer = await self._node_call(node, "get_parameters", {"names": params})
            for param, value in zip(params, ros_field(answer, "values") or (), strict=False):
                known, plain = parameter_from_ros(value)
                if known:
                    values[f"{node}:{param}"] = plain
        return values

    async def set_parameters(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Set every value on its node (one ``set_parameters`` call per node;
        rcl applies each parameter on its own); ``ParameterError`` after all
        of them with each refused name and the node's reason, and a name on
        a node that does not serve parameters as not found."""
        reasons: dict[str, str] = {}
        for node, params in by_node(list(values)).items():
            if self._graph.service_type(f"{node}/set_parameters") is None:
                reasons.update({f"{node}:{p}": f"not found (no node {node})" for p in params})
                continue
            request = {
                "parameters": [
                    {"name": param, "value": parameter_to_ros(values[f"{node}:{param}"])}
                    for param in params
                ]
            }
            answer = await self._node_call(node, "set_parameters", request)
            for param, result in zip(params, ros_field(answer, "results") or (), strict=False):
                if not ros_field(result, "successful"):
                    reasons[f"{node}:{param}"] = ros_field(result, "reason") or "refused"
        after = await self.get_parameters(list(values))
        if reasons:
            raise ParameterError(reasons, after)
        return after

    # -- watching: /parameter_events --------------------------------------------------------
    @property
    def parameter_events_subscribed(self) -> bool:
        """Whether the internal ``/parameter_events`` subscription exists
        (it does while at least one parameter is watched)."""
        return self._sub is not None

    async def subscribe_parameters(self, names: Sequence[str]) -> None:
        by_node(names)  # ValueError for a name that is not /node:param
        if self._sub is None and names:
            if self._decode is None:
                # the type's hash and decoder, built off the event loop (the
                # first build generates code)
                node = self._node

                def build() -> tuple[str, Decoder]:
                    key = node.key(PARAMETER_EVENTS, PARAMETER_EVENT_TYPE)
                    return key, node.codecs.decoder(PARAMETER_EVENT_TYPE, "cdr")

                self._key, self._decode = await anyio.to_thread.run_sync(build)
            if self._sub is None:  # not declared meanwhile
                tag = self._node.new_tag()
                handle = self._session.subscribe(self._node.data_selector(PARAMETER_EVENTS), tag)
                sub = Subscription(PARAMETER_EVENTS, tag, handle, parameter_events=True)
                self._sub = sub
                self._node.routes[tag] = sub
        self._watched.update(names)

    async def unsubscribe_parameters(self, names: Sequence[str]) -> None:
        self._watched.difference_update(names)
        sub = self._sub
        if sub is not None and not self._watched:
            self._sub = None
            self._node.routes.pop(sub.tag, None)
            if sub.handle is not None:
                self._session.undeclare(sub.handle)

    def on_samples(self, samples: list[rz.SampleData]) -> None:
        """The ``/parameter_events`` samples of one inbox item, in order."""
        for key, payload, attachment in samples:
            self._on_parameter_event(key, payload, attachment)

    def _on_parameter_event(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        """One ``/parameter_events`` sample (see the module's contract)."""
        if not valid_attachment(attachment):
            self._events.reject(
                "attachment", f"{PARAMETER_EVENTS}: a sample without a valid attachment"
            )
            return
        decode = self._decode
        if key != self._key or decode is None:
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
        values = watched_values(event, self._watched)
        if values is None:
            self._events.reject("malformed", f"{PARAMETER_EVENTS}: not a {PARAMETER_EVENT_TYPE}")
        elif values:
            self._events.emit(ParameterValues(values))
