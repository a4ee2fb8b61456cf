"""A generated CDR decoder for the message classes (``ros_mobile_bridge.interfaces``).

:func:`build_class_decoder` generates, once per type, the Python source of
one function that reads a whole CDR payload straight into an instance of the
type's class (nested messages inline, no call per nested message), compiles
it and returns it; :func:`build_class_encoder` (``_cdr_encode``) does the
other direction. The generated source is inspectable: the code object's
file name is ``<cdr decoder of pkg/msg/Name>`` and the function's
``__source__`` attribute holds the text.

How the generated decoder reads (little endian, the common case):

* consecutive fields whose offsets are known from the last dynamic position
  (scalars, fixed-size numeric arrays, the length of the string or the
  count of the sequence that follows them) are read by one
  ``struct.Struct.unpack_from`` into the instances' slots; the padding
  between them is ``x`` bytes in the format, since the position's alignment
  is tracked while generating (after a string or a sequence it is unknown,
  and the code aligns at run time);
* instances are made with ``object.__new__`` and their slots assigned: the
  classes' constructors never run;
* a string is ``payload[start:end].tobytes().decode()`` after its NUL
  terminator is checked; numeric and bool arrays are ``numpy.frombuffer``
  views of the payload (no copy: read-only when the payload is ``bytes``,
  writable when it is a writable buffer); arrays of strings and of messages
  are loops.

A big-endian payload is read by a second function generated the same way
with big-endian formats, built on the first such payload; its numeric arrays
are converted to native byte order (copies). The decoder accepts ``bytes``,
``bytearray`` and C-contiguous memoryviews (one of another format than
``"B"`` is read as its bytes).

``wstring`` and ``wchar`` fields (which rosbags' CDR code does not support
either) and ``float128`` are refused when the codec is built, with
:class:`~ros_mobile_bridge.SchemaError`.

Decoding checks what rosbags' ``deserialize_cdr`` checks, with the
registry's rule for what may follow the message: a string's length at least
one and its terminator NUL, UTF-8 text, every length within the payload, at
most 3 bytes (padding) left over after the message. Bounds of bounded
strings and sequences are not checked when decoding (rosbags does not
either); the encoder checks them.
"""

from __future__ import annotations

import struct
import sys
import threading
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from .._errors import DecodeError, SchemaError
from ._cdr_layout import (
    DTYPES,
    FORMATS,
    LITTLE,
    SIZES,
    Classes,
    Field,
    Invalid,
    SourceWriter,
    class_fields,
    compact,
    compile_function,
    first_alignment,
    meet,
    residue,
)
from ._model import ARRAY, SCALAR, MsgDef

if TYPE_CHECKING:
    from ..interfaces._base import RosMessage

__all__ = ["build_class_decoder"]


class _DecoderWriter(SourceWriter):
    """Generates the statements of one decoder (one byte order).

    The position in the payload is ``base + offset``: ``base`` a variable
    (None at the start, where every offset is known) and ``offset`` a
    constant; ``known`` is what is known of ``base``: ``(modulus,
    remainder)``, the payload offset modulo ``modulus`` (the body starts at
    payload offset 4, so an 8-aligned body offset is 4 modulo 8).
    The open run (:attr:`fmt`, :attr:`targets`) is read by one
    ``unpack_from`` at ``base + start`` when something dynamic follows."""

    def __init__(self, key: str, defs: Mapping[str, MsgDef], classes: Classes, big: bool) -> None:
        super().__init__(key, defs, classes, 2)
        self.big = big
        self.order = ">" if big else "<"
        self.swap = big != (sys.byteorder == "big")
        """Whether arrays are converted to native byte order (copies)."""
        self.base: str | None = None
        self.offset = 0
        self.known = (8, 0)
        self.fmt = ""
        self.targets: list[str] = []
        self.arrays: list[tuple[str, str, int, int]] = []
        """Fixed-size arrays of the open run: (target, dtype global, count, offset)."""
        self.start = 0
        """The offset of the open run's first byte."""
        self.end = 0
        """The offset just past the open run."""
        self.checked_header = False

    # -- helpers ------------------------------------------------------------------------

    def unpacker(self, fmt: str) -> str:
        fmt = compact(fmt, trim=True)
        name = "_u_" + fmt.replace("?", "o")
        if name not in self.namespace:
            self.namespace[name] = struct.Struct(self.order + fmt).unpack_from
        return name

    def dtype(self, base: str) -> str:
        dtype = np.dtype(DTYPES[base])
        name = f"_t_{dtype.name}"
        if name not in self.namespace:
            self.namespace[name] = dtype
            if self.swap and dtype.itemsize > 1:
                self.namespace[name + "_swapped"] = dtype.newbyteorder(">" if self.big else "<")
        return name

    def at(self, offset: int) -> str:
        """The expression of payload offset ``base + offset``."""
        if self.base is None:
            return str(offset)
        if offset < 0:
            return f"{self.base} - {-offset}"
        return f"{self.base} + {offset}" if offset else self.base

    def array(self, target: str, base: str, count: str, offset: str) -> str:
        """The statement making ``target`` the array of ``count`` ``base``
        elements at ``offset``."""
        dtype = self.dtype(base)
        if self.swap and SIZES[base] > 1:
            return f"{target} = _fb(p, {dtype}_swapped, {count}, {offset}).astype({dtype})"
        return f"{target} = _fb(p, {dtype}, {count}, {offset})"

    # -- the position -------------------------------------------------------------------

    def place(self, align: int) -> int | None:
        """The offset the next item aligned to ``align`` goes at in the open
        run, or None when only a run-time alignment can tell."""
        mod, rem = self.known
        if align > mod:
            return None
        at = self.end
        return at + (residue(align) - rem - at) % align

    def flush(self) -> None:
        """Emit the open run's read; the position moves past it."""
        targets = self.targets
        if len(targets) == 1 and self.fmt in ("B", "?") and self.checked_header:
            # one byte: an index is cheaper than a struct call
            test = " != 0" if self.fmt == "?" else ""
            self.emit(f"{targets[0]} = p[{self.at(self.start)}]{test}")
        elif targets:
            unpack = self.unpacker(self.fmt)
            self.emit(f"{', '.join(targets)}, = {unpack}(p, {self.at(self.start)})")
            if not self.checked_header:
                self.checked_header = True
                magic = 0 if self.big else LITTLE
                self.emit(f"if h != {magic}: return _other(p)")
        self.emit_arrays()
        self.offset = self.end
        self.start = self.end
        self.fmt = ""
        self.targets = []
        self.arrays = []

    def emit_arrays(self) -> None:
        """The open run's fixed-size arrays: those of one dtype share one
        ``frombuffer`` and are slices of it (a slice costs a third of a
        ``frombuffer``)."""
        groups: dict[str, list[tuple[str, int, int]]] = {}
        for target, base, count, offset in self.arrays:
            groups.setdefault(DTYPES[base], []).append((target, count, offset))
        for target, base, count, offset in self.arrays:
            group = groups.pop(DTYPES[base], None)
            if group is None:
                continue
            if len(group) == 1:
                self.emit(self.array(target, base, str(count), self.at(offset)))
                continue
            size = SIZES[base]
            first = group[0][2]
            span = (group[-1][2] + group[-1][1] * size - first) // size
            whole = self.local("a")
            self.emit(self.array(whole, base, str(span), self.at(first)))
            for name, number, at in group:
                index = (at - first) // size
                self.emit(f"{name} = {whole}[{index}:{index + number}]")

    def materialize(self) -> str:
        """Flush, and make the position the variable ``q`` (returned)."""
        self.flush()
        if self.base != "q" or self.offset:
            self.emit(f"q = {self.at(self.offset)}")
            mod, rem = self.known
            self.known = (mod, (rem + self.offset) % mod)
        self.base, self.offset, self.start, self.end = "q", 0, 0, 0
        return "q"

    def align(self, align: int) -> None:
        """Align the position to ``align`` (at run time when it is unknown)."""
        if self.place(align) is not None:
            return
        self.flush()
        rest = residue(align)
        expr = self.at(self.offset + align - 1 - rest)
        if rest:
            self.emit(f"q = (({expr}) & -{align}) + {rest}")
        else:
            self.emit(f"q = ({expr}) & -{align}")
        self.base, self.offset, self.start, self.end = "q", 0, 0, 0
        self.known = (align, rest)

    def item(self, fmt: str, align: int, size: int, target: str | None) -> int:
        """Add an item of ``size`` bytes aligned to ``align`` to the open run
        (read into ``target``, or skipped: None); return its offset."""
        self.align(align)
        at = self.place(align)
        assert at is not None
        if not self.targets and not self.arrays:
            self.start = at
        elif at > self.end:
            self.fmt += f"{at - self.end}x"
        if target is None:
            self.fmt += f"{size}x"
        else:
            self.fmt += fmt
            self.targets.append(target)
        self.end = at + size
        return at

    def length(self) -> tuple[str, int]:
        """Read a uint32 (a string's length, a sequence's count) as the open
        run's last item and flush; return its variable and the offset just
        past it."""
        name = self.local("n")
        at = self.item("I", 4, 4, name)
        self.flush()
        return name, at + 4

    # -- fields -------------------------------------------------------------------------

    def message(self, name: str, target: str) -> None:
        """Emit the reads of a ``name`` instance into the new local ``target``."""
        cls = self.classes(name)
        self.emit(f"{target} = _new({self.const(cls, 'C')})")
        for field in class_fields(name, self.defs, self.classes, self.fields):
            self.field(field, target)

    def field(self, field: Field, owner: str) -> None:
        spec = field.spec
        attr = f"{owner}.{field.attr}" if field.attr is not None else None
        if spec.cardinality == SCALAR:
            if spec.ref is not None:
                sub = self.local("o")
                self.message(spec.ref, sub)
                self.emit(f"{attr} = {sub}")
            elif spec.base == "string":
                assert attr is not None
                self.string(attr)
            else:
                assert spec.base is not None
                if attr is None:  # an empty message's placeholder: read, not kept
                    self.item("B", 1, 1, "_")
                else:
                    size = SIZES[spec.base]
                    self.item(FORMATS[spec.base], size, size, attr)
            return
        assert attr is not None
        if spec.cardinality == ARRAY:
            if spec.ref is None and spec.base != "string":
                assert spec.base is not None
                size = SIZES[spec.base]
                at = self.item("", size, size * spec.size, None)
                self.arrays.append((attr, spec.base, spec.size, at))
                return
            count = str(spec.size)
        else:
            count, _after = self.length()
        if spec.ref is not None:
            self.messages(spec.ref, count, attr, fixed=spec.cardinality == ARRAY)
        elif spec.base == "string":
            self.strings(count, attr)
        else:
            assert spec.base is not None
            self.numbers(spec.base, count, attr)

    def string(self, target: str) -> None:
        name, after = self.length()
        end = self.local("e")
        start = self.at(after)
        self.emit(f"{end} = {self.at(after - 1)} + {name}")
        self.emit(f"if p[{end}] or {name} < 1: _bad(p, {end})")
        self.emit(f"{target} = p[{start}:{end}].tobytes().decode()")
        self.base, self.offset, self.start, self.end = end, 1, 1, 1
        self.known = (1, 0)

    def numbers(self, base: str, count: str, target: str) -> None:
        """A sequence of ``count`` numbers at the position (after its count)."""
        size = SIZES[base]
        at = self.place(size)
        if at is None:  # a 64-bit element after the 4-aligned count
            start = (
                f"((({self.at(self.offset + 3)}) & -8) + 4 if {count} else {self.at(self.offset)})"
            )
        elif at != self.offset:
            start = f"({self.at(at)} if {count} else {self.at(self.offset)})"
        else:
            start = self.at(at)
        if start != "q":
            self.emit(f"q = {start}")
        self.emit(self.array(target, base, count, "q"))
        self.emit(f"q += {count}" if size == 1 else f"q += {size} * {count}")
        after = (size, residue(size)) if size <= 4 else (8, 4)
        self.base, self.offset, self.start, self.end = "q", 0, 0, 0
        self.known = meet((4, 0), after)  # an empty sequence ends after its count

    def strings(self, count: str, target: str) -> None:
        """``count`` strings at the position (after their count, if any). The
        loop keeps ``e``, the last terminator's offset: the next string's
        length is at ``(e + 4) & -4``, the position after the loop ``e + 1``."""
        self.flush()
        lst, end = self.local("l"), self.local("e")
        self.emit(f"{end} = {self.at(self.offset - 1)}")
        self.emit(f"{target} = {lst} = []")
        self.emit(f"{lst}_append = {lst}.append")
        self.emit(f"for _ in range({count}):")
        self.indent += 1
        self.emit(f"q = ({end} + 4) & -4")
        self.emit("n, = _u32(p, q)")
        self.emit(f"{end} = q + 3 + n")
        self.emit(f"if p[{end}] or n < 1: _bad(p, {end})")
        self.emit(f"{lst}_append(p[q + 4:{end}].tobytes().decode())")
        self.indent -= 1
        self.base, self.offset, self.start, self.end = end, 1, 1, 1
        self.known = (1, 0)

    def messages(self, name: str, count: str, target: str, fixed: bool) -> None:
        """``count`` ``name`` instances at the position."""
        self.materialize()
        before = self.known
        lst = self.local("l")
        self.emit(f"{target} = {lst} = []")
        self.emit(f"{lst}_append = {lst}.append")
        self.emit(f"for _ in range({count}):")
        self.indent += 1
        first = first_alignment(name, self.defs, self.classes, self.fields)
        # What is known at the top of an iteration: the position before the
        # loop or after an item, whichever is less; found by generating the
        # body until that no longer changes.
        mark, names = len(self.lines), self.names
        top = before
        for _ in range(4):
            del self.lines[mark:]
            self.names = names
            self.known = top
            self.align(first)
            item = self.local("o")
            self.message(name, item)
            self.materialize()
            after = meet(before, self.known)
            if after == top:
                break
            top = after
        else:  # pragma: no cover - the knowledge only shrinks, in at most 4 steps
            raise AssertionError("no fixed point")
        self.emit(f"{lst}_append({item})")
        self.indent -= 1
        self.known = top

    def finish(self) -> None:
        """Emit the end check (nothing but padding left) and the return."""
        self.flush()
        if not self.checked_header:  # cannot happen: every type reads something
            raise SchemaError(f"type {self.key!r} reads nothing")
        self.emit(f"if len(p) > {self.at(self.offset + 3)}: _leftover(p, {self.at(self.offset)})")


def _decoder_source(
    key: str, defs: Mapping[str, MsgDef], classes: Classes, big: bool
) -> tuple[str, dict[str, Any]]:
    writer = _DecoderWriter(key, defs, classes, big)
    writer.targets.append("h")  # the encapsulation header opens the first run
    writer.fmt = "H2x"
    writer.end = 4
    writer.offset = writer.start = 0
    writer.known = (8, 0)
    writer.message(key, "o")
    writer.finish()
    writer.emit("return o")
    strings = any(".tobytes()" in line for line in writer.lines)
    lines = writer.lines
    if strings:  # a string is sliced out of a memoryview
        lines = ["        if p.__class__ is not _memoryview: p = _memoryview(p)", *lines]
    source = "\n".join(
        [
            "def function(p):",
            "    try:",
            *lines,
            "    except Exception as exc:",
            "        return _failed(p, exc)",
            "",
        ]
    )
    return source, writer.namespace


class _Decoder:
    """The state behind one type's decoder: its big-endian variant (built
    on first use) and its error paths."""

    def __init__(self, key: str, defs: Mapping[str, MsgDef], classes: Classes) -> None:
        self.key = key
        self.defs = dict(defs)
        self.classes = classes
        self.little = self._build(big=False)
        self._big: Callable[[Any], Any] | None = None
        self._lock = threading.Lock()

    def _build(self, *, big: bool) -> Callable[[Any], Any]:
        source, namespace = _decoder_source(self.key, self.defs, self.classes, big)
        namespace.update(
            _new=object.__new__,
            _fb=np.frombuffer,
            _memoryview=memoryview,
            _u32=struct.Struct(">I" if big else "<I").unpack_from,
            _other=self.other,
            _failed=self.failed_big if big else self.failed,
            _bad=self.bad_string,
            _leftover=self.leftover,
        )
        kind = "big-endian decoder" if big else "decoder"
        decode: Callable[[Any], Any] = compile_function(source, kind, self.key, namespace)
        return decode

    def big(self) -> Callable[[Any], Any]:
        decode = self._big
        if decode is None:
            with self._lock:
                decode = self._big
                if decode is None:
                    decode = self._big = self._build(big=True)
        return decode

    def other(self, payload: Any) -> Any:
        """A payload whose header is not little-endian CDR's."""
        if len(payload) >= 4 and payload[0] == 0 and payload[1] == 0:
            return self.big()(payload)
        raise self.header_error(payload)

    def header_error(self, payload: Any) -> DecodeError:
        size = len(payload)
        if size < 4 or payload[0] != 0:
            head = bytes(payload[:2]).hex() or "missing"
            return DecodeError(
                f"cannot decode {self.key}: not a CDR payload ({size} bytes, encapsulation {head})"
            )
        return DecodeError(
            f"cannot decode {self.key}: unsupported CDR encapsulation 0x{payload[1]:04x} "
            "(only plain CDR / XCDR1 is supported)"
        )

    def bad_string(self, payload: Any, end: int) -> None:
        raise Invalid(f"invalid string (length or terminator) ending at offset {end - 4}")

    def leftover(self, payload: Any, end: int) -> None:
        raise Invalid(
            f"{len(payload) - end} bytes left over after the message (wrong type or definition?)"
        )

    def failed(self, payload: Any, exc: Exception) -> Any:
        """The error path of the generated code: retry a buffer it does not
        read directly as a byte memoryview, else raise :class:`DecodeError`."""
        if isinstance(exc, DecodeError):
            raise exc
        if not (
            type(payload) is memoryview
            and payload.format == "B"
            and payload.ndim == 1
            and payload.c_contiguous
        ):
            try:
                view = memoryview(payload).cast("B")
            except Exception as cast_exc:
                raise DecodeError(
                    f"cannot decode {self.key}: not a contiguous byte buffer "
                    f"({type(payload).__name__}: {cast_exc})"
                ) from None
            return self.little(view)
        size = len(payload)
        if size < 4 or payload[0] != 0 or payload[1] > 1:
            raise self.header_error(payload) from None
        if payload[1] == 0:  # big endian: the little-endian reads failed first
            return self.big()(payload)
        return self.failed_big(payload, exc)

    def failed_big(self, payload: Any, exc: Exception) -> Any:
        """The error path of the big-endian variant (and the end of the
        little-endian one's): raise :class:`DecodeError`."""
        if isinstance(exc, DecodeError):
            raise exc
        size = len(payload)
        if isinstance(exc, Invalid):
            raise DecodeError(f"cannot decode {self.key}: {exc}") from None
        raise DecodeError(
            f"cannot decode {self.key} from {size} bytes: {type(exc).__name__}: {exc}"
        ) from exc


def build_class_decoder(
    key: str, defs: Mapping[str, MsgDef], classes: Classes
) -> Callable[[memoryview | bytes], RosMessage]:
    """The CDR decoder of type ``key`` into its class (see the module docstring).

    ``defs`` holds the definition of ``key`` and of every type it uses
    (canonical names ``pkg/msg/Name``); ``classes(name)`` is the class of
    each of them (``interfaces._base.message_class`` for the bundled types).
    The decoder takes a whole payload (the 4-byte encapsulation header, then
    the body) and returns an instance; it raises :class:`DecodeError` and
    nothing else for a payload that does not decode. Numeric and bool arrays
    of a little-endian payload are views of it. Raises
    :class:`SchemaError` for a type it cannot decode (``wstring``,
    ``wchar``, ``float128``; a class whose fields do not match)."""
    return _Decoder(key, defs, classes).little
