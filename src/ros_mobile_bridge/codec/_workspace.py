"""Interface definitions read from local directories (a colcon workspace, a
ROS installation): what :attr:`ClientOptions.interface_paths` and
``$AMENT_PREFIX_PATH`` point at."""

from __future__ import annotations

import logging
import os
import re
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Final

from .._checks import check_interface_paths
from .._errors import SchemaError
from ._bundled import bundled_interface, bundled_interface_names
from ._interface import KINDS, Interface, ParsedInterfaces, find_in, make_interface
from ._model import MsgDef

__all__ = [
    "MAX_INTERFACE_BYTES",
    "MAX_INTERFACE_FILES",
    "InterfacePaths",
    "ament_prefix_paths",
    "find_interface",
    "interface_names",
    "interface_paths_for",
]

MAX_INTERFACE_FILES: Final = 20_000
"""Interface files one :class:`InterfacePaths` indexes (a full ROS desktop
installation has about 1,500)."""
MAX_INTERFACE_BYTES: Final = 16 * 1024 * 1024
"""Bytes of interface text one :class:`InterfacePaths` reads in all."""

_NAME: Final = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_PACKAGE_NAME: Final = re.compile(r"<name>\s*([A-Za-z][A-Za-z0-9_]*)\s*</name>")
_log = logging.getLogger("ros_mobile_bridge")


def ament_prefix_paths() -> tuple[str, ...]:
    """The prefixes ``$AMENT_PREFIX_PATH`` lists (``os.pathsep``-separated;
    empty entries dropped), or ``()`` when it is not set."""
    value = os.environ.get("AMENT_PREFIX_PATH", "")
    return tuple(p for p in value.split(os.pathsep) if p)


class InterfacePaths:
    """Interface files under local directories, found by name.

    Each path is an install prefix (``share/<pkg>/{msg,srv,action}/``; also
    what ``$AMENT_PREFIX_PATH`` lists), a ``share`` directory
    (``<pkg>/{msg,srv,action}/``), or one package's source directory (a
    ``package.xml`` beside ``msg/``, ``srv/``, ``action/``). An earlier path
    wins over a later one for the same name.

    Nothing is read at construction: the directories are listed on the first
    lookup and a file is read when its interface is first asked for, each
    once. At most ``max_files`` files are indexed and ``max_bytes`` bytes of
    text read; past either, files are skipped, counted in :attr:`skipped`
    and logged once. An unreadable or undecodable file is logged, counted in
    :attr:`unreadable` and skipped; so is a text that does not parse.
    Thread-safe.
    """

    def __init__(
        self,
        paths: Sequence[str | os.PathLike[str]] = (),
        *,
        max_files: int = MAX_INTERFACE_FILES,
        max_bytes: int = MAX_INTERFACE_BYTES,
    ) -> None:
        self.paths = check_interface_paths(paths)
        self.max_files = max_files
        self.max_bytes = max_bytes
        self.files_read = 0
        """Interface files read so far."""
        self.bytes_read = 0
        """Bytes of interface text read so far."""
        self.skipped = 0
        """Files left out because of ``max_files`` or ``max_bytes``."""
        self.unreadable = 0
        """Files that could not be read, decoded or parsed."""
        self._lock = threading.RLock()
        self._index: dict[str, Path] | None = None
        self._texts: dict[str, str | None] = {}
        self._warned = False
        self._bad: set[str] = set()
        self._parsed = ParsedInterfaces(self._text)

    def __repr__(self) -> str:
        return f"InterfacePaths({list(self.paths)!r})"

    # ------------------------------------------------------------------ index

    def _over(self, what: str) -> None:
        self.skipped += 1
        if not self._warned:
            self._warned = True
            _log.warning("interface paths: %s reached; further interface files are skipped", what)

    def _packages(self, root: Path) -> list[tuple[str, Path]]:
        """``(package name, package dir)`` for the interface packages ``root``
        holds, in name order."""
        if (root / "package.xml").is_file():
            try:
                xml = (root / "package.xml").read_text(encoding="utf-8", errors="replace")
            except OSError:
                xml = ""
            found = _PACKAGE_NAME.search(xml)
            return [(found.group(1) if found else root.name, root)]
        share = root / "share"
        base = share if share.is_dir() else root
        try:
            children = sorted(base.iterdir())
        except OSError as exc:
            _log.warning("interface paths: cannot list %s: %s", base, exc)
            return []
        return [
            (child.name, child)
            for child in children
            if _NAME.fullmatch(child.name) and any((child / k).is_dir() for k in KINDS)
        ]

    def _build_index(self) -> dict[str, Path]:
        index: dict[str, Path] = {}
        count = 0
        for path in self.paths:
            for package, directory in self._packages(Path(path)):
                for kind in KINDS:
                    folder = directory / kind
                    if not folder.is_dir():
                        continue
                    try:
                        files = sorted(folder.glob(f"*.{kind}"))
                    except OSError as exc:
                        _log.warning("interface paths: cannot list %s: %s", folder, exc)
                        continue
                    for file in files:
                        if not _NAME.fullmatch(file.stem):
                            continue
                        if count >= self.max_files:
                            self._over(f"max_files={self.max_files}")
                            continue
                        count += 1
                        index.setdefault(f"{package}/{kind}/{file.stem}", file)
        return index

    def _get_index(self) -> dict[str, Path]:
        index = self._index
        if index is None:
            with self._lock:
                if self._index is None:
                    self._index = self._build_index()
                index = self._index
        return index

    def _text(self, name: str) -> str | None:
        path = self._get_index().get(name)
        if path is None:
            return None
        with self._lock:
            if name in self._texts:
                return self._texts[name]
            text: str | None = None
            try:
                size = path.stat().st_size
                if self.bytes_read + size > self.max_bytes:
                    self._over(f"max_bytes={self.max_bytes}")
                else:
                    data = path.read_bytes()[: self.max_bytes - self.bytes_read]
                    self.bytes_read += len(data)
                    self.files_read += 1
                    text = data.decode("utf-8")
            except (OSError, UnicodeDecodeError) as exc:
                self.unreadable += 1
                _log.warning("interface paths: cannot read %s: %s", path, exc)
            self._texts[name] = text
            return text

    # ------------------------------------------------------------------ lookups

    def names(self) -> list[str]:
        """Every interface found (``"pkg/kind/Name"``), sorted."""
        return sorted(self._get_index())

    def text(self, name: str) -> str | None:
        """The file text of the interface with the canonical ``name``
        (``"pkg/kind/Name"``, no tolerance), or None."""
        return self._text(name)

    def find(self, name: str) -> Interface | None:
        """The interface ``name`` (looked up tolerantly, as
        :func:`bundled_interface` does) with ``origin`` its file's path, or
        None when no path has it (or its file cannot be read)."""
        found = find_in(self._text, name)
        if found is None:
            return None
        canonical, text = found
        return make_interface(canonical, text, str(self._get_index()[canonical]))

    def definition(self, type_name: str) -> MsgDef | None:
        """The parsed definition of the canonical ``type_name`` (a message or
        a type derived from a service or an action), or None. A text that
        does not parse is logged, counted in :attr:`unreadable` and skipped."""
        if not self.paths or type_name in self._bad:
            return None
        try:
            return self._parsed.definition(type_name)
        except SchemaError as exc:
            with self._lock:
                if type_name in self._bad:
                    return None
                self._bad.add(type_name)
                self.unreadable += 1
            _log.warning("interface paths: %s does not parse: %s", type_name, exc)
            return None


_SHARED_LOCK = threading.Lock()
_SHARED: dict[tuple[str, ...], InterfacePaths] = {}
SHARED_PATHS_MAX: Final = 32
"""How many distinct path lists :func:`interface_paths_for` keeps (oldest
out first)."""


def interface_paths_for(
    paths: Sequence[str | os.PathLike[str]] = (), *, ament_prefix_path: bool = True
) -> InterfacePaths:
    """The process's :class:`InterfacePaths` for ``paths`` followed by the
    prefixes of ``$AMENT_PREFIX_PATH`` (when ``ament_prefix_path`` and the
    variable is set): one per distinct list, so that every connection with
    the same options scans the directories once (a file changed after that
    is seen by a new process). ``TypeError`` for a path that is not one."""
    key = check_interface_paths(paths) + (ament_prefix_paths() if ament_prefix_path else ())
    with _SHARED_LOCK:
        found = _SHARED.get(key)
        if found is None:
            found = InterfacePaths(key)
            _SHARED[key] = found
            while len(_SHARED) > SHARED_PATHS_MAX:
                del _SHARED[next(iter(_SHARED))]
        return found


def find_interface(
    name: str, paths: Sequence[str | os.PathLike[str]] = (), *, ament_prefix_path: bool = True
) -> Interface | None:
    """The interface ``name`` (``"pkg/kind/Name"``, looked up tolerantly:
    ``"std_msgs/String"``), from the local ``paths`` and
    ``$AMENT_PREFIX_PATH`` first (see :class:`ClientOptions.interface_paths
    <ros_mobile_bridge.ClientOptions>`; ``origin`` is the file's path), else
    the bundled one (``origin`` ``"bundled"``), else None."""
    local = interface_paths_for(paths, ament_prefix_path=ament_prefix_path).find(name)
    return local if local is not None else bundled_interface(name)


def interface_names(
    paths: Sequence[str | os.PathLike[str]] = (), *, ament_prefix_path: bool = True
) -> list[str]:
    """Every interface name :func:`find_interface` knows, sorted: the local
    ones and the bundled ones."""
    local = interface_paths_for(paths, ament_prefix_path=ament_prefix_path).names()
    return sorted({*local, *bundled_interface_names()})
