"""Action goals over rosbridge (``send_action_goal``): the goals this
connection sent, the bridge's feedback, results and refusals of them. The
actions part of :class:`~._rosbridge.RosbridgeAdapter`; its reader hands
each action event here."""

from __future__ import annotations

import logging
from typing import Any

from .._errors import ActionGoalError, DecodeError, RosBridgeError, ServiceError
from ..codec import CodecRegistry
from ..transport import WebSocket
from ..wire import rosbridge as rb
from ._rosbridge_calls import RosbridgeCalls
from ._rosbridge_definitions import RosbridgeDefinitions
from ._rosbridge_discovery import names_in
from ._seam import GoalEvents
from ._shared import as_instance, check_fits, plain

__all__ = ["RosbridgeActions"]


class RosbridgeActions:
    """The goals of one rosbridge connection (see
    :class:`~._seam.ActionClient`). Goals count against
    ``max_pending_requests`` with the calls."""

    def __init__(
        self,
        ws: WebSocket,
        engine: rb.RosbridgeEngine,
        calls: RosbridgeCalls,
        definitions: RosbridgeDefinitions,
        codecs: CodecRegistry,
        log: logging.Logger,
    ) -> None:
        self._ws = ws
        self._engine = engine
        self._calls = calls
        self._definitions = definitions
        self._codecs = codecs
        self._log = log
        # goal id -> (action, the action's type as pkg/action/Name, events)
        self._goals: dict[str, tuple[str, str, GoalEvents]] = {}
        calls.count_also(self._goals)

    async def send_action_goal(
        self, action: str, action_type: str, goal: Any, events: GoalEvents
    ) -> str:
        # The bridge never answers a goal for an action nobody serves, so
        # such a goal would wait forever: refuse it here.
        try:
            servers = names_in(await self._calls.rosapi("/rosapi/action_servers"), "action_servers")
        except (ServiceError, TimeoutError) as exc:
            self._log.debug("cannot list action servers (%s); sending the goal anyway", exc)
        else:
            if action not in servers:
                raise ActionGoalError(action, "no action server offers it")
        parts = action_type.split("/")
        base = f"{parts[0]}/action/{parts[-1]}"
        goal = plain(goal)
        for part in ("_Goal", "_Result", "_Feedback"):  # once per type and connection
            await self._definitions.fetch_part(base + part)
        check_fits(self._codecs, f"{base}_Goal", goal)
        self._calls.check_pending(action, ActionGoalError)
        goal_id = self._calls.next_id(f"goal:{action}")
        frame = self._engine.send_action_goal(action, action_type, goal, id=goal_id)
        self._goals[goal_id] = (action, base, events)
        try:
            await self._ws.send(frame)
        except BaseException:
            self._goals.pop(goal_id, None)
            raise
        return goal_id

    async def cancel_action_goal(self, action: str, goal_id: str) -> None:
        await self._ws.send(self._engine.cancel_action_goal(action, id=goal_id))

    def on_feedback(self, event: rb.ActionFeedback) -> None:
        """A feedback message from the reader: to its goal, if still ours."""
        entry = self._goals.get(event.id or "")
        if entry is not None:
            _action, base, events = entry
            try:
                feedback = as_instance(self._codecs, f"{base}_Feedback", event.values)
            except DecodeError as exc:
                self._log.warning("%s: a feedback message that does not decode: %s", _action, exc)
                return
            events.on_feedback(feedback)

    def on_result(self, event: rb.ActionResult) -> None:
        """A result from the reader: the goal ends."""
        entry = self._goals.pop(event.id or "", None)
        if entry is not None:
            _action, base, events = entry
            try:
                values = as_instance(self._codecs, f"{base}_Result", event.values)
            except DecodeError as exc:
                events.on_failed(f"the result does not decode: {exc}")
                return
            events.on_result(event.status, values, event.result)

    def on_error_status(self, key: str, message: str) -> bool:
        """An error status with id ``key``: the bridge refused that goal
        (it fails with ``message``); False when ``key`` is no goal's."""
        entry = self._goals.pop(key, None)
        if entry is None:
            return False
        entry[2].on_failed(message)
        return True

    def fail_all(self, error: RosBridgeError) -> None:
        """The connection is lost (``error`` says how): every goal fails
        (``ActionGoalLost``, reason ``"disconnected"``)."""
        goals = list(self._goals.values())
        self._goals.clear()  # (in place: the calls count this dict)
        for _action, _base, events in goals:
            events.on_lost(error)
