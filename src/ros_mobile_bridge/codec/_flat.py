"""A direct CDR -> dict decoder for the commonest message shapes.

The general decoder (``_registry._make_cdr_decoder``) lets rosbags build a
message object and converts that to a dict: two passes and a check call per
string. For a type whose fields are, all the way down, scalar numbers,
``bool``, ``byte``, ``char``, ``string`` and nested messages of the same
kind (``std_msgs/String``, ``Header``, ``Twist``, ``Pose``, ``Imu``
without its covariances, ...), :func:`build_flat_decoder` generates one
function that reads the little-endian payload straight into the dict, about
three times faster for a ``std_msgs/String``.

It gives exactly the dict the general decoder gives, and never an error of
its own: any payload it cannot read as plainly valid (big-endian, too short,
a string without its terminator or not UTF-8, bytes left over, not a
byte-formatted memoryview) is handed to the general decoder, which decodes
it or raises its :class:`DecodeError` as it always did. Arrays and
sequences, ``wstring`` and ``wchar`` are not covered: such a type keeps the
general decoder."""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping
from typing import Any

from ._model import DUMMY_FIELD, SCALAR, MsgDef

__all__ = ["build_flat_decoder"]

_FORMATS: dict[str, tuple[str, int]] = {
    # (struct format, size = CDR alignment)
    "bool": ("?", 1),
    "byte": ("B", 1),  # the ROS 2 octet, 0..255 (the general path masks rosbags' int8)
    "char": ("B", 1),
    "int8": ("b", 1),
    "uint8": ("B", 1),
    "int16": ("h", 2),
    "uint16": ("H", 2),
    "int32": ("i", 4),
    "uint32": ("I", 4),
    "int64": ("q", 8),
    "uint64": ("Q", 8),
    "float32": ("f", 4),
    "float64": ("d", 8),
}


class _Fallback(Exception):
    """The payload is not one the generated decoder reads itself."""


def _flat(key: str, defs: Mapping[str, MsgDef], depth: int = 0) -> bool:
    """Whether ``key`` is made only of what the generated decoder reads."""
    msgdef = defs.get(key)
    if msgdef is None or depth > 32:
        return False
    for field in msgdef.fields:
        if field.cardinality != SCALAR:
            return False
        if field.ref is not None:
            if not _flat(field.ref, defs, depth + 1):
                return False
        elif field.base == "string":
            if field.string_bound:  # the general path may check the bound
                return False
        elif field.base not in _FORMATS:
            return False
    return True


class _Writer:
    """Generates the statements reading one type's fields, nested types
    inline; ``b`` is the offset in the CDR body (alignment counts from it).

    Up to the first string the offsets are known when generating: those
    fields, the encapsulation header and the first string's length are read
    by one ``unpack_from`` at the top (:attr:`lead`), and no ``b`` is kept
    for them (:attr:`static` is the known offset; None once past a string).
    After a string, each run of scalars whose alignments divide the first's
    is read by one ``unpack_from`` too (:attr:`run`): aligned to the first,
    ``b`` makes the rest's offsets known."""

    def __init__(self, defs: Mapping[str, MsgDef]) -> None:
        self.defs = defs
        self.lines: list[str] = []
        self.names = 0
        self.structs: dict[str, str] = {}
        self.lead = "<H2x"
        """The format of the first read: the header, then the body's leading fields."""
        self.lead_targets = ["h"]
        self.static: int | None = 0
        self.run = "<"
        """The format of the open run of scalars after a string (``"<"``: none)."""
        self.run_targets: list[str] = []
        self.run_align = 1
        self.run_size = 0

    def _local(self) -> str:
        self.names += 1
        return f"x{self.names}"

    def unpack(self, fmt: str) -> str:
        name = self.structs.get(fmt)
        if name is None:
            name = self.structs[fmt] = f"_s{len(self.structs)}"
        return name

    def _lead_read(self, fmt: str, align: int, target: str) -> int:
        """Add a field at the next offset aligned to ``align`` to the first
        read; return that offset."""
        assert self.static is not None
        offset = (self.static + align - 1) & -align
        if offset > self.static:
            self.lead += f"{offset - self.static}x"
        self.lead += fmt
        self.lead_targets.append(target)
        self.static = offset + align
        return offset

    def _run_read(self, fmt: str, align: int, target: str) -> None:
        """Add a scalar after a string to the open run, or open one."""
        if self.run_targets and align > self.run_align:
            self._flush()
        if not self.run_targets:
            self.run_align = align
        offset = (self.run_size + align - 1) & -align
        if offset > self.run_size:
            self.run += f"{offset - self.run_size}x"
        self.run += fmt
        self.run_targets.append(target)
        self.run_size = offset + align

    def _flush(self) -> None:
        """Emit the open run's read, if any."""
        if not self.run_targets:
            return
        align = self.run_align
        if align > 1:
            self.lines.append(f"b = (b + {align - 1}) & -{align}")
        self.lines += [
            f"{', '.join(self.run_targets)}, = {self.unpack(self.run)}(p, b + 4)",
            f"b += {self.run_size}",
        ]
        self.run, self.run_targets, self.run_size = "<", [], 0

    def _string(self, target: str) -> None:
        # ``e``: the payload index of the string's terminating NUL
        if self.static is not None:
            offset = self._lead_read("I", 4, "n")
            self.static = None
            start = f"{offset + 8}"
            self.lines.append(f"e = {offset + 7} + n")
        else:
            self._flush()
            start = "b + 8"
            self.lines += [
                "b = (b + 3) & -4",
                f"n = {self.unpack('<I')}(p, b + 4)[0]",
                "e = b + 7 + n",
            ]
        self.lines += [
            "if n < 1 or e >= size or p[e] != 0: raise _Fallback",
            f"{target} = str(p[{start} : e], 'utf-8')",
            "b = e - 3",
        ]

    def message(self, key: str) -> str:
        """Emit the reads of ``key``'s fields; return its dict expression."""
        msgdef = self.defs[key]
        visible = msgdef.visible_fields
        items: list[str] = []
        for field in msgdef.fields:
            if field.ref is not None:
                items.append(f"{field.name!r}: {self.message(field.ref)}")
                continue
            assert field.base is not None
            target = self._local()
            if field.base == "string":
                self._string(target)
            elif self.static is not None:
                self._lead_read(*_FORMATS[field.base], target)
            else:
                self._run_read(*_FORMATS[field.base], target)
            if field.name != DUMMY_FIELD or visible:
                items.append(f"{field.name!r}: {target}")
        return "{" + ", ".join(items) + "}"

    def end(self) -> str:
        """The check that nothing but padding follows the last field (call
        it once every field is written)."""
        self._flush()
        if self.static is not None:
            return f"if size > {self.static + 7}: raise _Fallback"
        if self.lines[-1] == "b = e - 3":  # a string came last
            self.lines.pop()
            return "if e + 4 < size: raise _Fallback"
        return "if b + 7 < size: raise _Fallback"


def build_flat_decoder(
    key: str, defs: Mapping[str, MsgDef], general: Callable[[memoryview], Any]
) -> Callable[[memoryview], Any] | None:
    """The direct decoder of type ``key`` (see the module docstring), handing
    every payload it does not read itself to ``general``; None when the type
    has a field it does not cover."""
    if not _flat(key, defs):
        return None
    writer = _Writer(defs)
    result = writer.message(key)
    lead = writer.unpack(writer.lead)
    end = writer.end()  # before the lines: it may drop the last one
    lines = [
        f"{', '.join(writer.lead_targets)} = {lead}(p, 0)",
        "if h != 256 or p.itemsize != 1: raise _Fallback",  # CDR, little endian
        "size = len(p)",
        *writer.lines,
        end,
    ]
    body = "\n".join("        " + line for line in lines)
    source = (
        "def decode(p):\n"
        "    try:\n"
        f"{body}\n"
        f"        return {result}\n"
        "    except Exception:\n"
        "        return _general(p)\n"
    )
    namespace: dict[str, Any] = {"_Fallback": _Fallback, "_general": general}
    for fmt, name in writer.structs.items():
        namespace[name] = struct.Struct(fmt).unpack_from
    exec(compile(source, f"<ros_mobile_bridge.codec flat decoder for {key}>", "exec"), namespace)
    decode: Callable[[memoryview], Any] = namespace["decode"]
    return decode
