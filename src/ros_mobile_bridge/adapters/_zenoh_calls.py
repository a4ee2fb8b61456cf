"""What the Zenoh adapter asks with queries, as a mixin of
:class:`~._zenoh.ZenohAdapter`: service calls (a zenoh ``get`` on the
service key with rmw_zenoh's attachment), actions (their ``_action/``
services and feedback topic) and parameters (the nodes' ``rcl_interfaces``
services). The adapter's core (``adapters/_zenoh.py``) owns the state these
methods use, declared on :class:`ZenohCalls`, and routes each query's
replies and each feedback sample back here."""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Final

from .._errors import ActionGoalError, DecodeError, ParameterError, SchemaError, ServiceError
from .._options import ClientOptions
from .._types import ServiceInfo
from ..codec import CodecRegistry
from ..flow import Decoder, PendingRequests
from ..transport._zenoh import ZenohSession
from ..wire import rmw_zenoh as rz
from ._seam import GoalEvents
from ._shared import EventSource
from ._zenoh_values import (
    Goal,
    Query,
    Subscription,
    by_node,
    parameter_from_ros,
    parameter_to_ros,
    ros_field,
    split_type,
    valid_attachment,
)

__all__ = ["ZenohCalls"]

_RESULT_TIMEOUT: Final = 24 * 3600.0
"""How long a goal's ``get_result`` query may wait (the goal's own life)."""
_GOAL_SUCCEEDED: Final = 4
_MAX_RESULT_QUERIES: Final = 4
"""How many times a goal's ``get_result`` query is sent when the earlier ones
ended without a reply while the action server stayed in the graph."""


async def _noop() -> None:
    return None


class ZenohCalls:
    """Services, actions and parameters over zenoh queries (a mixin of
    :class:`~._zenoh.ZenohAdapter`, which sets up the state below)."""

    _session: ZenohSession
    _options: ClientOptions
    codecs: CodecRegistry
    domain: int
    _ids: Iterator[int]  # node and entity ids
    _tags: Iterator[int]  # inbox tags
    _service_infos: list[ServiceInfo]
    _by_tag: dict[int, Subscription]
    _client_gids: dict[str, tuple[bytes, int]]  # service -> (gid, token)
    _call_seq: Iterator[int]
    _queries: dict[int, Query]
    _calls: PendingRequests[list[tuple[bool, bytes, bytes | None]]]
    _goals: dict[bytes, Goal]
    _feedback_subs: dict[str, Subscription]

    _events: EventSource

    if TYPE_CHECKING:  # the adapter's core and EventSource provide these

        def _service_type(self, name: str) -> str | None: ...
        def _type_hash(self, type_name: str) -> str: ...
        def _token_key(self, kind: rz.EntityKind, entity_id: int, **kw: Any) -> str: ...
        def _graph_hash(
            self, name: str, kinds: tuple[rz.EntityKind, ...]
        ) -> tuple[str, str] | None: ...
        async def _ensure_described(self, type_name: str, type_hash: str) -> None: ...

    async def _describe_entity(self, name: str, kind: rz.EntityKind) -> None:
        """Learn the type of the graph's entity ``name`` from its node when
        our definition lacks it or hashes differently (``_zenoh_describe``);
        ``SchemaError`` when it cannot be learnt."""
        announced = self._graph_hash(name, (kind,))
        if announced is not None:
            await self._ensure_described(*announced)

    # -- services ---------------------------------------------------------------------------
    def _client_identity(self, service: str, srv_type: str, hash_: str) -> bytes:
        known = self._client_gids.get(service)
        if known is not None:
            return known[0]
        key = self._token_key(
            rz.EntityKind.CLIENT,
            next(self._ids),
            name=service,
            type_name=srv_type,
            hash_=hash_,
            qos=rz.Qos(),
        )
        gid = rz.entity_gid(key)
        self._client_gids[service] = (gid, self._session.declare_token(key))
        return gid

    def _check_pending(self, what: str, *, goal: bool = False) -> None:
        limit = self._options.max_pending_requests
        if len(self._calls) + len(self._goals) >= limit:
            reason = f"{limit} requests already wait for an answer (max_pending_requests)"
            raise ActionGoalError(what, reason) if goal else ServiceError(what, reason)

    def _start_query(
        self,
        service: str,
        srv_type: str,
        payload: bytes,
        timeout: float,
        on_done: Callable[[list[tuple[bool, bytes, bytes | None]]], None] | None = None,
    ) -> int:
        try:
            hash_ = self._type_hash(srv_type)
        except SchemaError as exc:
            raise ServiceError(service, f"cannot compute the type hash: {exc}") from exc
        key = rz.format_key(rz.TopicKey(self.domain, service, srv_type, hash_))
        gid = self._client_identity(service, srv_type, hash_)
        attachment = rz.encode_attachment(next(self._call_seq), time.time_ns(), gid)
        query_id = self._session.query(key, payload=payload, attachment=attachment, timeout=timeout)
        self._queries[query_id] = Query(service, on_done=on_done)
        return query_id

    async def _request(self, service: str, srv_type: str, request: Any, timeout: float) -> Any:
        """Call ``service`` (of type ``srv_type``) and return the decoded
        response; ``ServiceError`` with the reason otherwise."""
        req_name, res_name = CodecRegistry.service_type_names(srv_type)
        try:
            payload = self.codecs.encoder(req_name, "cdr")(request if request is not None else {})
            decode = self.codecs.decoder(res_name, "cdr")
        except SchemaError as exc:
            raise ServiceError(service, f"no definition of {srv_type}: {exc}") from exc
        self._check_pending(service)
        query_id = self._start_query(service, srv_type, payload, timeout)
        replies = await self._calls.request(query_id, _noop)
        for ok, body, _attachment in replies:
            if not ok:
                text = body.decode("utf-8", "replace")
                raise ServiceError(service, f"the server replied with an error: {text}")
            try:
                return decode(memoryview(body))
            except DecodeError as exc:
                raise ServiceError(service, f"the response does not decode: {exc}") from exc
        raise ServiceError(service, f"no reply within {timeout:g} s")

    async def call_service(self, name: str, request: Any, timeout: float) -> Any:
        srv_type = self._service_type(name)
        if srv_type is None:
            raise ServiceError(name, "no server offers this service on this domain")
        await self._describe_entity(name, rz.EntityKind.SERVICE)
        return await self._request(name, srv_type, request, timeout)

    # -- actions ----------------------------------------------------------------------------
    async def send_action_goal(
        self, action: str, action_type: str, goal: Any, events: GoalEvents
    ) -> str:
        pkg, _, name = split_type(action_type, "action")
        base = f"{pkg}/action/{name}"
        send_goal = f"{action}/_action/send_goal"
        if self._service_type(send_goal) is None:
            raise ActionGoalError(action, "no action server offers it")
        self._check_pending(action, goal=True)
        await self._describe_entity(send_goal, rz.EntityKind.SERVICE)
        await self._describe_entity(f"{action}/_action/get_result", rz.EntityKind.SERVICE)
        await self._describe_entity(f"{action}/_action/feedback", rz.EntityKind.PUBLISHER)
        try:
            feedback_decode: Decoder | None = self.codecs.decoder(f"{base}_FeedbackMessage", "cdr")
        except SchemaError as exc:
            raise ActionGoalError(action, f"no definition of {action_type}: {exc}") from exc
        goal_uuid = uuid.uuid4().bytes
        uuid_msg = {"uuid": list(goal_uuid)}
        await self._ensure_feedback(action, base)
        handle = Goal(action, base, goal_uuid, events, feedback_decode)
        self._goals[goal_uuid] = handle
        try:
            answer = await self._request(
                send_goal,
                f"{base}_SendGoal",
                {"goal_id": uuid_msg, "goal": goal},
                self._options.service_timeout,
            )
        except ServiceError as exc:
            self._goals.pop(goal_uuid, None)
            raise ActionGoalError(action, exc.reason) from exc
        except BaseException:
            self._goals.pop(goal_uuid, None)
            raise
        if not ros_field(answer, "accepted"):
            self._goals.pop(goal_uuid, None)
            raise ActionGoalError(action, "the action server rejected the goal")
        self._ask_result(handle)
        return goal_uuid.hex()

    def _ask_result(self, goal: Goal) -> None:
        srv_type = f"{goal.action_type}_GetResult"
        _req, res_name = CodecRegistry.service_type_names(srv_type)
        try:
            payload = self.codecs.encoder(_req, "cdr")({"goal_id": {"uuid": list(goal.uuid)}})
            decode = self.codecs.decoder(res_name, "cdr")
        except SchemaError as exc:
            self._goals.pop(goal.uuid, None)
            goal.events.on_failed(f"no definition of {srv_type}: {exc}")
            return

        def done(replies: list[tuple[bool, bytes, bytes | None]]) -> None:
            if goal.uuid not in self._goals:
                return
            if not replies and self._options.keepalive_interval > 0:
                # the router (or the server) went before the result: the
                # keep-alive decides (see _retry_results); a lost router
                # fails the goal with "disconnected" through fail_pending
                goal.orphaned = True
                return
            del self._goals[goal.uuid]
            for ok, body, _attachment in replies:
                if not ok:
                    goal.events.on_failed(body.decode("utf-8", "replace"))
                    return
                try:
                    answer = decode(memoryview(body))
                except DecodeError as exc:
                    goal.events.on_failed(f"the result does not decode: {exc}")
                    return
                status = ros_field(answer, "status")
                code = status if isinstance(status, int) else None
                goal.events.on_result(code, ros_field(answer, "result"), code == _GOAL_SUCCEEDED)
                return
            goal.events.on_failed("the action server sent no result")

        goal.orphaned = False
        goal.asked += 1
        self._start_query(
            f"{goal.action}/_action/get_result", srv_type, payload, _RESULT_TIMEOUT, done
        )

    def _retry_results(self) -> None:
        """Called by the keep-alive while a router is connected: each goal
        whose ``get_result`` query ended without a reply is asked again, or
        fails with the reason when its server left the graph or
        :data:`_MAX_RESULT_QUERIES` queries went unanswered."""
        for goal in [g for g in self._goals.values() if g.orphaned]:
            reason = None
            if self._service_type(f"{goal.action}/_action/get_result") is None:
                reason = "the action server is gone (its get_result service left the graph)"
            elif goal.asked >= _MAX_RESULT_QUERIES:
                reason = f"the action server sent no result ({goal.asked} queries)"
            if reason is None:
                self._ask_result(goal)
            else:
                del self._goals[goal.uuid]
                goal.events.on_failed(reason)

    async def _ensure_feedback(self, action: str, base: str) -> None:
        if action in self._feedback_subs:
            return
        topic = f"{action}/_action/feedback"
        tag = next(self._tags)
        handle = self._session.subscribe(f"{self.domain}/{topic.lstrip('/')}/*/*", tag)
        sub = Subscription(topic, tag, handle, feedback_of=action)
        self._feedback_subs[action] = sub
        self._by_tag[tag] = sub

    def _on_feedback(
        self,
        sub: Subscription,
        payload: bytes,
        attachment: bytes | None,
    ) -> None:
        """One ``_action/feedback`` sample: to the goal its uuid names (the
        topic carries every client's goals; others' are ignored)."""
        if not valid_attachment(attachment):
            self._events.reject("attachment", f"{sub.topic}: a sample without a valid attachment")
            return
        goals = [g for g in self._goals.values() if g.action == sub.feedback_of]
        if not goals:
            return
        decode = goals[0].feedback_decode
        if decode is None:
            return
        try:
            message = decode(memoryview(payload))
        except DecodeError as exc:
            self._events.reject("decode", f"{sub.topic}: {exc}")
            return
        raw = ros_field(ros_field(message, "goal_id"), "uuid")
        try:
            goal_uuid = bytes(raw) if raw is not None else b""
        except (TypeError, ValueError):
            goal_uuid = b""
        goal = self._goals.get(goal_uuid)
        if goal is not None:
            goal.events.on_feedback(ros_field(message, "feedback"))

    async def cancel_action_goal(self, action: str, goal_id: str) -> None:
        request = {"goal_info": {"goal_id": {"uuid": list(bytes.fromhex(goal_id))}}}
        await self._request(
            f"{action}/_action/cancel_goal",
            "action_msgs/srv/CancelGoal",
            request,
            self._options.service_timeout,
        )

    # -- parameters --------------------------------------------------------------------------
    # Each ROS node serves its own parameters (rcl_interfaces services under
    # its name); names are written "/node:param" as over rosbridge.
    async def _node_call(self, node: str, service: str, request: Any) -> Any:
        name = f"{node}/{service}"
        srv_type = self._service_type(name)
        if srv_type is None:
            raise ServiceError(name, f"node {node} offers no {service} service")
        return await self._request(name, srv_type, request, self._options.service_timeout)

    def _parameter_nodes(self) -> list[str]:
        suffix = "/list_parameters"
        return sorted(
            info.name[: -len(suffix)]
            for info in self._service_infos
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
            if self._service_type(f"{node}/get_parameters") is None:
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
            if self._service_type(f"{node}/set_parameters") is None:
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

    # watching parameters: adapters/_zenoh_parameter_events.py
