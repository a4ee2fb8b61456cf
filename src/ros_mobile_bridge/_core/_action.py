"""The handle of one action goal: feedback, acceptance, result, cancel.

Protocol-free: the adapter reports what happens to the goal through the
:class:`~ros_mobile_bridge.adapters.GoalEvents` callbacks, which this class
implements."""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any, Final, Generic, Literal

import anyio

from .._errors import ActionGoalError, ActionGoalLost, RosBridgeError
from .._types import ActionOutcome, FeedbackT, GoalState, ResultT
from ..flow import Watchable, Watcher

__all__ = ["ActionGoal"]

_STATUS: Final = {4: "succeeded", 5: "canceled", 6: "aborted"}
"""``action_msgs/msg/GoalStatus`` codes of the terminal states."""


class ActionGoal(Generic[ResultT, FeedbackT]):
    """A goal sent with :meth:`Client.send_action_goal
    <ros_mobile_bridge.Client.send_action_goal>`.

    The bridge does not relay the server's acceptance; the first feedback or
    the result is the evidence (:meth:`accepted`). :attr:`feedback` yields
    the newest feedback (older unread ones are skipped) and ends when the
    goal does. :meth:`result` waits for the end: a succeeded or canceled goal
    gives an :class:`~ros_mobile_bridge.ActionOutcome`; a rejected, aborted
    or lost one raises :class:`~ros_mobile_bridge.ActionGoalError` whose
    ``reason`` says which (``"disconnected"`` when the connection went).
    A goal sent as an instance of an action's ``Goal`` class
    (``Fibonacci.Goal(order=5)``) is an ``ActionGoal[Fibonacci.Result,
    Fibonacci.Feedback]`` for type checkers."""

    def __init__(self, action: str, cancel: Callable[[], Awaitable[None]]) -> None:
        self.action = action
        self._cancel = cancel
        self._state: GoalState = "pending"
        self._feedback: Watchable[Any] = Watchable(None)
        self._accepted = anyio.Event()
        self._done = anyio.Event()
        self._outcome: ActionOutcome[ResultT] | None = None
        self._error: ActionGoalError | None = None
        self._cancel_sent = False

    @property
    def state(self) -> GoalState:
        """``"pending"`` until accepted, ``"active"``, then ``"succeeded"``,
        ``"canceled"``, ``"aborted"`` or ``"failed"``."""
        return self._state

    @property
    def done(self) -> bool:
        """True once the goal reached a terminal state."""
        return self._done.is_set()

    @property
    def feedback(self) -> AsyncIterator[FeedbackT]:
        """Async iterator over feedback messages, newest wins; it ends when
        the goal does. (A plain iterator, not an async generator: leaving an
        ``async for`` early needs no cleanup.)"""
        return _Feedback(self._feedback.watch())

    async def accepted(self) -> None:
        """Return once the server has evidently accepted the goal (feedback
        or a result arrived). Raises ``ActionGoalError`` if it failed first."""
        await self._accepted.wait()
        if self._error is not None and self._outcome is None:
            raise self._error

    async def result(self) -> ActionOutcome[ResultT]:
        """Wait for the goal to end; see the class docstring."""
        await self._done.wait()
        if self._error is not None:
            raise self._error
        assert self._outcome is not None
        return self._outcome

    async def cancel(self) -> None:
        """Ask the server to cancel the goal (a no-op once it has ended).
        :meth:`result` then reports ``"canceled"`` (or how it ended first)."""
        if self.done or self._cancel_sent:
            return
        self._cancel_sent = True
        await self._cancel()

    # -- GoalEvents (called by the adapter's reader) --------------------------
    def on_feedback(self, values: Any) -> None:
        if self.done:
            return
        self._accept()
        self._feedback.set(values)

    def on_result(self, status: int | None, values: Any, succeeded: bool) -> None:
        if self.done:
            return
        if not succeeded and isinstance(values, str):
            # the bridge's own failures (a rejected goal, bad arguments) come
            # as a result with the reason as text
            self._accepted.set()
            self._fail("failed", values)
            return
        name = _STATUS.get(status) if status is not None else None
        if name is None:
            name = "succeeded" if succeeded else ("canceled" if self._cancel_sent else "aborted")
        self._accept()
        if name == "aborted":
            self._fail("aborted", "aborted")
            return
        final: Literal["succeeded", "canceled"] = "succeeded" if name == "succeeded" else "canceled"
        self._state = final
        self._outcome = ActionOutcome(final, values)
        self._finish()

    def on_failed(self, reason: str) -> None:
        if self.done:
            return
        self._fail("failed", reason)
        self._accepted.set()  # waiters wake and see the error

    def on_lost(self, error: RosBridgeError) -> None:
        if self.done:
            return
        self._state = "failed"
        self._error = ActionGoalLost(self.action, error)
        self._finish()
        self._accepted.set()

    def _accept(self) -> None:
        if self._state == "pending":
            self._state = "active"
        self._accepted.set()

    def _fail(self, state: GoalState, reason: str) -> None:
        self._state = state
        self._error = ActionGoalError(self.action, reason)
        self._finish()

    def _finish(self) -> None:
        self._feedback.close()
        self._done.set()


class _Feedback:
    """The feedback values of a :class:`Watcher`, skipping the initial None."""

    def __init__(self, watcher: Watcher[Any]) -> None:
        self._watcher = watcher

    def __aiter__(self) -> _Feedback:
        return self

    async def __anext__(self) -> Any:
        while True:
            value = await self._watcher.__anext__()
            if value is not None:
                return value
