"""The worker of the sync client: one thread running an event loop (asyncio
or trio) with an anyio ``BlockingPortal``, the ``async with`` blocks it holds
(each entered and left by one task of the worker, so anyio's cancel scopes
stay in the task that opened them), and the registry of the blocks a
:class:`~ros_mobile_bridge.SyncClient` made. ``_client.py`` builds the public
sync API on it."""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import logging
import threading
import weakref
from collections.abc import Awaitable, Callable, Hashable, Mapping
from contextlib import AbstractAsyncContextManager
from typing import TYPE_CHECKING, Any, Final, Generic, TypeVar

import anyio

from .._checks import check_timeout as _check_timeout
from .._errors import NotConnected

if TYPE_CHECKING:
    from anyio.from_thread import BlockingPortal

__all__ = ["JOIN_S", "Children", "Held", "Parent", "Worker", "set_event"]

T = TypeVar("T")

#: How long ``close()`` waits for the worker thread to end after its loop
#: was told to stop.
JOIN_S: Final = 5.0


class Worker:
    """One event loop in one daemon thread, reached through a blocking portal.

    :meth:`start` hands a coroutine function to the loop and returns a
    ``concurrent.futures.Future``; every future still waiting when the
    thread ends is failed with ``NotConnected``, so no caller waits on a
    dead loop."""

    def __init__(
        self,
        backend: str,
        backend_options: Mapping[str, Any] | None,
        name: str,
        log: logging.Logger,
    ) -> None:
        """``backend`` and ``backend_options`` are :func:`anyio.run`'s
        (see :func:`.._loop._backends.run_args`)."""
        self._log = log
        self._backend = backend
        self._backend_options = dict(backend_options) if backend_options else None
        self._ready: concurrent.futures.Future[BlockingPortal] = concurrent.futures.Future()
        self._lock = threading.Lock()
        self._pending: set[concurrent.futures.Future[Any]] = set()
        self._ended = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name=name, daemon=True)
        self._thread.start()
        try:
            self._portal = self._ready.result()
        except BaseException:
            self._thread.join(JOIN_S)
            raise

    @property
    def thread(self) -> threading.Thread:
        return self._thread

    @property
    def alive(self) -> bool:
        return not self._ended

    def _main(self) -> None:
        try:
            anyio.run(self._serve, backend=self._backend, backend_options=self._backend_options)
        except BaseException as exc:  # the thread's end is reported to every waiter
            self._error = exc
            if not self._ready.done():
                self._ready.set_exception(exc)
            else:
                self._log.error("the sync client's event loop failed: %r", exc)
        finally:
            with self._lock:
                self._ended = True
                pending, self._pending = self._pending, set()
            for future in pending:
                with contextlib.suppress(concurrent.futures.InvalidStateError):
                    future.set_exception(self._gone())

    async def _serve(self) -> None:
        from anyio.from_thread import BlockingPortal  # imported when first used

        async with BlockingPortal() as portal:
            self._ready.set_result(portal)
            await portal.sleep_until_stopped()

    def _gone(self) -> NotConnected:
        why = f": {self._error!r}" if self._error is not None else ""
        return NotConnected(f"the sync client's worker thread has stopped{why}")

    def _check_caller(self) -> None:
        if threading.get_ident() == self._thread.ident:
            raise RuntimeError(
                "a blocking method of the sync client was called from its own event loop "
                "(inside SyncClient.run): await the async Client there instead"
            )

    def start(self, fn: Callable[..., Awaitable[T]], *args: Any) -> concurrent.futures.Future[T]:
        """Start ``fn(*args)`` in the loop; ``NotConnected`` if it has stopped."""
        self._check_caller()
        try:
            future: concurrent.futures.Future[T] = self._portal.start_task_soon(fn, *args)
        except RuntimeError as exc:  # the portal stopped, or its loop is gone
            raise self._gone() from exc
        with self._lock:
            if self._ended:
                future.cancel()
                raise self._gone()
            self._pending.add(future)
        future.add_done_callback(self._forget)
        return future

    def _forget(self, future: concurrent.futures.Future[Any]) -> None:
        with self._lock:
            self._pending.discard(future)

    def wait(self, future: concurrent.futures.Future[T], what: str) -> T:
        """The result of ``future``. A ``KeyboardInterrupt`` (or any exception)
        raised in this thread while waiting cancels the call in the loop
        and propagates."""
        try:
            return future.result()
        except concurrent.futures.CancelledError:
            raise NotConnected(f"{what}: the sync client closed while it was running") from None
        except BaseException:
            future.cancel()  # a no-op once it finished; else cancels the task's scope
            raise

    def run(self, fn: Callable[..., Awaitable[T]], *args: Any, what: str = "call") -> T:
        """Run ``fn(*args)`` in the loop and wait for its result."""
        return self.wait(self.start(fn, *args), what)

    def run_bounded(
        self,
        fn: Callable[..., Awaitable[T]],
        args: tuple[Any, ...],
        timeout: float | None,
        what: str,
    ) -> T:
        """:meth:`run`, cancelled in the loop after ``timeout`` seconds
        (``TimeoutError``); None: no bound of its own."""
        limit = _check_timeout(timeout)
        if limit is None:
            return self.run(fn, *args, what=what)

        async def bounded() -> T:
            with anyio.move_on_after(limit):
                return await fn(*args)
            raise TimeoutError(f"{what}: no result within {limit:.3g} s")

        return self.run(bounded, what=what)

    def stop(self, join_timeout: float) -> bool:
        """Stop the loop (cancelling what still runs there) and join the
        thread within ``join_timeout``. Returns whether the thread ended."""
        if threading.get_ident() == self._thread.ident:
            return False
        if not self._ended:
            try:
                stopping = self._portal.start_task_soon(self._portal.stop, True)
            except RuntimeError:
                pass  # already stopping or stopped
            else:
                with contextlib.suppress(BaseException):
                    stopping.result(timeout=join_timeout)
        self._thread.join(join_timeout)
        return not self._thread.is_alive()


class Held(Generic[T]):
    """An async context manager held open by one task of the worker: entered,
    then left when :meth:`exit` is called, both in that task."""

    def __init__(self, worker: Worker, cm: AbstractAsyncContextManager[T], what: str) -> None:
        self._worker = worker
        self._cm = cm
        self._what = what
        self._release: anyio.Event | None = None
        self._owner: concurrent.futures.Future[None] | None = None
        self._left = False

    async def _hold(self, entered: concurrent.futures.Future[T]) -> None:
        self._release = anyio.Event()
        async with self._cm as value:
            entered.set_result(value)
            await self._release.wait()

    def enter(self) -> T:
        entered: concurrent.futures.Future[T] = concurrent.futures.Future()
        owner = self._owner = self._worker.start(self._hold, entered)
        try:
            both: list[concurrent.futures.Future[Any]] = [entered, owner]
            concurrent.futures.wait(both, return_when=concurrent.futures.FIRST_COMPLETED)
        except BaseException:  # KeyboardInterrupt while entering: abandon it
            owner.cancel()
            raise
        if entered.done():
            return entered.result()
        self._left = True
        self._worker.wait(owner, self._what)  # raises why it failed
        raise NotConnected(f"{self._what} ended before it was entered")  # pragma: no cover

    @property
    def open(self) -> bool:
        return self._owner is not None and not self._left

    def exit(self, timeout: float) -> None:
        """Leave the block: the task's ``__aexit__`` runs; wait up to
        ``timeout`` for it. Idempotent."""
        owner = self._owner
        if owner is None or self._left:
            return
        self._left = True
        release = self._release
        if not owner.done() and release is not None:
            with contextlib.suppress(NotConnected):
                self._worker.run(set_event, release, what=self._what)
        try:
            owner.result(timeout=timeout)
        except concurrent.futures.TimeoutError:
            owner.cancel()
            raise TimeoutError(
                f"{self._what} did not finish closing within {timeout:.3g} s"
            ) from None
        except concurrent.futures.CancelledError:
            pass  # cancelled by the loop stopping: its __aexit__ ran then


async def set_event(event: anyio.Event) -> None:
    event.set()


class Children:
    """The :class:`SyncSubscription` and :class:`SyncActionGoal` blocks a
    :class:`SyncClient` has entered and not yet left, each with the
    :class:`Held` it keeps open; :meth:`SyncClient.close` leaves them first.
    Keyed weakly: a block dropped without being left is forgotten (stopping
    the worker ends its task). The lock guards the map, which threads
    entering and leaving blocks change concurrently."""

    def __init__(self) -> None:
        self._open: weakref.WeakKeyDictionary[Hashable, Held[Any]] = weakref.WeakKeyDictionary()
        self._lock = threading.Lock()

    def add(self, child: Hashable, held: Held[Any]) -> None:
        with self._lock:
            self._open[child] = held

    def entered(self) -> list[Hashable]:
        """A snapshot of the blocks still open."""
        with self._lock:
            return list(self._open)

    def leave(self, child: Hashable, timeout: float) -> None:
        """Leave ``child``'s block (its ``__aexit__`` runs in the worker),
        waiting up to ``timeout`` (``TimeoutError``); a no-op once it was
        left. ``NotConnected`` (the worker has stopped) means there is
        nothing left to leave."""
        with self._lock:
            held = self._open.pop(child, None)
        if held is not None:
            with contextlib.suppress(NotConnected):
                held.exit(timeout)


@dataclasses.dataclass(frozen=True)
class Parent:
    """What a :class:`SyncClient` gives each block it makes: the worker
    whose loop runs it, the registry its ``close()`` leaves, and how long
    leaving one may take (``options.teardown_timeout`` + slack)."""

    worker: Worker
    children: Children
    leave_timeout: float
