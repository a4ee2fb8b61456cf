"""The message class of a type whatever its definitions' source: the bundled
generated class when the definitions are the bundled ones, else a class made
at run time from them (:mod:`ros_mobile_bridge.interfaces._runtime`).

A class made at run time is one per type and exact closure of definitions,
kept process-wide in a bounded least-recently-used cache
(:data:`RUNTIME_CLASSES_MAX` entries): asking again with equal definitions
gives the identical class object, from any thread. Two classes for the same
type name made from different definitions are different classes (their
``__ros_hash__`` differs when the wire format does), and a run-time class is
never the generated class of equal definitions: ``isinstance`` and ``==``
hold between instances of the one class :func:`class_for` gives. A class
dropped from the cache for the bound stays valid for whoever holds it (and
its nested fields keep the classes they were made with); asking again makes
a new one.

Pickling: a class made at run time cannot be pickled, as no module holds
it. Its instances can: each pickles as its type name, its definitions and
its field values, and unpickles through :func:`class_for` (in another
process too), so the unpickled message's class is the one :func:`class_for`
gives there.
"""

from __future__ import annotations

import threading
from collections.abc import Hashable, Mapping
from typing import TYPE_CHECKING, Any, Final

from .._errors import SchemaError
from ._bundled import bundled_definition
from ._lru import LruCache
from ._model import MsgDef
from ._typehash import definitions_closure, definitions_hash

if TYPE_CHECKING:
    from ..interfaces._base import RosMessage

__all__ = ["RUNTIME_CLASSES", "RUNTIME_CLASSES_MAX", "class_for", "known_generation", "remember"]

RUNTIME_CLASSES_MAX: Final = 512
"""How many classes (per type and definitions) :func:`class_for` keeps."""

RUNTIME_CLASSES: Final[LruCache[Hashable, type[RosMessage]]] = LruCache(RUNTIME_CLASSES_MAX)
"""The process's classes by ``(type name, closure of definitions)``; the
bundled classes that closures equal to the bundled ones resolve to are kept
too (so that the comparison is made once)."""

_BUILD: Final = threading.RLock()
"""Held while a class is made (with its nested classes), so that threads
asking for the same new type get one class."""


_KNOWN: Final[dict[tuple[str, str], type[RosMessage]]] = {}
"""Classes the user named (a subscription's class, ``rmb interface
generate``'s), by (type name, RIHS01 hash): a type of that hash decodes to
them, not to a class made at run time."""
_known_generation = [0]


def known_generation() -> int:
    """Counts the classes :func:`remember` added: codecs built before a
    change may hold other classes (part of the registry's codec keys)."""
    return _known_generation[0]


def remember(cls: type[RosMessage]) -> None:
    """Make ``cls`` (and the classes of its nested fields) the class
    :func:`class_for` gives for its type and hash, in place of one made at
    run time: a subscription naming a class ``rmb interface generate``
    wrote then receives instances of it. Bundled classes need not be
    remembered (they are found anyway); a class without a type or hash is
    ignored."""
    from ..interfaces._base import MESSAGE, MESSAGES, _plan

    pending = [cls]
    with _BUILD:
        while pending:
            current = pending.pop()
            key = getattr(current, "__ros_type__", None)
            digest_ = getattr(current, "__ros_hash__", None)
            if not isinstance(key, str) or not isinstance(digest_, str):
                continue
            if _KNOWN.get((key, digest_)) is current:
                continue
            _KNOWN[(key, digest_)] = current
            _known_generation[0] += 1
            plan = _plan(current)
            for name, kind in zip(plan.names, plan.kinds, strict=True):
                if kind in (MESSAGE, MESSAGES):
                    try:
                        pending.append(plan.nested_class(name))
                    except SchemaError:
                        continue


def class_for(key: str, defs: Mapping[str, MsgDef]) -> type[RosMessage]:
    """The message class of the type ``key`` (canonical: ``pkg/msg/Name``,
    ``pkg/srv/Name_Request``, ``pkg/action/Name_SendGoal_Request``,
    ``pkg/action/Name_FeedbackMessage``, ...) defined by ``defs``, which
    holds its definition and that of every type it uses, directly or not,
    by canonical name (other entries are ignored).

    A class :func:`remember` was given for the type and the closure's hash
    comes first. When every one of those definitions has the bundled one's fields
    (:func:`~ros_mobile_bridge.codec._bundled.bundled_definition`: names
    and types in order; defaults and constants, which do not change the
    wire format, are not compared), the bundled generated class
    (``ros_mobile_bridge.interfaces.<pkg>.<kind>.<Name>``). Else a class made
    at run time, behaving as a generated one (see
    :mod:`ros_mobile_bridge.interfaces._runtime`), its ``__ros_hash__``
    computed from ``defs``; its nested fields' classes are
    :func:`class_for`'s for their own closures (bundled ones where those are
    bundled). The same definitions give the same class object, cached
    process-wide (thread-safe, bounded: see the module's documentation).

    Raises :class:`~ros_mobile_bridge.SchemaError` when ``defs`` lacks a
    definition the type needs, or when a class cannot express it (a field
    named like a method or a Python keyword, a primitive with no Python
    type such as ``float128``)."""
    closure = definitions_closure(key, defs)
    if _KNOWN:
        known = _KNOWN.get((key, definitions_hash(key, closure)))
        if known is not None:
            return known
    ident = _ident(key, closure)
    found = RUNTIME_CLASSES.get(ident)
    if found is not None:
        return found
    with _BUILD:
        found = RUNTIME_CLASSES.get(ident)
        if found is None:
            found = _bundled(key, closure) or _build(key, closure)
            RUNTIME_CLASSES.put(ident, found)
        return found


def _ident(key: str, closure: Mapping[str, MsgDef]) -> Hashable:
    """The cache key of ``key`` with ``closure``: its definitions in name
    order (a definition holding an unhashable value, which the parsers do
    not make, is keyed by its ``repr``)."""
    ident = (key, tuple(closure[name] for name in sorted(closure)))
    try:
        hash(ident)
    except TypeError:
        return repr(ident)
    return ident


def _bundled(key: str, closure: Mapping[str, MsgDef]) -> type[RosMessage] | None:
    """The generated class of ``key`` when ``closure`` describes the bundled
    types' wire format: the same fields, of the same types, in the same
    order, all the way down (so the same RIHS01 hash). Defaults and
    constants are not compared: a REP-2011 description carries no
    constants, a server's schema may leave out defaults, and neither
    changes a message on the wire."""
    for name, msgdef in closure.items():
        bundled = bundled_definition(name)
        if bundled is None or bundled.wire != msgdef.wire:
            return None
    from ..interfaces._base import message_class

    try:
        return message_class(key)
    except SchemaError:  # pragma: no cover - every bundled type has a class
        return None


def _build(key: str, closure: Mapping[str, MsgDef]) -> type[RosMessage]:
    from ..interfaces._runtime import build_class

    msgdef = closure[key]
    nested = {ref: class_for(ref, closure) for ref in msgdef.refs()}
    cls = build_class(key, msgdef, definitions_hash(key, closure), nested)
    cls._ros_definitions_ = tuple(closure.values())  # type: ignore[attr-defined]
    cls.__reduce__ = _reduce  # type: ignore[assignment,method-assign]
    return cls


def _reduce(self: RosMessage) -> tuple[Any, ...]:
    """How an instance of a class made at run time pickles: its type name,
    its class's definitions and its field values (nested messages pickled
    the same way), rebuilt by :func:`_rebuild`."""
    cls = type(self)
    names = [name for name, _type in cls.__ros_fields__]
    values = tuple(getattr(self, name) for name in names)
    return _rebuild, (cls.__ros_type__, cls._ros_definitions_, values)  # type: ignore[attr-defined]


def _rebuild(key: str, definitions: tuple[MsgDef, ...], values: tuple[Any, ...]) -> RosMessage:
    """An instance of :func:`class_for`'s class for ``key`` and
    ``definitions``, with these field values (unpickling)."""
    cls = class_for(key, {msgdef.name: msgdef for msgdef in definitions})
    return cls._make(*values)
