"""Actions over Zenoh (:class:`ZenohActions`, the actions part of
:class:`~._zenoh.ZenohAdapter`): a ROS 2 action is its ``_action/send_goal``,
``_action/get_result`` and ``_action/cancel_goal`` services, called through
the connection's query engine (:class:`~._zenoh_calls.ZenohQueries`), and
its ``_action/feedback`` topic, one internal subscription per action.

Contract:

* A goal is sent once the action server is in the graph (else
  ``ActionGoalError``), the types its services and feedback use are known
  (learnt from the server's node when ours lack them or hash differently),
  and fewer than ``max_pending_requests`` requests wait; its id is returned
  once the server accepted it.
* Its result is one ``get_result`` query that waits as long as the goal
  lives. When that query ends without a reply (the router or the server
  went) the goal is orphaned; the keep-alive, while a router is connected,
  asks again (:meth:`ZenohActions.retry_results`), up to
  :data:`_MAX_RESULT_QUERIES` queries, or fails the goal when its server
  left the graph.
* Feedback samples go to the goal their uuid names (the topic carries every
  client's goals; others' are ignored); one without a valid attachment, or
  that does not decode, is counted and skipped.
* A lost connection fails every open goal with ``"disconnected"``."""

from __future__ import annotations

import uuid
from typing import Any, Final

from .._errors import ActionGoalError, DecodeError, RosBridgeError, SchemaError, ServiceError
from ..codec import CodecRegistry
from ..flow import Decoder
from ..wire import rmw_zenoh as rz
from ._seam import GoalEvents
from ._zenoh_calls import Replies, ZenohQueries
from ._zenoh_describe import ZenohDescriptions
from ._zenoh_node import ZenohNode
from ._zenoh_values import Goal, Subscription, ros_field, split_type, valid_attachment

__all__ = ["ZenohActions"]

_RESULT_TIMEOUT: Final = 24 * 3600.0
"""How long a goal's ``get_result`` query may wait (the goal's own life)."""
_GOAL_SUCCEEDED: Final = 4
_MAX_RESULT_QUERIES: Final = 4
"""How many times a goal's ``get_result`` query is sent when the earlier ones
ended without a reply while the action server stayed in the graph."""


class ZenohActions:
    """Sending goals, following their feedback and results (see the module
    docstring and :class:`~._seam.ActionClient`)."""

    def __init__(
        self,
        node: ZenohNode,
        queries: ZenohQueries,
        descriptions: ZenohDescriptions,
        goals: dict[bytes, Goal],
    ) -> None:
        """``goals`` is the table of open goals, by uuid (empty; the query
        engine counts it against ``max_pending_requests``)."""
        self._node = node
        self._session = node.session
        self._codecs = node.codecs
        self._options = node.options
        self._graph = node.graph
        self._events = node.events
        self._queries = queries
        self._descriptions = descriptions
        self._goals = goals
        self._feedback_subs: dict[str, Subscription] = {}

    async def send_action_goal(
        self, action: str, action_type: str, goal: Any, events: GoalEvents
    ) -> str:
        pkg, _, name = split_type(action_type, "action")
        base = f"{pkg}/action/{name}"
        send_goal = f"{action}/_action/send_goal"
        if self._graph.service_type(send_goal) is None:
            raise ActionGoalError(action, "no action server offers it")
        self._queries.check_pending(action, goal=True)
        describe = self._descriptions.describe_entity
        await describe(send_goal, rz.EntityKind.SERVICE)
        await describe(f"{action}/_action/get_result", rz.EntityKind.SERVICE)
        await describe(f"{action}/_action/feedback", rz.EntityKind.PUBLISHER)
        try:
            feedback_decode: Decoder | None = self._codecs.decoder(f"{base}_FeedbackMessage", "cdr")
        except SchemaError as exc:
            raise ActionGoalError(action, f"no definition of {action_type}: {exc}") from exc
        goal_uuid = uuid.uuid4().bytes
        uuid_msg = {"uuid": list(goal_uuid)}
        self._ensure_feedback(action)
        handle = Goal(action, base, goal_uuid, events, feedback_decode)
        self._goals[goal_uuid] = handle
        try:
            answer = await self._queries.request(
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
            payload = self._codecs.encoder(_req, "cdr")({"goal_id": {"uuid": list(goal.uuid)}})
            decode = self._codecs.decoder(res_name, "cdr")
        except SchemaError as exc:
            self._goals.pop(goal.uuid, None)
            goal.events.on_failed(f"no definition of {srv_type}: {exc}")
            return

        def done(replies: Replies) -> None:
            if goal.uuid not in self._goals:
                return
            if not replies and self._options.keepalive_interval > 0:
                # the router (or the server) went before the result: the
                # keep-alive decides (see retry_results); a lost router
                # fails the goal with "disconnected" through fail_all
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
        self._queries.start_query(
            f"{goal.action}/_action/get_result", srv_type, payload, _RESULT_TIMEOUT, done
        )

    def retry_results(self) -> None:
        """Called by the keep-alive while a router is connected: each goal
        whose ``get_result`` query ended without a reply is asked again, or
        fails with the reason when its server left the graph or
        :data:`_MAX_RESULT_QUERIES` queries went unanswered."""
        for goal in [g for g in self._goals.values() if g.orphaned]:
            reason = None
            if self._graph.service_type(f"{goal.action}/_action/get_result") is None:
                reason = "the action server is gone (its get_result service left the graph)"
            elif goal.asked >= _MAX_RESULT_QUERIES:
                reason = f"the action server sent no result ({goal.asked} queries)"
            if reason is None:
                self._ask_result(goal)
            else:
                del self._goals[goal.uuid]
                goal.events.on_failed(reason)

    def _ensure_feedback(self, action: str) -> None:
        if action in self._feedback_subs:
            return
        topic = f"{action}/_action/feedback"
        tag = self._node.new_tag()
        handle = self._session.subscribe(self._node.data_selector(topic), tag)
        sub = Subscription(topic, tag, handle, feedback_of=action)
        self._feedback_subs[action] = sub
        self._node.routes[tag] = sub

    def on_feedback(self, sub: Subscription, samples: list[rz.SampleData]) -> None:
        """The ``_action/feedback`` samples of one inbox item, in order (see
        the module docstring)."""
        for _key, payload, attachment in samples:
            self._on_feedback(sub, payload, attachment)

    def _on_feedback(self, sub: Subscription, payload: bytes, attachment: bytes | None) -> None:
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
        await self._queries.request(
            f"{action}/_action/cancel_goal",
            "action_msgs/srv/CancelGoal",
            request,
            self._options.service_timeout,
        )

    def fail_all(self, error: RosBridgeError) -> None:
        """The connection is lost (``error`` says how): every open goal
        fails (``ActionGoalLost``, reason ``"disconnected"``)."""
        goals = list(self._goals.values())
        self._goals.clear()
        for goal in goals:
            goal.events.on_lost(error)
