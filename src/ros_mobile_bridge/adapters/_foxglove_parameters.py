"""The parameters part of a Foxglove connection (``Adapter.parameters``):
``getParameters`` / ``setParameters`` requests answered by
``parameterValues`` with the request's id, and the ``parametersSubscribe``
updates. The adapter's reader hands each answer to :attr:`requests` and
each unsolicited update up as an event; this part only asks."""

from __future__ import annotations

import itertools
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import Any

from .._errors import NotSupportedError, ParameterError
from ..flow import PendingRequests
from ..wire import foxglove as fx

__all__ = ["FoxgloveParameters"]


class FoxgloveParameters:
    """Parameters over one Foxglove connection whose server offers the
    ``parameters`` capability (see :class:`~._seam.ParameterAccess`)."""

    def __init__(
        self,
        engine: fx.FoxgloveEngine,
        *,
        send_request: Callable[[bytes | str], Awaitable[None]],
        send: Callable[[bytes | str], Awaitable[None]],
        check_pending: Callable[[str], None],
        capabilities: Callable[[], Sequence[str]],
        closed: Callable[[], bool],
    ) -> None:
        """``send_request`` writes a request whose answer must be read as it
        comes, ``send`` any other frame; ``check_pending`` raises when the
        connection's requests are at their bound; ``capabilities`` is the
        server's list now (a later ``serverInfo`` may change it)."""
        self._engine = engine
        self._send_request = send_request
        self._send = send
        self._check_pending = check_pending
        self._capabilities = capabilities
        self._closed = closed
        self._ids = itertools.count(1)
        self.requests: PendingRequests[dict[str, Any]] = PendingRequests()
        """The requests waiting for their ``parameterValues``, by id (the
        adapter's reader resolves them)."""

    async def _request(self, build: Callable[[str], bytes | str]) -> dict[str, Any]:
        self._check_pending("parameters")
        request_id = f"rmb-{next(self._ids)}"
        return await self.requests.request(
            request_id, lambda: self._send_request(build(request_id))
        )

    async def get_parameters(self, names: Sequence[str]) -> dict[str, Any]:
        names = list(names)
        return await self._request(lambda rid: self._engine.get_parameters(names, rid))

    async def set_parameters(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Set ``values``; the server answers with the values it holds
        afterwards. The protocol carries no refusal, so a name whose reported
        value is not the one sent was refused: ``ParameterError`` naming
        what the robot kept, after every accepted value was applied."""
        params = [fx.Parameter(name, value) for name, value in values.items()]
        after = await self._request(lambda rid: self._engine.set_parameters(params, rid))
        reasons = {
            name: f"the robot kept {after[name]!r} (the Foxglove protocol gives no reason)"
            for name, value in values.items()
            if name in after and not same_value(after[name], value)
        }
        if reasons:
            raise ParameterError(reasons, after)
        return after

    async def subscribe_parameters(self, names: Sequence[str]) -> None:
        """``NotSupportedError`` when the server lacks ``parametersSubscribe``."""
        if "parametersSubscribe" not in self._capabilities():
            raise NotSupportedError("the server does not offer 'parametersSubscribe'")
        await self._send(self._engine.subscribe_parameter_updates(list(names)))

    async def unsubscribe_parameters(self, names: Sequence[str]) -> None:
        if "parametersSubscribe" in self._capabilities() and not self._closed():
            await self._send(self._engine.unsubscribe_parameter_updates(list(names)))


def same_value(held: Any, sent: Any) -> bool:
    """Whether the value a server reports is the one sent (``2`` and
    ``2.0`` are; ``True`` and ``1`` are not; sequences element by element)."""
    held, sent = (v.tolist() if hasattr(v, "tolist") else v for v in (held, sent))
    if isinstance(held, bool) or isinstance(sent, bool):
        return type(held) is type(sent) and held == sent
    if isinstance(held, (list, tuple, bytes)) and isinstance(sent, (list, tuple, bytes)):
        return len(held) == len(sent) and all(map(same_value, held, sent))
    try:
        return bool(held == sent)
    except Exception:  # a numpy array or another odd value: not provably the same
        return False
