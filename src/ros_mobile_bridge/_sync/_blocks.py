"""The blocking ``with`` blocks of a :class:`~._client.SyncClient`: a
subscription (:class:`SyncSubscription`) and an action goal
(:class:`SyncActionGoal`), each an async context manager of the client that
one task of the worker enters and later leaves."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterator
from types import TracebackType
from typing import Any, ClassVar, Generic, TypeVar

from .._checks import check_timeout as _check_timeout
from .._core._action import ActionGoal
from .._errors import NotConnected
from .._types import (
    ActionOutcome,
    DataT,
    FeedbackT,
    GoalState,
    Message,
    ResultT,
    SubscriptionState,
    SubscriptionStats,
)
from ..flow import Subscription
from ._worker import Held, Parent

__all__ = ["SyncActionGoal", "SyncSubscription"]

T = TypeVar("T")
T_ = TypeVar("T_")

_B = TypeVar("_B", bound="_SyncBlock[Any]")


class _SyncBlock(Generic[T]):
    """The shape :class:`SyncSubscription` and :class:`SyncActionGoal` share:
    a plain ``with`` block over an async context manager that one task of
    the worker enters and later leaves (:class:`Held`). Entered once; while
    open it is in its client's :class:`Children`, so ``close()`` leaves it;
    leaving waits up to the client's teardown time."""

    #: How to enter it, for the error raised when it is used before.
    _how_to_enter: ClassVar[str]

    def __init__(self, held: Held[T], parent: Parent) -> None:
        self._held = held
        self._parent = parent
        self._value: T | None = None

    def __enter__(self: _B) -> _B:
        if self._value is not None:
            raise RuntimeError(f"a {type(self).__name__} can be entered once")
        self._value = self._held.enter()
        self._parent.children.add(self, self._held)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._leave()

    def _leave(self) -> None:
        self._parent.children.leave(self, self._parent.leave_timeout)

    def _entered(self) -> T:
        if self._value is None:
            raise RuntimeError(self._how_to_enter)
        return self._value

    def _run(self, fn: Callable[[], Awaitable[T_]], timeout: float | None, what: str) -> T_:
        return self._parent.worker.run_bounded(fn, (), timeout, what)


class SyncSubscription(_SyncBlock[Subscription[DataT]]):
    """A subscription of a :class:`SyncClient`: ``for msg in sub`` blocks
    for each :class:`~ros_mobile_bridge.Message`; :meth:`get` takes one with
    a timeout. Iteration ends when the subscription or the client closes;
    a lost connection raises ``NotConnected``."""

    _how_to_enter = "enter the subscription first: with robot.subscribe(...) as sub"

    def __init__(
        self, held: Held[Subscription[DataT]], parent: Parent, topic: str, timeout: float | None
    ) -> None:
        super().__init__(held, parent)
        self.topic = topic
        self._timeout = timeout

    def close(self) -> None:
        """Unsubscribe (idempotent)."""
        self._leave()

    def __repr__(self) -> str:
        return f"<SyncSubscription {self.topic}>"

    def get(self, timeout: float | None = None) -> Message[DataT]:
        """The next message. ``timeout`` (default: the one given to
        ``subscribe``) bounds the wait: ``TimeoutError`` when no message came
        (nothing is lost; call again); with neither, it waits until a
        message comes or the subscription ends. ``NotConnected`` once the subscription
        has ended (after the queued messages), or the connection's error."""
        try:
            return self._next(timeout)
        except StopAsyncIteration:
            raise NotConnected(f"the subscription to {self.topic} has ended") from None

    def get_batch(self, max_size: int = 256, timeout: float | None = None) -> list[Message[DataT]]:
        """Every message already waiting (at least one, at most ``max_size``),
        in order, for one hand-over between threads instead of one per
        message: :meth:`Subscription.batches`' step. Waits, times out and
        ends as :meth:`get` does."""
        sub = self._entered()
        batches = sub.batches(max_size)  # checks max_size at once
        limit = self._timeout if timeout is None else _check_timeout(timeout)
        if not self._held.open:
            raise NotConnected(f"the subscription to {self.topic} has ended")
        try:
            return self._run(batches.__anext__, limit, f"receive on {self.topic}")
        except StopAsyncIteration:
            raise NotConnected(f"the subscription to {self.topic} has ended") from None

    def __iter__(self) -> Iterator[Message[DataT]]:
        return self

    def __next__(self) -> Message[DataT]:
        try:
            return self._next(None)
        except StopAsyncIteration:
            raise StopIteration from None

    def _next(self, timeout: float | None) -> Message[DataT]:
        sub = self._entered()
        limit = self._timeout if timeout is None else _check_timeout(timeout)
        if not self._held.open:
            raise StopAsyncIteration
        return self._run(sub.__anext__, limit, f"receive on {self.topic}")

    def wait_active(self, timeout: float | None = None) -> None:
        """Return once the topic is carried (``state == "active"``);
        ``TimeoutError`` after ``timeout`` seconds (default: the one given
        to ``subscribe``; with neither, it waits until the topic is carried
        or the subscription ends, ``NotConnected``)."""
        sub = self._entered()
        limit = self._timeout if timeout is None else _check_timeout(timeout)
        self._run(sub.wait_active, limit, "wait_active")

    @property
    def state(self) -> SubscriptionState:
        """``"pending"`` or ``"active"``."""
        return self._entered().state

    @property
    def stats(self) -> SubscriptionStats:
        """A snapshot of the subscription's counters."""
        return self._entered().stats


class SyncActionGoal(_SyncBlock[ActionGoal[ResultT, FeedbackT]]):
    """An action goal of a :class:`SyncClient`, with blocking waits."""

    _how_to_enter = "enter the goal first: with robot.send_action_goal(...) as goal"

    def __init__(
        self, held: Held[ActionGoal[ResultT, FeedbackT]], parent: Parent, action: str
    ) -> None:
        super().__init__(held, parent)
        self._feedback: Any = None
        self.action = action

    def __repr__(self) -> str:
        return f"<SyncActionGoal {self.action}>"

    @property
    def state(self) -> GoalState:
        """The goal's state (:attr:`ActionGoal.state`)."""
        return self._entered().state

    @property
    def done(self) -> bool:
        """True once the goal reached a terminal state."""
        return self._entered().done

    def accepted(self, timeout: float | None = None) -> None:
        """:meth:`ActionGoal.accepted`, blocking; without ``timeout`` it
        waits until the goal is accepted or fails."""
        self._run(self._entered().accepted, timeout, "accepted")

    def result(self, timeout: float | None = None) -> ActionOutcome[ResultT]:
        """:meth:`ActionGoal.result`, blocking; without ``timeout`` it waits
        until the goal ends, however long the action runs."""
        return self._run(self._entered().result, timeout, "result")

    def cancel(self, timeout: float | None = None) -> None:
        """:meth:`ActionGoal.cancel`, blocking."""
        self._run(self._entered().cancel, timeout, "cancel")

    def next_feedback(self, timeout: float | None = None) -> FeedbackT:
        """The newest feedback not yet seen (waits for one: without
        ``timeout``, until one comes or the goal ends); ``StopIteration``
        is never raised: ``NotConnected`` once the goal has ended."""
        goal = self._entered()

        async def step() -> FeedbackT:
            if self._feedback is None:  # made in the loop: it holds anyio events
                self._feedback = goal.feedback
            try:
                value: FeedbackT = await self._feedback.__anext__()
                return value
            except StopAsyncIteration:
                raise NotConnected(f"the goal to {self.action} has ended") from None

        return self._run(step, timeout, "feedback")
