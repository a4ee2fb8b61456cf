"""The standard ROS 2 Jazzy interfaces bundled with the package.

``_interfaces.json.gz`` (written by ``scripts/gen-interfaces``) holds the
``.msg``/``.srv``/``.action`` text of every interface of the standard
packages, as shipped (comments, constants and defaults included), and the
official RIHS01 hash of every type they define or derive. Nothing is read at
import: the file is loaded once, on the first lookup, under a lock; each
interface is parsed only when one of its types is asked for, and the parsed
definitions are kept.
"""

from __future__ import annotations

import gzip
import json
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal, cast

from ._model import MsgDef
from ._names import lookup_candidates, split_type_name
from ._parse import action_texts, parse_ros2msg, parse_srv

__all__ = [
    "DATA_FILE",
    "Interface",
    "InterfaceKind",
    "bundled_definition",
    "bundled_hash",
    "bundled_interface",
    "bundled_interface_names",
    "interface_definitions",
    "owner_interface",
]

DATA_FILE: Final = Path(__file__).with_name("_interfaces.json.gz")
"""The bundled data file."""

InterfaceKind = Literal["msg", "srv", "action"]


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


class _Bundle:
    """The data file's content, read on first use (thread-safe)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lock = threading.Lock()
        self._doc: dict[str, Any] | None = None
        self._parsed: dict[str, dict[str, MsgDef]] = {}

    @property
    def loaded(self) -> bool:
        """Whether the data file has been read."""
        return self._doc is not None

    def _load(self) -> dict[str, Any]:
        doc = self._doc
        if doc is not None:
            return doc
        with self._lock:
            if self._doc is None:
                self._doc = json.loads(gzip.decompress(self.path.read_bytes()))
            return self._doc

    def interfaces(self) -> dict[str, str]:
        return cast("dict[str, str]", self._load()["interfaces"])

    def hashes(self) -> dict[str, str]:
        return cast("dict[str, str]", self._load()["hashes"])

    def packages(self) -> dict[str, str]:
        return cast("dict[str, str]", self._load()["packages"])

    def parsed(
        self, interface: str, build: Callable[[str, str], dict[str, MsgDef]]
    ) -> dict[str, MsgDef]:
        """The definitions ``interface``'s text defines (parsed once)."""
        found = self._parsed.get(interface)
        if found is None:
            text = self.interfaces()[interface]
            found = build(interface, text)
            with self._lock:
                found = self._parsed.setdefault(interface, found)
        return found


_BUNDLE = _Bundle(DATA_FILE)


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


_DERIVED: Final = (
    ("srv", ("_Request", "_Response", "_Event")),
    (
        "action",
        (
            "_SendGoal_Request",
            "_SendGoal_Response",
            "_SendGoal_Event",
            "_GetResult_Request",
            "_GetResult_Response",
            "_GetResult_Event",
            "_FeedbackMessage",
            "_SendGoal",
            "_GetResult",
            "_Goal",
            "_Result",
            "_Feedback",
        ),
    ),
)


def owner_interface(type_name: str) -> str | None:
    """The interface name whose file defines the canonical ``type_name``
    (``pkg/srv/X_Request`` -> ``pkg/srv/X``), or None for a plain message
    name (``pkg/msg/X`` is its own interface)."""
    pkg, kind, typ = split_type_name(type_name)
    for derived_kind, suffixes in _DERIVED:
        if kind != derived_kind:
            continue
        for suffix in suffixes:
            if typ.endswith(suffix) and len(typ) > len(suffix):
                return f"{pkg}/{kind}/{typ[: -len(suffix)]}"
    return None


def bundled_interface(name: str) -> Interface | None:
    """The bundled interface ``name`` (``"std_msgs/msg/String"``; looked up
    tolerantly: ``"std_msgs/String"`` finds it, and ``"std_srvs/SetBool"``
    finds the service), or None. Loads the data file on first use."""
    try:
        candidates = lookup_candidates(name)
    except (TypeError, ValueError):
        return None
    interfaces = _BUNDLE.interfaces()
    for candidate in candidates:
        text = interfaces.get(candidate)
        if text is not None:
            kind: InterfaceKind = candidate.split("/")[1]  # type: ignore[assignment]
            return Interface(candidate, kind, text, "bundled")
    return None


def bundled_interface_names() -> list[str]:
    """Every bundled interface's name (``"pkg/kind/Name"``), sorted."""
    return sorted(_BUNDLE.interfaces())


def bundled_hash(type_name: str) -> str | None:
    """The official ``RIHS01_`` hash of ``type_name`` (any type a bundled
    interface defines or derives: ``pkg/srv/X_Event``,
    ``pkg/action/X_SendGoal_Request``, ...), or None. Looked up tolerantly."""
    try:
        candidates = lookup_candidates(type_name)
    except (TypeError, ValueError):
        return None
    hashes = _BUNDLE.hashes()
    for candidate in candidates:
        found = hashes.get(candidate)
        if found is not None:
            return found
    return None


def bundled_definition(type_name: str) -> MsgDef | None:
    """The parsed definition of the canonical ``type_name`` from the bundled
    texts (a message, or a type derived from a service or an action), or
    None. Only the interface that defines it is parsed, once."""
    interfaces = _BUNDLE.interfaces()
    owner = owner_interface(type_name)
    for interface in (type_name, owner):
        if interface is not None and interface in interfaces:
            defs = _BUNDLE.parsed(interface, interface_definitions)
            found = defs.get(type_name)
            if found is not None:
                return found
    return None
