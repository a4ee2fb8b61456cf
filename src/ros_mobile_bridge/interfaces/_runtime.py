"""Message classes made at run time, from a definition learnt while running
(a robot's type description, a server's schema, a local workspace).

:func:`build_class` writes the class's source with the same
:class:`~._emit.ClassWriter` the generated modules come from, and executes
it in a namespace holding ``_base``'s helpers and the nested fields'
classes: a class made here is the class a generated module would hold for
the same definition (same base, ``__slots__``, ``__ros_type__``,
``__ros_hash__``, ``__ros_fields__``, constants, keyword constructor with
its defaults and checks), except that its ``__module__`` is this module,
which does not hold it (it cannot be imported by name, so the class itself
cannot be pickled; :mod:`ros_mobile_bridge.codec._classes` gives its
instances a way to be), and its docstring has no ``.msg`` comments.
:func:`ros_mobile_bridge.codec._classes.class_for` is the way in: it caches
the classes and reuses the bundled ones.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from .._errors import SchemaError
from ..codec._model import MsgDef
from . import _base
from ._base import RosMessage, own_plan
from ._emit import ClassWriter, Message, location

__all__ = ["RUNTIME_MODULE", "build_class"]

RUNTIME_MODULE = __name__
"""The ``__module__`` of every class made at run time."""


class _Writer(ClassWriter):
    """Refers to a nested field's class by a name of the namespace the
    source runs in (``_c0``, ``_c1``, ...); annotations name it as rclpy's
    ``repr`` does (``geometry_msgs.msg.Point``), and are never evaluated."""

    def __init__(self, type_hash: str) -> None:
        super().__init__(lambda _name: type_hash, check_shadowing=False)
        self.names: dict[str, str] = {}

    def ref(self, type_name: str) -> tuple[str, str]:
        name = self.names.setdefault(type_name, f"_c{len(self.names)}")
        pkg, kind, qual = location(type_name)
        return f"{pkg}.{kind}.{qual}", name


def build_class(
    type_name: str,
    msgdef: MsgDef,
    type_hash: str,
    nested: Mapping[str, type[RosMessage]],
) -> type[RosMessage]:
    """A new message class for the message type ``type_name`` (canonical:
    ``pkg/msg/Name``, ``pkg/srv/Name_Request``, ...) defined by ``msgdef``
    (a :class:`~ros_mobile_bridge.codec._model.MsgDef`), with the hash
    ``type_hash``; ``nested`` holds the class of every type its fields use,
    by type name. Its ``__qualname__`` is the generated class's
    (``Name.Request``), its ``repr`` rclpy's (``pkg.srv.Name.Request(...)``).
    Raises :class:`~ros_mobile_bridge.SchemaError` when the classes cannot
    express the definition (a field named like a method or a keyword, or
    twice, a primitive with no Python type) or a nested class is missing."""
    pkg, kind, qualname = location(type_name)
    writer = _Writer(type_hash)
    summary = f"The ROS message ``{type_name}``, a class made at run time from its definition."
    lines = writer.message(Message(type_name, qualname, summary, [], msgdef), "")
    namespace: dict[str, Any] = {"__name__": RUNTIME_MODULE, "RosMessage": RosMessage}
    namespace["ClassVar"] = ClassVar
    for helper in writer.helpers:
        namespace[helper] = getattr(_base, helper)
    fields: dict[str, type[RosMessage]] = {}
    for ref, local in writer.names.items():
        sub = nested.get(ref)
        if sub is None:
            raise SchemaError(f"{type_name}: no class for {ref!r}, which it uses")
        namespace[local] = sub
    for spec in msgdef.fields:
        if spec.ref is not None:
            fields[spec.name] = nested[spec.ref]
    # annotations stay text, as in a generated module
    source = "from __future__ import annotations\n\n" + "\n".join(lines) + "\n"
    try:
        code = compile(source, f"<class {type_name}>", "exec", dont_inherit=True)
    except SyntaxError as exc:  # a definition no parser here makes (a field twice)
        raise SchemaError(f"{type_name}: no class can express it: {exc.msg}") from None
    exec(code, namespace)
    cls: type[RosMessage] = namespace[qualname.rpartition(".")[2]]
    cls.__qualname__ = qualname
    init = cls.__dict__.get("__init__")
    if init is not None:
        init.__qualname__ = f"{qualname}.__init__"
    own_plan(cls, f"{pkg}.{kind}.{qualname}", fields)
    return cls
