"""``open_client()``: a client that outlives the task that opened it, for
Jupyter (a cell opens it, later cells use it, one closes it).

``connect()`` is an ``async with`` block: its task group and cancel scopes
must be entered and left by one task. A notebook runs every cell in a task
of its own, so ``await connect(url).__aenter__()`` in one cell and the exit
in another fails (``RuntimeError: Attempted to exit cancel scope in a
different task``). Here a background task owns the ``async with`` from
start to end; the handle it returns reaches the client from any task of
the same event loop, and :meth:`ClientHandle.aclose` asks the owner to
leave the block (so the teardown and its zero Twist run there)."""

from __future__ import annotations

import logging
import warnings
from contextlib import AbstractAsyncContextManager
from typing import Any, Final

import anyio
import sniffio

from .._connect import ProtocolArg, connect
from .._core._client import Client
from .._errors import NotConnected
from .._options import CLOSE_SLACK_S, ClientOptions

__all__ = ["ClientHandle", "open_client"]


class _Owner:
    """The background task's state: the client once connected, the error
    when it failed, and the events that connect the task to the handle."""

    def __init__(self, log: logging.Logger) -> None:
        self.log = log
        self.client: Client | None = None
        self.error: BaseException | None = None
        self.entered = anyio.Event()
        self.release = anyio.Event()
        self.done = anyio.Event()
        self.scope = anyio.CancelScope()

    async def run(self, cm: AbstractAsyncContextManager[Client]) -> None:
        try:
            with self.scope:
                async with cm as client:
                    self.client = client
                    self.entered.set()
                    await self.release.wait()
        except anyio.get_cancelled_exc_class():
            raise  # the loop is shutting down: the teardown has run (shielded)
        except BaseException as exc:  # kept for the handle; a background task must not raise
            self.error = exc
            if self.client is not None and not self.release.is_set():
                # the block ended on its own after open_client returned: nobody
                # sees this error until an aclose() that may never come, so say it now
                self.log.warning(
                    "the client opened by open_client ended with %r "
                    "(ClientHandle.aclose() raises it again)",
                    exc,
                    exc_info=not isinstance(exc, KeyboardInterrupt | SystemExit),
                )
        finally:
            self.done.set()
            self.entered.set()


def _spawn(owner: _Owner, cm: AbstractAsyncContextManager[Client]) -> object:
    """Start ``owner.run(cm)`` as a task no caller's task group owns (that is
    the point): an asyncio task the handle keeps a reference to, or a trio
    system task. Returns what keeps it alive."""
    library = sniffio.current_async_library()
    if library == "asyncio":
        import asyncio

        return asyncio.get_running_loop().create_task(owner.run(cm), name="rmb-open-client")
    if library == "trio":
        import trio

        trio.lowlevel.spawn_system_task(owner.run, cm, name="rmb-open-client")
        return None
    raise RuntimeError(f"open_client does not support the {library!r} event loop")


async def open_client(
    target: str,
    *,
    protocol: ProtocolArg = "auto",
    port: int | None = None,
    secure: bool | None = None,
    options: ClientOptions | None = None,
) -> ClientHandle:
    """Connect and return a :class:`ClientHandle` that stays open across
    tasks, for Jupyter and other REPLs where each input runs in its own
    task::

        robot = await rmb.open_client("ws://localhost:8765")   # one cell
        async with robot.subscribe("/odom") as sub: ...         # later cells
        await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {...})
        await robot.aclose()                                     # zero Twist, then close

    The arguments are :func:`~ros_mobile_bridge.connect`'s, and so are the
    errors, raised here; ``NotConnected`` if the background task was
    cancelled before the connection was made (the event loop shutting
    down). The connection is owned by a background task of the running
    event loop (asyncio or trio; a trio *system* task), not by the caller:
    in a program that can use ``async with connect(...)``, do; it is the
    structured form. Use the handle from the event loop that opened it only.

    The handle must be closed with :meth:`ClientHandle.aclose`. A handle
    left open is torn down (zero Twist included) only if its event loop
    cancels the background task as it shuts down, as ``asyncio.run()`` and
    ``trio.run()`` do. Restarting or shutting down a Jupyter kernel ends
    the process without that: no teardown runs and no zero Twist is sent;
    the robot's own ``cmd_vel`` watchdog is then what stops it. A handle
    garbage-collected while still open emits a ``ResourceWarning``."""
    if options is not None and not isinstance(options, ClientOptions):
        raise TypeError("options must be a ClientOptions")
    cm = connect(target, protocol=protocol, port=port, secure=secure, options=options)
    opts = options or ClientOptions()
    owner = _Owner(opts.logger)
    keep = _spawn(owner, cm)
    try:
        await owner.entered.wait()
    except BaseException:  # the caller was cancelled while connecting: stop the owner
        owner.scope.cancel()
        with anyio.CancelScope(shield=True), anyio.move_on_after(CLOSE_SLACK_S):
            await owner.done.wait()
        raise
    if owner.client is None:
        if owner.error is not None:
            raise owner.error
        # the owner task was cancelled from outside before it connected
        raise NotConnected(
            f"open_client({target!r}): the background task was cancelled before the "
            "connection was made (is the event loop shutting down?)"
        )
    return ClientHandle(owner, owner.client, keep, opts.teardown_timeout)


class ClientHandle:
    """A :class:`~ros_mobile_bridge.Client` opened by :func:`open_client`.

    Every attribute of the client is reached through the handle
    (``robot.topics``, ``await robot.publish(...)``,
    ``async with robot.subscribe(...)``), or through :attr:`client` for
    static typing. :meth:`aclose` ends it."""

    def __init__(self, owner: _Owner, client: Client, keep: object, teardown: float) -> None:
        self._owner = owner
        self._client = client
        self._keep = keep  # the asyncio task: the loop keeps only a weak reference
        self._teardown = teardown

    @property
    def client(self) -> Client:
        """The client itself (typed); valid until :meth:`aclose`."""
        return self._client

    @property
    def closed(self) -> bool:
        """True once the client's block has been left (after :meth:`aclose`,
        or when the event loop cancelled the background task)."""
        return self._owner.done.is_set()

    async def aclose(self) -> None:
        """Close the client: its teardown runs in the background task (the
        zero Twist to every velocity topic published to and to
        ``options.stop_topics``, then the socket closes), and this waits for
        it, shielded from cancellation, for at most
        ``options.teardown_timeout`` + 5 s. Idempotent. Raises the error
        the block ended with, if any (once; logged at WARNING too if the
        block ended on its own before this call)."""
        owner = self._owner
        owner.release.set()
        with anyio.CancelScope(shield=True):
            with anyio.move_on_after(self._teardown + CLOSE_SLACK_S):
                await owner.done.wait()
            if not owner.done.is_set():
                owner.log.warning(
                    "aclose: the client did not finish closing in time; cancelling it"
                )
                owner.scope.cancel()
        error, owner.error = owner.error, None
        if error is not None:
            raise error

    async def __aenter__(self) -> ClientHandle:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.aclose()

    def __del__(self) -> None:
        owner = self.__dict__.get("_owner")
        if owner is not None and not owner.release.is_set() and not owner.done.is_set():
            warnings.warn(
                f"{self!r} was garbage-collected without aclose(): its connection stays "
                "open until the event loop ends (and a killed kernel sends no zero Twist)",
                ResourceWarning,
                source=self,
                stacklevel=2,
            )

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        if self._owner.done.is_set() and name in _NEEDS_OPEN:
            raise NotConnected("the client is closed (ClientHandle.aclose was called)")
        return getattr(self._client, name)

    def __dir__(self) -> list[str]:
        return sorted(set(super().__dir__()) | {n for n in dir(Client) if not n.startswith("_")})

    def __repr__(self) -> str:
        state = "closed" if self.closed else self._client.status
        return f"<ClientHandle {self._client.protocol} {state}>"


#: Client methods that start something new: refused once the handle is closed
#: (the client's own checks would say NotConnected too; this says why).
_NEEDS_OPEN: Final = frozenset(
    {"subscribe", "publish", "advertise", "call_service", "send_action_goal", "watch_parameters"}
)
