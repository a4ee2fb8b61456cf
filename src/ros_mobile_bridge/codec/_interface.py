"""One interface file (``.msg``, ``.srv``, ``.action``) and the definitions
it yields: what the bundled interfaces and a local workspace share."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Literal

from ._model import MsgDef
from ._names import lookup_candidates, split_type_name
from ._parse import action_texts, parse_ros2msg, parse_srv

__all__ = [
    "KINDS",
    "Interface",
    "InterfaceKind",
    "ParsedInterfaces",
    "find_in",
    "interface_definitions",
    "make_interface",
    "owner_interface",
]

InterfaceKind = Literal["msg", "srv", "action"]
KINDS: Final[tuple[InterfaceKind, ...]] = ("msg", "srv", "action")


@dataclass(frozen=True)
class Interface:
    """One interface definition: ``name`` is ``"pkg/kind/Name"``, ``kind``
    ``"msg"``, ``"srv"`` or ``"action"``, ``text`` the file's text (a
    ``.msg``, ``.srv`` or ``.action`` file, comments included) and
    ``origin`` ``"bundled"`` or the path of the file it was read from."""

    name: str
    kind: InterfaceKind
    text: str
    origin: str


def interface_definitions(name: str, text: str) -> dict[str, MsgDef]:
    """Every definition the interface ``name`` (``pkg/kind/Name``) with the
    file text ``text`` defines, by canonical name: the message itself; a
    service's ``_Request`` and ``_Response``; an action's ``_Goal``,
    ``_Result``, ``_Feedback``, ``_SendGoal_Request``/``_Response``,
    ``_GetResult_Request``/``_Response`` and ``_FeedbackMessage``. Raises
    :class:`~ros_mobile_bridge.SchemaError` when the text does not parse."""
    kind = name.split("/")[1]
    if kind == "srv":
        return parse_srv(name, text)
    if kind == "action":
        out: dict[str, MsgDef] = {}
        for derived, derived_text in action_texts(name, text).items():
            _mains, defs = parse_ros2msg(derived, derived_text)
            out[derived] = defs[derived]
        return out
    _mains, defs = parse_ros2msg(name, text)
    return {name: defs[name]}


_DERIVED: Final = {
    "srv": ("_Request", "_Response"),
    "action": (
        "_SendGoal_Request",
        "_SendGoal_Response",
        "_GetResult_Request",
        "_GetResult_Response",
        "_FeedbackMessage",
        "_Goal",
        "_Result",
        "_Feedback",
    ),
}


def owner_interface(type_name: str) -> str | None:
    """The interface whose file defines the canonical ``type_name`` when it
    is a derived type (``pkg/srv/X_Request`` -> ``pkg/srv/X``,
    ``pkg/action/X_SendGoal_Request`` -> ``pkg/action/X``), else None."""
    pkg, kind, typ = split_type_name(type_name)
    for suffix in _DERIVED.get(kind or "", ()):
        if typ.endswith(suffix) and len(typ) > len(suffix):
            return f"{pkg}/{kind}/{typ[: -len(suffix)]}"
    return None


class ParsedInterfaces:
    """Definitions parsed from interface texts on demand, each interface
    once (thread-safe). ``text_of(name)`` gives an interface's text or None."""

    def __init__(self, text_of: Callable[[str], str | None]) -> None:
        self._text_of = text_of
        self._lock = threading.Lock()
        self._parsed: dict[str, dict[str, MsgDef]] = {}

    def definition(self, type_name: str) -> MsgDef | None:
        """The definition of the canonical ``type_name`` (a message, or a type
        derived from a service or an action), or None. Raises
        :class:`~ros_mobile_bridge.SchemaError` when the text that should
        define it does not parse."""
        for interface in (type_name, owner_interface(type_name)):
            if interface is None:
                continue
            defs = self._parsed.get(interface)
            if defs is None:
                text = self._text_of(interface)
                if text is None:
                    continue
                parsed = interface_definitions(interface, text)
                with self._lock:
                    defs = self._parsed.setdefault(interface, parsed)
            found = defs.get(type_name)
            if found is not None:
                return found
        return None


def find_in(texts: Callable[[str], str | None], name: str) -> tuple[str, str] | None:
    """``(canonical name, text)`` of the first of ``name``'s tolerant
    spellings that ``texts`` knows, or None (also for a malformed name)."""
    try:
        candidates = lookup_candidates(name)
    except (TypeError, ValueError):
        return None
    for candidate in candidates:
        text = texts(candidate)
        if text is not None:
            return candidate, text
    return None


def make_interface(name: str, text: str, origin: str) -> Interface:
    """An :class:`Interface` for the canonical ``name``."""
    kind = name.split("/")[1]
    assert kind in KINDS
    return Interface(name, kind, text, origin)
