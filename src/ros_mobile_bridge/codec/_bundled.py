"""The standard ROS 2 Jazzy interfaces bundled with the package.

``_interfaces.json.gz`` (written by ``scripts/gen-interfaces``) holds the
``.msg``/``.srv``/``.action`` text of every interface of the standard
packages, as shipped (comments, constants and defaults included), and the
official RIHS01 hash of every type they define or derive. Nothing is read at
import: the file is loaded once, on the first lookup, under a lock; an
interface is parsed only when one of its types is asked for, and the parsed
definitions are kept.
"""

from __future__ import annotations

import gzip
import json
import threading
from pathlib import Path
from typing import Any, Final, cast

from ._interface import Interface, ParsedInterfaces, find_in, make_interface
from ._model import MsgDef

__all__ = [
    "DATA_FILE",
    "bundled_definition",
    "bundled_hash",
    "bundled_interface",
    "bundled_interface_names",
    "bundled_packages",
    "loaded",
]

DATA_FILE: Final = Path(__file__).with_name("_interfaces.json.gz")
"""The bundled data file."""


class _Bundle:
    """The data file's content, read on first use (thread-safe)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lock = threading.Lock()
        self._doc: dict[str, Any] | None = None
        self.parsed = ParsedInterfaces(lambda name: self.interfaces().get(name))

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


_BUNDLE = _Bundle(DATA_FILE)


def loaded() -> bool:
    """Whether the data file has been read (it is, once, on the first
    lookup; never at import)."""
    return _BUNDLE.loaded


def bundled_interface(name: str) -> Interface | None:
    """The bundled interface ``name`` (``"std_msgs/msg/String"``; looked up
    tolerantly: ``"std_msgs/String"`` finds it, and ``"std_srvs/SetBool"``
    finds the service), or None. Loads the data file on first use."""
    found = find_in(_BUNDLE.interfaces().get, name)
    return None if found is None else make_interface(*found, "bundled")


def bundled_interface_names() -> list[str]:
    """Every bundled interface's name (``"pkg/kind/Name"``), sorted."""
    return sorted(_BUNDLE.interfaces())


def bundled_packages() -> dict[str, str]:
    """The bundled packages and their versions (``"supplement"`` for the
    packages written from their fields, see ``scripts/interfaces/``)."""
    return dict(_BUNDLE.packages())


def bundled_hash(type_name: str) -> str | None:
    """The official ``RIHS01_`` hash of ``type_name`` (any type a bundled
    interface defines or derives: ``pkg/srv/X_Event``,
    ``pkg/action/X_SendGoal_Request``, ...), or None. Looked up tolerantly."""
    found = find_in(_BUNDLE.hashes().get, type_name)
    return None if found is None else found[1]


def bundled_definition(type_name: str) -> MsgDef | None:
    """The parsed definition of the canonical ``type_name`` from the bundled
    texts (a message, or a type derived from a service or an action), or
    None. Only the interface that defines it is parsed, once."""
    return _BUNDLE.parsed.definition(type_name)
