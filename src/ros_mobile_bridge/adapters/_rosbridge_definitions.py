"""Message definitions over rosbridge: a type the bundled definitions lack,
asked of ``/rosapi/message_details`` and registered with the connection's
codecs. A part of :class:`~._rosbridge.RosbridgeAdapter`."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any, Final

from .._errors import SchemaError, ServiceError
from ..codec import CodecRegistry, same_type_name
from ..wire._limits import truncate_for_log
from ._rosbridge_calls import RosbridgeCalls

_IDL_TO_MSG: Final[Mapping[str, str]] = {
    "boolean": "bool",
    "octet": "byte",
    "float": "float32",
    "double": "float64",
}
"""``/rosapi/message_details`` names some primitives as IDL does."""


class RosbridgeDefinitions:
    """The definitions fetched from the bridge, once per connection and
    type (the types it could not give are remembered); the connection's
    ``Adapter.descriptions``."""

    def __init__(self, codecs: CodecRegistry, calls: RosbridgeCalls, log: logging.Logger) -> None:
        self._codecs = codecs
        self._rosapi = calls.rosapi
        self._log = log
        self._none: set[str] = set()  # asked, and the bridge gave none

    async def _fetch(self, schema: str, *, quiet: bool = False) -> None:
        """Register ``schema`` from ``/rosapi/message_details`` (for cbor-raw
        of a type the bundled definitions lack); an action's goal
        (``pkg/action/X_Goal``) from ``/rosapi/action_goal_details`` and a
        service's request (``pkg/srv/X_Request``) from
        ``/rosapi/service_request_details``, to check what the caller sends.
        A failure is logged (at debug level when ``quiet``) and remembered."""
        service, args = _details_request(schema)
        try:
            answer = await self._rosapi(service, args)
            self._codecs.add_schema(schema, "ros2msg", typedefs_to_msg(schema, answer))
        except (ServiceError, TimeoutError, SchemaError, ValueError) as exc:
            self._none.add(schema)  # asked once per connection
            self._log.log(
                logging.DEBUG if quiet else logging.WARNING,
                "no definition of %s from %s: %s",
                schema,
                service,
                truncate_for_log(str(exc)),
            )

    async def fetch_definition(self, schema: str) -> bool:
        """Whether a definition of ``schema`` is known, asking the bridge
        (``/rosapi/message_details``, once per connection and type) when it
        is not. The client asks before publishing a type it cannot resolve
        from the bundled definitions, the graph or the user's own."""
        if schema not in self._none and not self._codecs.has_schema(schema):
            await self._fetch(schema)
        return self._codecs.resolves(schema)

    async def fetch_part(self, schema: str) -> None:
        """Fetch the definition of a message, request, response, goal,
        result or feedback type ``schema`` once per
        connection, unless it is known (quietly: a bridge without it only
        means the bridge checks what is sent)."""
        if schema not in self._none and not self._codecs.has_schema(schema):
            await self._fetch(schema, quiet=True)


def _details_request(schema: str) -> tuple[str, dict[str, str]]:
    """Which ``/rosapi`` service describes ``schema``, and its request."""
    parts = schema.split("/")
    if len(parts) == 3:
        for kind, suffix, service in _DERIVED:
            if parts[1] == kind and parts[2].endswith(suffix):
                return service, {"type": schema.removesuffix(suffix)}
    return "/rosapi/message_details", {"type": schema}


_DERIVED = (
    ("action", "_Goal", "/rosapi/action_goal_details"),
    ("action", "_Result", "/rosapi/action_result_details"),
    ("action", "_Feedback", "/rosapi/action_feedback_details"),
    ("srv", "_Request", "/rosapi/service_request_details"),
    ("srv", "_Response", "/rosapi/service_response_details"),
)


def typedefs_to_msg(schema: str, answer: Any) -> str:
    """``/rosapi/message_details`` typedefs as concatenated ``.msg`` text."""
    typedefs = answer.get("typedefs") if isinstance(answer, dict) else None
    if not isinstance(typedefs, list) or not typedefs:
        raise ValueError("no typedefs in the answer")
    blocks: list[str] = []
    main = None
    for typedef in typedefs:
        name = typedef.get("type")
        fields = typedef.get("fieldnames", [])
        types = typedef.get("fieldtypes", [])
        lengths = typedef.get("fieldarraylen", [])
        lines = []
        for i, field in enumerate(fields):
            length = lengths[i] if i < len(lengths) else -1
            suffix = "" if length == -1 else ("[]" if length == 0 else f"[{length}]")
            base = _IDL_TO_MSG.get(types[i], types[i])
            lines.append(f"{base}{suffix} {field}")
        text = "\n".join(lines) + "\n"
        if main is None and same_type_name(str(name), schema):
            main = text
        else:
            blocks.append(f"{'=' * 80}\nMSG: {name}\n{text}")
    if main is None:
        raise ValueError(f"the typedefs do not define {schema}")
    return main + "".join(blocks)
