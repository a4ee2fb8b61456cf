"""Requests over one rosbridge connection: ``call_service`` round trips
(the user's calls and the adapter's own ``/rosapi/*`` ones), the ids every
operation carries, and the ``max_pending_requests`` bound. Every part of
:class:`~._rosbridge.RosbridgeAdapter` that asks the bridge something asks
through this one object; the adapter's reader resolves its answers."""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Sized
from typing import Any, Final

import anyio

from .._errors import ActionGoalError, ServiceError, ServiceTimeout
from .._options import ClientOptions
from ..flow import PendingRequests
from ..transport import WebSocket
from ..wire import rosbridge as rb
from ..wire._limits import truncate_for_log
from ._shared import check_pending

__all__ = ["RosbridgeCalls"]

_INTERNAL_TIMEOUT: Final = 5.0
"""Seconds for the adapter's own rosapi requests (discovery, parameters,
confirmations). Read at each call (a test patches it)."""


class RosbridgeCalls:
    """The correlated requests of one rosbridge connection."""

    def __init__(self, ws: WebSocket, engine: rb.RosbridgeEngine, options: ClientOptions) -> None:
        self._ws = ws
        self._engine = engine
        self._options = options
        self._ids = itertools.count(1)
        self.pending: PendingRequests[rb.ServiceResponse] = PendingRequests()
        """The calls waiting for their ``service_response``, by id."""
        self._names: dict[str, str] = {}  # call id -> service
        self._also_counted: list[Sized] = []

    def next_id(self, kind: str) -> str:
        """A fresh operation id, ``rmb:<kind>:<n>``."""
        return f"rmb:{kind}:{next(self._ids)}"

    def count_also(self, waiting: Sized) -> None:
        """Count ``waiting`` (another part's requests, such as action goals)
        against ``max_pending_requests`` with the calls."""
        self._also_counted.append(waiting)

    def check_pending(self, what: str, error: type[ServiceError] | type[ActionGoalError]) -> None:
        """Raise ``error`` at once when ``max_pending_requests`` calls and
        counted requests already wait for an answer on this connection."""
        waiting = len(self.pending) + sum(map(len, self._also_counted))
        check_pending(self._options, waiting, what, error)

    async def call(self, name: str, args: Any, timeout: float | None) -> Any:
        """One ``call_service`` round trip; the response's ``values``.
        Raises ``ServiceError`` (``ServiceTimeout`` for the server's
        timeout) when it fails. No local deadline here."""
        self.check_pending(name, ServiceError)
        call_id = self.next_id("call")
        frame = self._engine.call_service(name, args, id=call_id, timeout=timeout)
        self._names[call_id] = name
        try:
            response = await self.pending.request(call_id, lambda: self._ws.send(frame))
        finally:
            self._names.pop(call_id, None)
        if not response.result:
            text = truncate_for_log(
                response.values
                if isinstance(response.values, str)
                else rb.as_text(response.values),
                2000,
            )
            if timeout is not None and "timeout" in text.lower():
                # "Timeout exceeded while waiting for service response"
                raise ServiceTimeout(name, timeout, f"the bridge: {text}")
            raise ServiceError(name, text)
        return response.values

    async def rosapi(self, name: str, args: Any = None) -> Any:
        """A ``/rosapi/*`` call under the adapter's own deadline."""
        timeout = _INTERNAL_TIMEOUT
        with anyio.fail_after(timeout):
            return await self.call(name, args if args is not None else {}, timeout)

    async def round_trip(self) -> None:
        """Return once the bridge has answered a request sent now, so every
        frame sent before it has been handled. Any answer counts (an error
        too): only its arrival matters."""
        with contextlib.suppress(ServiceError):
            await self.call("/rosapi/get_time", {}, _INTERNAL_TIMEOUT)

    def resolve(self, response: rb.ServiceResponse) -> bool:
        """Hand a ``service_response`` to its call; False when none waits."""
        return response.id is not None and self.pending.resolve(response.id, response)

    def fail_status(self, key: str, message: str) -> bool:
        """An error status with id ``key``: fail that call with ``message``;
        False when ``key`` is no call's."""
        name = self._names.get(key)
        if name is None:
            return False
        self.pending.fail(key, ServiceError(name, message))
        return True
