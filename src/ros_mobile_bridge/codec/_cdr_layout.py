"""What the generated CDR decoder (:mod:`._cdr`) and encoder
(:mod:`._cdr_encode`) share: the primitives' struct formats, sizes and
dtypes, a class's fields in wire order (:func:`class_fields`), what is
statically known of a position's alignment (:func:`first_alignment`,
:func:`residue`, :func:`meet`), struct formats merged across fields
(:func:`compact`), and compiling a generated function with its source kept
for tracebacks (:func:`compile_function`)."""

from __future__ import annotations

import linecache
import struct
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Final

from .._errors import SchemaError
from ..interfaces._base import _DTYPES
from ._model import SEQUENCE, FieldSpec, MsgDef

if TYPE_CHECKING:
    from ..interfaces._base import RosMessage

__all__ = [
    "DTYPES",
    "FORMATS",
    "LITTLE",
    "SIZES",
    "Classes",
    "Field",
    "Invalid",
    "SourceWriter",
    "class_fields",
    "compact",
    "compile_function",
    "first_alignment",
    "meet",
    "residue",
]

Classes = Callable[[str], "type[RosMessage]"]
"""The class of each message type (canonical ``pkg/msg/Name``) of a closure."""

FORMATS: Final[dict[str, str]] = {
    # the struct format of each primitive; its size is its CDR alignment
    "bool": "?",
    "byte": "B",  # the ROS 2 octet, 0..255, as the classes hold it
    "char": "B",
    "int8": "b",
    "uint8": "B",
    "int16": "h",
    "uint16": "H",
    "int32": "i",
    "uint32": "I",
    "int64": "q",
    "uint64": "Q",
    "float32": "f",
    "float64": "d",
}
DTYPES: Final = _DTYPES
"""A numeric or bool array's element type -> its numpy dtype (the classes' table)."""
SIZES: Final[dict[str, int]] = {base: struct.calcsize(fmt) for base, fmt in FORMATS.items()}
LITTLE: Final = 256
"""The encapsulation header of a little-endian CDR payload (``00 01``) read as ``<H``."""


class Invalid(Exception):
    """A payload the generated code found invalid (the reason is the message)."""


# --------------------------------------------------------------------------- layout


class Field:
    """One field of a class as the generators need it: its attribute name
    (the class's), its definition and its nested class (if any)."""

    __slots__ = ("attr", "cls", "spec")

    def __init__(self, attr: str | None, spec: FieldSpec, cls: type[RosMessage] | None) -> None:
        self.attr = attr
        """The slot name; None for the hidden placeholder of an empty message."""
        self.spec = spec
        self.cls = cls


def class_fields(
    name: str, defs: Mapping[str, MsgDef], classes: Classes, cache: dict[str, list[Field]]
) -> list[Field]:
    """The fields of type ``name`` in wire order, checked against its class;
    raises :class:`SchemaError` for what the generated codecs do not read."""
    found = cache.get(name)
    if found is not None:
        return found
    msgdef = defs.get(name)
    if msgdef is None:
        raise SchemaError(f"no definition of {name!r} in the closure")
    cls = classes(name)
    visible = msgdef.visible_fields
    attrs = [attr for attr, _type in cls.__ros_fields__]
    if len(attrs) != len(visible):
        raise SchemaError(
            f"class {cls.__qualname__} has {len(attrs)} fields, definition {name!r} has "
            f"{len(visible)}"
        )
    fields: list[Field] = []
    if not visible:
        fields.append(Field(None, msgdef.fields[0], None))
    for attr, spec in zip(attrs, visible, strict=True):
        if not attr.isidentifier() or attr.startswith("__"):
            raise SchemaError(f"type {name!r} has a field the codec cannot name: {attr!r}")
        sub = None
        if spec.ref is not None:
            sub = classes(spec.ref)
        elif spec.base != "string" and spec.base not in FORMATS:
            raise SchemaError(
                f"type {name!r}, field {attr!r}: primitive type {spec.base!r} is not supported "
                "by the CDR codec"
            )
        fields.append(Field(attr, spec, sub))
    cache[name] = fields
    return fields


def first_alignment(
    name: str, defs: Mapping[str, MsgDef], classes: Classes, cache: dict[str, list[Field]]
) -> int:
    """The alignment of the first thing type ``name`` puts on the wire."""
    spec = class_fields(name, defs, classes, cache)[0].spec
    if spec.cardinality == SEQUENCE or spec.base == "string":
        return 4
    if spec.ref is not None:
        return first_alignment(spec.ref, defs, classes, cache)
    assert spec.base is not None
    return SIZES[spec.base]


def residue(align: int) -> int:
    """The payload offsets aligned to ``align`` in the body (which starts at
    offset 4) are those ``== residue(align)`` modulo ``align``."""
    return 4 % align


def meet(a: tuple[int, int], b: tuple[int, int]) -> tuple[int, int]:
    """What is known of a position that is either ``a`` or ``b``, each an
    ``(modulus, remainder)`` pair."""
    mod = min(a[0], b[0])
    while mod > 1 and a[1] % mod != b[1] % mod:
        mod //= 2
    return mod, a[1] % mod


def compact(fmt: str, *, trim: bool = False) -> str:
    """``fmt`` with runs of one code counted (``"ddd4x4x"`` -> ``"3d8x"``);
    with ``trim``, without its trailing pad bytes (an unpack need not skip them)."""
    out: list[tuple[str, int]] = []
    count = ""
    for char in fmt:
        if char.isdigit():
            count += char
            continue
        number = int(count) if count else 1
        count = ""
        if out and out[-1][0] == char:
            out[-1] = (char, out[-1][1] + number)
        else:
            out.append((char, number))
    while trim and out and out[-1][0] == "x":
        out.pop()
    return "".join(f"{n}{c}" if n > 1 else c for c, n in out)


def compile_function(source: str, kind: str, key: str, namespace: dict[str, Any]) -> Any:
    """Compile and run the generated ``source``; return its ``function``,
    with the text as its ``__source__`` attribute."""
    filename = f"<cdr {kind} of {key}>"
    exec(compile(source, filename, "exec"), namespace)
    # tracebacks and debuggers show the generated lines
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    function = namespace["function"]
    function.__source__ = source
    return function


# --------------------------------------------------------------------------- decoder


class SourceWriter:
    """The text of one generated function, as a writer builds it: its lines
    (at an indent), fresh local names, and the constants its module holds.
    The decoder's and the encoder's writers build on it."""

    def __init__(self, key: str, defs: Mapping[str, MsgDef], classes: Classes, indent: int) -> None:
        self.key = key
        self.defs = defs
        self.classes = classes
        self.fields: dict[str, list[Field]] = {}
        self.lines: list[str] = []
        self.indent = indent
        self.names = 0
        self.namespace: dict[str, Any] = {}
        self.constants: dict[int, str] = {}

    def emit(self, line: str) -> None:
        self.lines.append("    " * self.indent + line)

    def local(self, prefix: str) -> str:
        """A local name not used before (``prefix`` and a number)."""
        self.names += 1
        return f"{prefix}{self.names}"

    def const(self, value: object, prefix: str) -> str:
        """A global of the generated module holding ``value``."""
        name = self.constants.get(id(value))
        if name is None:
            name = f"_{prefix}{len(self.constants)}"
            self.constants[id(value)] = name
            self.namespace[name] = value
        return name
