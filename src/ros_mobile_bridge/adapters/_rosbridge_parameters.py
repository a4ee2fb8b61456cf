"""Parameters over rosbridge, read and written through the bridge's
``/rosapi/*_param*`` services. A part of :class:`~._rosbridge.RosbridgeAdapter`."""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import Any

from .._errors import NotSupportedError, ServiceError
from .._options import ClientOptions
from ._rosbridge_discovery import _names


class RosbridgeParameters:
    """Getting and setting parameters (rosbridge has no updates to
    subscribe to). The adapter owns the state and helpers declared here."""

    _options: ClientOptions
    _call: Callable[[str, Any, float | None], Awaitable[Any]]

    async def get_parameters(self, names: Sequence[str]) -> dict[str, Any]:
        if not names:
            answer = await self._param_call("/rosapi/get_param_names", {})
            names = _names(answer, "names")
        values: dict[str, Any] = {}
        for name in names:
            answer = await self._param_call("/rosapi/get_param", {"name": name})
            if not isinstance(answer, dict) or answer.get("successful") is False:
                continue  # "Parameter not found": absent from the result
            raw = answer.get("value")
            if isinstance(raw, str) and raw:
                try:  # the value is a JSON document in a string
                    values[name] = json.loads(raw)
                except ValueError:
                    values[name] = raw
        return values

    async def set_parameters(self, values: Mapping[str, Any]) -> dict[str, Any]:
        for name, value in values.items():
            answer = await self._param_call(
                "/rosapi/set_param", {"name": name, "value": json.dumps(value)}
            )
            if isinstance(answer, dict) and answer.get("successful") is False:
                raise ServiceError(
                    "/rosapi/set_param", f"{name}: {answer.get('reason') or 'refused'}"
                )
        return await self.get_parameters(list(values))

    async def _param_call(self, service: str, args: Any) -> Any:
        return await self._call(service, args, self._options.service_timeout)

    async def subscribe_parameters(self, names: Sequence[str]) -> None:
        raise NotSupportedError("rosbridge has no parameter updates to subscribe to")

    async def unsubscribe_parameters(self, names: Sequence[str]) -> None:
        return None
