"""A generated CDR encoder for the message classes (``ros_mobile_bridge.interfaces``).

:func:`build_class_encoder` generates, once per type, one function writing
an instance as little-endian CDR with the 4-byte encapsulation header,
byte for byte what rosbags' ``Typestore.serialize_cdr`` writes for the same
message (padding relative to the body, nothing after the last field). The
generated source is inspectable: the code object's file name is ``<cdr
encoder of pkg/msg/Name>`` and the function's ``__source__`` attribute holds
the text.

The output is a list of parts joined once: each run of fixed-size fields
(scalars, the length of the string or the count of the sequence that
follows) is one ``struct.Struct.pack`` with its padding as ``x`` bytes, a
string its UTF-8 bytes, a numeric array the array itself (``bytes.join``
copies it from its buffer), a run-time padding a slice of zeros.

The fast path takes the values as the classes hold them: ``int``,
``float``, ``bool``, ``str``, one-dimensional C-contiguous numpy arrays of
the field's dtype, ``list`` for arrays of strings and of messages, nested
instances of exactly their field's class. Anything else (a tuple or
``bytes`` for an array, a numpy bool, a subclass instance, a value that
does not fit) makes it fail, and the value is then checked field by field
(:func:`normalized`): a value that fits is converted (as the classes'
constructors convert it) and the message encoded again; one that does not
fit raises :class:`~ros_mobile_bridge.MessageError` naming the field (its
dotted path, ``"pose.covariance"``, ``"transforms[2].header"``).

What fits a field: an integer (``int``, a numpy integer, ``bool``) within
its type's range (``byte`` and ``char``: 0..255); a real number for
``float32``/``float64`` (within float32's range for ``float32``; ``nan``
and infinities pass); for ``bool``, ``True``/``False`` or a value equal
to one of them (a numpy bool, 0, 1); a ``str`` encodable as UTF-8 within its bound for ``string``; for
a numeric array, what the constructors take (a numpy array, a list, a
tuple, ``bytes`` for an 8-bit integer array) of the right length (fixed
size) or at most the bound (bounded sequence); for arrays of strings and of
messages, a list or tuple of such; an instance of the field's class.
"""

from __future__ import annotations

import operator
import struct
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from .._errors import MessageError
from ._cdr_layout import (
    DTYPES,
    FORMATS,
    LITTLE,
    SIZES,
    Classes,
    Field,
    SourceWriter,
    class_fields,
    compact,
    compile_function,
    first_alignment,
    meet,
    residue,
)
from ._model import ARRAY, SCALAR, SEQUENCE, MsgDef

if TYPE_CHECKING:
    from ..interfaces._base import RosMessage

__all__ = ["build_class_encoder"]

_ZEROS: Final = tuple(bytes(n) for n in range(16))
"""``_ZEROS[n]``: ``n`` zero bytes (run-time padding, a string's terminator)."""
_LENGTHS: Final = tuple(struct.Struct(f"<{n}xI").pack for n in range(8))
"""``_LENGTHS[n](length)``: ``n`` zero bytes, then a uint32."""


class _Misfit(Exception):
    """The fast path met a value it does not take as it is."""


class _EncoderWriter(SourceWriter):
    """Generates the statements of one encoder.

    The position being written is ``base + offset`` (``base`` None: every
    offset is known; ``known`` is what is known of ``base``, ``(modulus,
    remainder)``); the parts written so far end at ``written`` (a base and
    an offset: zero bytes go between it and the next part). The open run
    (:attr:`fmt`, :attr:`values`) becomes one ``pack``. The parts are
    expressions joined at the end (:attr:`parts`, pending; flushed into the
    list ``L`` before and inside loops)."""

    def __init__(self, key: str, defs: Mapping[str, MsgDef], classes: Classes) -> None:
        super().__init__(key, defs, classes, 1)
        self.base: str | None = None
        self.offset = 0
        self.known = (8, 0)
        self.written: tuple[str | None, int] = (None, 0)
        self.fmt = ""
        self.values: list[str] = []
        self.start = 0
        self.end = 0
        self.parts: list[str] = []
        self.listed = False
        """Whether the parts list ``L`` exists (a loop came)."""

    # -- helpers ------------------------------------------------------------------------

    def packer(self, fmt: str) -> str:
        fmt = compact(fmt)
        name = "_p_" + fmt.replace("?", "o")
        if name not in self.namespace:
            self.namespace[name] = struct.Struct("<" + fmt).pack
        return name

    def dtype(self, base: str) -> str:
        dtype = np.dtype(DTYPES[base])
        name = f"_t_{dtype.name}"
        self.namespace.setdefault(name, dtype)
        return name

    def at(self, offset: int, base: str | None = None, *, here: bool = True) -> str:
        """The expression of ``base + offset`` (the position's base by default)."""
        if here:
            base = self.base
        if base is None:
            return str(offset)
        if offset < 0:
            return f"{base} - {-offset}"
        return f"{base} + {offset}" if offset else base

    def check(self, condition: str) -> None:
        self.emit(f"if {condition}: raise _Misfit")

    # -- the position and the parts -----------------------------------------------------

    def place(self, align: int) -> int | None:
        mod, rem = self.known
        if align > mod:
            return None
        at = self.end
        return at + (residue(align) - rem - at) % align

    def gap(self, base: str | None, offset: int) -> None:
        """Zero bytes up to ``base + offset`` from :attr:`written`; the
        position ``base + offset`` is written."""
        wbase, woffset = self.written
        if wbase == base:
            if offset > woffset:
                self.parts.append(f"_zeros[{offset - woffset}]")
        else:
            name = self.local("z")
            here = self.at(offset, base, here=False)
            there = self.at(woffset, wbase, here=False)
            if " " in there:
                there = f"({there})"
            self.emit(f"{name} = _zeros[{here} - {there}]")
            self.parts.append(name)
        self.written = (base, offset)

    def flush(self) -> None:
        """Add the open run's pack to the parts; the position moves past it."""
        if self.values:
            self.gap(self.base, self.start)
            self.parts.append(f"{self.packer(self.fmt)}({', '.join(self.values)})")
            self.written = (self.base, self.end)
        self.offset = self.start = self.end
        self.fmt = ""
        self.values = []

    def new_base(self, expr: str, known: tuple[int, int]) -> None:
        """Make the position the variable ``q`` = ``expr`` (which may use the
        old base)."""
        if self.written[0] == "q":  # ``q`` is about to change: keep what is written
            self.emit(f"w = {self.at(self.written[1], 'q', here=False)}")
            self.written = ("w", 0)
        self.emit(f"q = {expr}")
        self.base, self.offset, self.start, self.end = "q", 0, 0, 0
        self.known = known

    def settle(self) -> None:
        """Flush, write the zeros up to the position, and make it ``q``."""
        self.flush()
        if self.base != "q" or self.offset:
            there = self.written == (self.base, self.offset)
            if there:
                self.written = ("", 0)  # all is written: nothing to keep
            mod, rem = self.known
            self.new_base(self.at(self.offset), (mod, (rem + self.offset) % mod))
            if there:
                self.written = ("q", 0)
        self.gap("q", 0)

    def flush_parts(self) -> None:
        """Move the pending parts into the list ``L``."""
        if not self.parts:
            return
        joined = ", ".join(self.parts)
        if not self.listed:
            self.emit(f"L = [{joined}]")
            self.listed = True
        elif len(self.parts) == 1:
            self.emit(f"L.append({joined})")
        else:
            self.emit(f"L += ({joined},)")
        self.parts = []

    def align(self, align: int) -> None:
        if self.place(align) is not None:
            return
        self.flush()
        rest = residue(align)
        expr = self.at(self.offset + align - 1 - rest)
        self.new_base(
            f"(({expr}) & -{align}) + {rest}" if rest else f"({expr}) & -{align}", (align, rest)
        )

    def item(self, fmt: str, align: int, value: str) -> int:
        self.align(align)
        at = self.place(align)
        assert at is not None
        if not self.values:
            self.start = self.end
        if at > self.end:
            self.fmt += f"{at - self.end}x"
        self.fmt += fmt
        self.values.append(value)
        self.end = at + struct.calcsize(fmt)
        return at

    # -- fields -------------------------------------------------------------------------

    def message(self, name: str, obj: str) -> None:
        """Emit the writes of the instance in local ``obj`` (its class checked)."""
        self.check(f"{obj}.__class__ is not {self.const(self.classes(name), 'C')}")
        for field in class_fields(name, self.defs, self.classes, self.fields):
            self.field(field, obj)

    def field(self, field: Field, obj: str) -> None:
        spec = field.spec
        if field.attr is None:  # an empty message's placeholder
            self.item("B", 1, "0")
            return
        value = f"{obj}.{field.attr}"
        if spec.cardinality == SCALAR:
            if spec.ref is not None:
                sub = self.local("o")
                self.emit(f"{sub} = {value}")
                self.message(spec.ref, sub)
            elif spec.base == "string":
                self.string(value, spec.string_bound)
            elif spec.base == "bool":
                self.item("?", 1, f"_bools[{value}]")
            else:
                assert spec.base is not None
                self.item(FORMATS[spec.base], SIZES[spec.base], value)
            return
        local = self.local("v")
        self.emit(f"{local} = {value}")
        if spec.ref is None and spec.base != "string":
            assert spec.base is not None
            self.numbers(spec.base, local, spec.cardinality, spec.size)
            return
        self.check(f"{local}.__class__ is not list")
        if spec.cardinality == ARRAY:
            self.check(f"len({local}) != {spec.size}")
        else:
            if spec.size:
                self.check(f"len({local}) > {spec.size}")
            self.item("I", 4, f"len({local})")
        if spec.ref is not None:
            self.messages(spec.ref, local)
        else:
            self.strings(local, spec.string_bound)

    def string(self, value: str, bound: int) -> None:
        if bound:
            text = self.local("t")
            self.emit(f"{text} = {value}")
            self.check(f"len({text}) > {bound}")
            value = text
        data = self.local("s")
        size = self.local("n")
        self.emit(f"{data} = {value}.encode()")
        self.emit(f"{size} = len({data})")
        at = self.item("I", 4, f"{size} + 1")
        self.flush()
        self.parts.append(data)
        end = self.local("e")
        self.emit(f"{end} = {self.at(at + 4)} + {size}")
        self.written = (end, 0)
        self.base, self.offset, self.start, self.end = end, 1, 1, 1
        self.known = (1, 0)

    def numbers(self, base: str, local: str, cardinality: int, size: int) -> None:
        dtype = self.dtype(base)
        self.check(f"{local}.__class__ is not _ndarray or {local}.dtype is not {dtype}")
        count = self.local("c")
        self.emit(f"{count} = {local}.size")
        itemsize = SIZES[base]
        if cardinality == ARRAY:
            self.check(f"{count} != {size}")
            self.align(itemsize)
            at = self.place(itemsize)
            assert at is not None
            self.flush()
            self.gap(self.base, at)
            self.parts.append(local)
            self.written = (self.base, at + itemsize * size)
            self.offset = self.start = self.end = at + itemsize * size
            return
        if size:
            self.check(f"{count} > {size}")
        self.item("I", 4, count)
        self.flush()
        at = self.place(itemsize)
        here = self.at(self.offset)
        if at is None:  # a 64-bit element after the 4-aligned count
            start = f"((({self.at(self.offset + 3)}) & -8) + 4 if {count} else {here})"
        elif at != self.offset:
            start = f"({self.at(at)} if {count} else {here})"
        else:
            start = here
        if start != here:
            self.new_base(start, (1, 0))
            self.gap("q", 0)
        self.parts.append(local)
        self.written = ("", 0)  # the array ends at the new ``q``
        after = (itemsize, residue(itemsize)) if itemsize <= 4 else (8, 4)
        end = f"{count}" if itemsize == 1 else f"{itemsize} * {count}"
        self.new_base(f"{self.at(self.offset)} + {end}", meet((4, 0), after))
        self.written = ("q", 0)

    def strings(self, local: str, bound: int) -> None:
        self.settle()
        self.flush_parts()
        self.emit("w = q")
        item = self.local("x")
        self.emit(f"for {item} in {local}:")
        self.indent += 1
        if bound:
            self.check(f"len({item}) > {bound}")
        self.emit(f"b = {item}.encode()")
        self.emit("n = len(b)")
        self.emit("a = (q + 3) & -4")
        self.emit("L += (_lengths[a - w](n + 1), b)")
        self.emit("w = a + 4 + n")
        self.emit("q = w + 1")
        self.indent -= 1
        self.written = ("w", 0)
        self.base, self.offset, self.start, self.end = "q", 0, 0, 0
        self.known = (1, 0)

    def messages(self, name: str, local: str) -> None:
        self.settle()
        self.flush_parts()
        before = self.known
        item = self.local("o")
        self.emit(f"for {item} in {local}:")
        self.indent += 1
        first = first_alignment(name, self.defs, self.classes, self.fields)
        mark, names = len(self.lines), self.names
        top = before
        for _ in range(4):
            del self.lines[mark:]
            self.names = names
            self.known = top
            self.base, self.offset, self.start, self.end = "q", 0, 0, 0
            self.written = ("q", 0)
            self.align(first)
            self.message(name, item)
            self.settle()
            self.flush_parts()
            after = meet(before, self.known)
            if after == top:
                break
            top = after
        else:  # pragma: no cover - the knowledge only shrinks, in at most 4 steps
            raise AssertionError("no fixed point")
        self.indent -= 1
        self.known = top

    def finish(self) -> str:
        """The return statement (every field written)."""
        self.flush()
        self.gap(self.base, self.offset)  # a last string's terminator
        if not self.listed:
            return f"return _join(({', '.join(self.parts)},))"
        self.flush_parts()
        return "return _join(L)"


def _encoder_source(
    key: str, defs: Mapping[str, MsgDef], classes: Classes
) -> tuple[str, dict[str, Any]]:
    writer = _EncoderWriter(key, defs, classes)
    writer.fmt = "H2x"
    writer.values = [str(LITTLE)]
    writer.end = 4
    writer.message(key, "m")
    ret = writer.finish()
    body = [*writer.lines, "    " + ret]
    source = "\n".join(
        [
            "def plain(m):",
            *body,
            "",
            "def function(m):",
            "    try:",
            *("    " + line for line in body),
            "    except Exception:",
            "        return _slow(m)",
            "",
        ]
    )
    return source, writer.namespace


# --------------------------------------------------------------------------- the slow path


def _type_name(value: object) -> str:
    return type(value).__name__


_BOOLS: Final = {False: False, True: True}


def _scalar(base: str) -> Callable[[Any], Any]:
    """The check of a primitive scalar (not a string): the value as the fast
    path takes it, or :class:`_Refused`."""
    pack = struct.Struct("<" + FORMATS[base]).pack
    if base == "bool":

        def check_bool(value: Any) -> bool:
            try:
                return _BOOLS[value]
            except (KeyError, TypeError):
                raise _Refused(f"expected a bool, got {_type_name(value)}") from None

        return check_bool
    floating = base.startswith("float")

    def check(value: Any) -> Any:
        try:
            pack(value)
        except OverflowError:
            raise _Refused(f"{value} is out of range for {base}") from None
        except struct.error:
            if floating:
                raise _Refused(f"expected a number ({base}), got {_type_name(value)}") from None
            try:
                number = operator.index(value)
            except TypeError:
                reason = f"expected an integer ({base}), got {_type_name(value)}"
                raise _Refused(reason) from None
            raise _Refused(f"{number} is out of range for {base}") from None
        return value

    return check


class _Refused(Exception):
    """A value does not fit its field: ``path`` (filled in on the way out)
    and ``reason``."""

    def __init__(self, reason: str, path: str = "") -> None:
        super().__init__(reason)
        self.reason = reason
        self.path = path

    def within(self, name: str) -> _Refused:
        if not self.path:
            return _Refused(self.reason, name)
        joint = "" if self.path.startswith("[") else "."
        return _Refused(self.reason, f"{name}{joint}{self.path}")


def _text(value: Any, bound: int) -> str:
    if not isinstance(value, str):
        raise _Refused(f"expected a str, got {_type_name(value)}")
    if bound and len(value) > bound:
        raise _Refused(f"string longer than its bound {bound} ({len(value)} characters)")
    try:
        value.encode()
    except UnicodeEncodeError as exc:
        raise _Refused(f"not encodable as UTF-8: {exc.reason}") from None
    return str(value)


def _items(value: Any, spec_size: int, fixed: bool, what: str) -> list[Any]:
    if isinstance(value, str | bytes | bytearray | Mapping) or not isinstance(value, Iterable):
        raise _Refused(f"expected a list of {what}, got {_type_name(value)}")
    items = list(value)
    _length(len(items), spec_size, fixed)
    return items


def _length(count: int, size: int, fixed: bool) -> None:
    if fixed:
        if count != size:
            raise _Refused(f"expected exactly {size} elements, got {count}")
    elif size and count > size:
        raise _Refused(f"expected at most {size} elements, got {count}")


def _numbers(value: Any, base: str, size: int, fixed: bool, owner: RosMessage) -> Any:
    from ..interfaces import _base

    dtype = np.dtype(DTYPES[base])
    if isinstance(value, np.ndarray) and value.dtype == dtype and value.dtype.isnative:
        array = value
    else:
        try:
            array = _base.converted_array(owner, "", value, dtype, base)
        except MessageError as exc:
            raise _Refused(exc.reason) from None
        if array.dtype != dtype:
            array = array.astype(dtype)
    if array.ndim != 1:
        array = array.reshape(-1)
    array = np.ascontiguousarray(array)
    if array.dtype is not dtype:
        array = array.view(dtype)
    _length(int(array.shape[0]), size, fixed)
    return array


class _Normalizer:
    """Checks an instance field by field and gives it with every value as
    the fast path takes it (a new instance when anything changed)."""

    def __init__(self, defs: Mapping[str, MsgDef], classes: Classes) -> None:
        self.defs = defs
        self.classes = classes
        self.fields: dict[str, list[Field]] = {}
        self.scalars: dict[str, Callable[[Any], Any]] = {}

    def message(self, name: str, value: Any) -> Any:
        cls = self.classes(name)
        if not isinstance(value, cls):
            reason = f"expected {name}, got {_type_name(value)}"
            if isinstance(value, Mapping):
                reason += f" (a dict converts with {cls.__qualname__}.from_dict)"
            raise _Refused(reason)
        out = object.__new__(cls)
        for field in class_fields(name, self.defs, self.classes, self.fields):
            if field.attr is None:
                continue
            try:
                item = getattr(value, field.attr)
            except AttributeError:
                raise _Refused("missing (the slot is not set)", field.attr) from None
            try:
                item = self.field(field, item, value)
            except _Refused as exc:
                raise exc.within(field.attr) from None
            setattr(out, field.attr, item)
        return out

    def field(self, field: Field, value: Any, owner: Any) -> Any:
        spec = field.spec
        fixed = spec.cardinality == ARRAY
        if spec.cardinality == SCALAR:
            if spec.ref is not None:
                return self.message(spec.ref, value)
            assert spec.base is not None
            if spec.base == "string":
                return _text(value, spec.string_bound)
            check = self.scalars.get(spec.base)
            if check is None:
                check = self.scalars[spec.base] = _scalar(spec.base)
            return check(value)
        assert spec.cardinality in (ARRAY, SEQUENCE)
        if spec.ref is not None:
            items = _items(value, spec.size, fixed, spec.ref)
            out = []
            for index, item in enumerate(items):
                try:
                    out.append(self.message(spec.ref, item))
                except _Refused as exc:
                    raise exc.within(f"[{index}]") from None
            return out
        assert spec.base is not None
        if spec.base == "string":
            items = _items(value, spec.size, fixed, "str")
            texts = []
            for index, item in enumerate(items):
                try:
                    texts.append(_text(item, spec.string_bound))
                except _Refused as exc:
                    raise exc.within(f"[{index}]") from None
            return texts
        return _numbers(value, spec.base, spec.size, fixed, owner)


class _Encoder:
    """One type's encoder: the generated fast path and the slow path."""

    def __init__(self, key: str, defs: Mapping[str, MsgDef], classes: Classes) -> None:
        self.key = key
        self.normalizer = _Normalizer(dict(defs), classes)
        source, namespace = _encoder_source(key, self.normalizer.defs, classes)
        namespace.update(
            _join=b"".join,
            _zeros=_ZEROS,
            _lengths=_LENGTHS,
            _bools=_BOOLS,
            _Misfit=_Misfit,
            _ndarray=np.ndarray,
            _slow=self.slow,
        )
        self.encode: Callable[[Any], bytes] = compile_function(source, "encoder", key, namespace)
        self.plain: Callable[[Any], bytes] = namespace["plain"]

    def slow(self, message: Any) -> bytes:
        """Check ``message`` field by field: a :class:`MessageError` naming
        the first that does not fit, else the encoding of its values as the
        fast path takes them."""
        try:
            fixed = self.normalizer.message(self.key, message)
        except _Refused as exc:
            raise MessageError(self.key, exc.reason, exc.path or None) from None
        try:
            return self.plain(fixed)
        except Exception as exc:  # pragma: no cover - a checked message encodes
            raise MessageError(self.key, f"{type(exc).__name__}: {exc}") from exc


def build_class_encoder(
    key: str, defs: Mapping[str, MsgDef], classes: Classes
) -> Callable[[RosMessage], bytes]:
    """The little-endian CDR encoder of type ``key`` from its class (see the
    module docstring): the payload with its 4-byte encapsulation header, as
    ``bytes``. ``defs`` and ``classes`` as for
    :func:`~ros_mobile_bridge.codec._cdr.build_class_decoder`. The encoder
    raises :class:`MessageError` naming the field for a value that does not
    fit. Raises :class:`SchemaError` for a type it cannot encode."""
    return _Encoder(key, defs, classes).encode
