"""Per-type converters between rosbags message objects and plain dicts.

Both directions are built once per type (at ``decoder()``/``encoder()`` time)
and cached per typestore generation, so the per-message work is a straight
run over a precomputed field list:

* decode: a generated function per type, ``def conv(m): return {"a": m.a,
  "b": conv_B(m.b), "c": [conv_C(x) for x in m.c]}``;
* encode: a closure per type that validates a (partial) mapping, fills the
  missing fields from precomputed defaults and calls the rosbags class.
"""

from __future__ import annotations

import math
import operator
import struct
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from rosbags.typesys.base import normalize_fieldname

from .._errors import SchemaError
from ..interfaces._base import RosMessage
from ._model import ARRAY, DUMMY_FIELD, FLOAT_TYPES, INT_RANGES, SCALAR, FieldSpec, MsgDef

__all__ = ["Builder", "Converter", "Invalid", "build_builder", "build_converter", "check_default"]

Converter = Callable[[Any], dict[str, Any]]
"""rosbags message object -> dict."""
Builder = Callable[[Any], object]
"""(partial) mapping -> rosbags message object; raises :class:`Invalid`."""

_FLOAT32_MAX = float(np.finfo(np.float32).max)
_pack_f32 = struct.Struct("<f").pack
_NUMPY_DTYPES: dict[str, np.dtype[Any]] = {
    "bool": np.dtype(np.bool_),
    "byte": np.dtype(np.uint8),  # ROS 2 octet; rosbags wants int8, see _array_coercer
    "char": np.dtype(np.uint8),
    "int8": np.dtype(np.int8),
    "uint8": np.dtype(np.uint8),
    "int16": np.dtype(np.int16),
    "uint16": np.dtype(np.uint16),
    "int32": np.dtype(np.int32),
    "uint32": np.dtype(np.uint32),
    "int64": np.dtype(np.int64),
    "uint64": np.dtype(np.uint64),
    "float32": np.dtype(np.float32),
    "float64": np.dtype(np.float64),
}


class Invalid(Exception):
    """A value does not fit its field. ``path`` is the dotted field path
    (filled in on the way out), ``reason`` what is wrong."""

    def __init__(self, reason: str, path: str = "") -> None:
        super().__init__(reason)
        self.reason = reason
        self.path = path

    def within(self, name: str) -> Invalid:
        """This error, one level further out (``name`` is a field or ``[i]``)."""
        if not self.path:
            path = name
        elif self.path.startswith("["):
            path = name + self.path
        else:
            path = f"{name}.{self.path}"
        return Invalid(self.reason, path)


def _attr(field: FieldSpec, owner: str) -> str:
    attr = normalize_fieldname(field.name)
    if not attr.isidentifier():
        raise SchemaError(f"type {owner!r} has a field with an invalid name: {field.name!r}")
    return attr


# --------------------------------------------------------------------------- decode


def build_converter(key: str, defs: Mapping[str, MsgDef], cache: dict[str, Converter]) -> Converter:
    """The message-object -> dict converter of type ``key`` (and, recursively,
    of the types it uses), memoised in ``cache``. ``defs`` holds the
    definitions as registered in the typestore the objects come from."""
    conv = cache.get(key)
    if conv is not None:
        return conv
    msgdef = defs[key]
    namespace: dict[str, Any] = {"_u8": np.uint8}
    items: list[str] = []
    for index, field in enumerate(msgdef.visible_fields):
        attr = f"m.{_attr(field, key)}"
        if field.ref is not None:
            sub = f"_c{index}"
            namespace[sub] = build_converter(field.ref, defs, cache)
            expr = (
                f"{sub}({attr})" if field.cardinality == SCALAR else f"[{sub}(x) for x in {attr}]"
            )
        elif field.base == "byte":
            # rosbags decodes the ROS 2 octet as a signed int8; ROS 2 means 0..255.
            expr = f"({attr} & 0xFF)" if field.cardinality == SCALAR else f"{attr}.view(_u8)"
        else:
            expr = attr
        items.append(f"{field.name!r}: {expr}")
    source = "def conv(m):\n    return {" + ", ".join(items) + "}\n"
    exec(compile(source, f"<ros_mobile_bridge.codec converter for {key}>", "exec"), namespace)
    conv = namespace["conv"]
    cache[key] = conv
    return conv  # type: ignore[no-any-return]


# --------------------------------------------------------------------------- encode


def _type_name(value: object) -> str:
    return type(value).__name__


def _int_coercer(base: str) -> Callable[[Any], int]:
    lo, hi = INT_RANGES[base]
    octet = base == "byte"

    def coerce(value: Any) -> int:
        if isinstance(value, float | np.floating):
            raise Invalid(f"expected an integer ({base}), got {_type_name(value)}")
        try:
            number = operator.index(value)
        except TypeError:
            raise Invalid(f"expected an integer ({base}), got {_type_name(value)}") from None
        if not lo <= number <= hi:
            raise Invalid(f"{number} is out of range for {base}")
        if octet and number > 127:
            number -= 256
        return number

    return coerce


def _float_coercer(base: str) -> Callable[[Any], float]:
    single = base == "float32"

    def coerce(value: Any) -> float:
        if type(value) is float:
            number = value
        elif isinstance(value, int | np.integer | np.floating):
            number = float(value)
        else:
            raise Invalid(f"expected a number ({base}), got {_type_name(value)}")
        if single and math.isfinite(number) and abs(number) > _FLOAT32_MAX:
            try:
                _pack_f32(number)
            except OverflowError:
                raise Invalid(f"{number} is out of range for float32") from None
        return number

    return coerce


def _bool_coerce(value: Any) -> bool:
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer) and value in (0, 1):
        return bool(value)
    raise Invalid(f"expected a bool, got {_type_name(value)}")


def _string_coercer(bound: int) -> Callable[[Any], str]:
    def coerce(value: Any) -> str:
        if not isinstance(value, str):
            raise Invalid(f"expected a str, got {_type_name(value)}")
        if bound and len(value) > bound:
            raise Invalid(f"string longer than its bound {bound} ({len(value)} characters)")
        return value

    return coerce


def _scalar_coercer(base: str, bound: int) -> Callable[[Any], Any]:
    if base in INT_RANGES:
        return _int_coercer(base)
    if base in FLOAT_TYPES:
        return _float_coercer(base)
    if base == "bool":
        return _bool_coerce
    if base == "string":
        return _string_coercer(bound)
    raise SchemaError(f"primitive type {base!r} is not supported by the CDR codec")


def _cast(array: np.ndarray[Any, Any], dtype: np.dtype[Any], base: str) -> np.ndarray[Any, Any]:
    have = array.dtype.kind
    want = dtype.kind
    if want == "b":
        if have != "b" and (have not in "iu" or (array.size and not np.isin(array, (0, 1)).all())):
            raise Invalid(f"expected bools, got an array of {array.dtype}")
    elif want in "iu":
        if have in "iu":
            if array.size:
                info = np.iinfo(dtype)
                if int(array.min()) < info.min or int(array.max()) > info.max:
                    raise Invalid(f"array values out of range for {base}")
        elif have != "b":
            raise Invalid(f"expected integers ({base}), got an array of {array.dtype}")
    elif want == "f":
        if have not in "biuf":
            raise Invalid(f"expected numbers ({base}), got an array of {array.dtype}")
        if dtype.itemsize == 4 and have == "f" and array.size:
            finite = array[np.isfinite(array)]
            if finite.size and float(np.abs(finite).max()) > _FLOAT32_MAX:
                raise Invalid("array values out of range for float32")
    return array.astype(dtype)


def _length_check(count: int, field: FieldSpec) -> None:
    if field.cardinality == ARRAY:
        if count != field.size:
            raise Invalid(f"expected exactly {field.size} elements, got {count}")
    elif field.size and count > field.size:
        raise Invalid(f"expected at most {field.size} elements, got {count}")


def _array_coercer(field: FieldSpec) -> Callable[[Any], Any]:
    base = field.base
    assert base is not None
    if base == "string":
        element = _string_coercer(field.string_bound)

        def coerce_strings(value: Any) -> list[str]:
            if not isinstance(value, list | tuple):
                raise Invalid(f"expected a list of str, got {_type_name(value)}")
            _length_check(len(value), field)
            out = []
            for index, item in enumerate(value):
                try:
                    out.append(element(item))
                except Invalid as exc:
                    raise exc.within(f"[{index}]") from None
            return out

        return coerce_strings

    dtype = _NUMPY_DTYPES.get(base)
    if dtype is None:
        raise SchemaError(f"primitive type {base!r} is not supported by the CDR codec")
    octet = base == "byte"
    bytes_ok = dtype.itemsize == 1 and dtype.kind != "b"

    def coerce_array(value: Any) -> np.ndarray[Any, Any]:
        if isinstance(value, np.ndarray):
            array = value
        elif isinstance(value, bytes | bytearray | memoryview):
            if not bytes_ok:
                raise Invalid(f"bytes are only accepted for 8-bit integer arrays, not {base}[]")
            array = np.frombuffer(value, dtype=np.uint8)
            if dtype.kind == "i":
                array = array.view(dtype)
        elif isinstance(value, list | tuple):
            try:
                array = np.asarray(value)
            except (ValueError, TypeError, OverflowError) as exc:
                raise Invalid(f"not an array of {base}: {exc}") from None
            if array.dtype.kind == "f" and dtype.kind == "u" and _all_ints_in(value, base):
                # numpy reads ints past int64's range as float64 (uint64 maxima)
                array = np.array(value, dtype)
            if array.size == 0:
                array = np.zeros(0, dtype)
        else:
            raise Invalid(f"expected an array of {base}, got {_type_name(value)}")
        if array.dtype != dtype:
            array = _cast(array, dtype, base)
        if array.ndim != 1:
            array = array.reshape(-1)
        if not array.flags.c_contiguous:
            array = np.ascontiguousarray(array)
        _length_check(array.shape[0], field)
        return array.view(np.int8) if octet else array

    return coerce_array


def _all_ints_in(values: list[Any] | tuple[Any, ...], base: str) -> bool:
    low, high = INT_RANGES[base]
    return all(type(v) is int and low <= v <= high for v in values)


def check_default(field: FieldSpec) -> None:
    """Raise :class:`Invalid` unless the declared default of primitive field
    ``field`` fits its type (and :class:`SchemaError` for a type the CDR codec
    does not support)."""
    assert field.base is not None
    value = field.default
    if field.cardinality == SCALAR:
        _scalar_coercer(field.base, field.string_bound)(value)
    else:
        _array_coercer(field)(list(value) if isinstance(value, tuple) else value)


def _nested_array_coercer(field: FieldSpec, build: Builder) -> Callable[[Any], list[object]]:
    def coerce(value: Any) -> list[object]:
        if not isinstance(value, list | tuple):
            raise Invalid(f"expected a list of {field.ref} mappings, got {_type_name(value)}")
        _length_check(len(value), field)
        out = []
        for index, item in enumerate(value):
            try:
                out.append(build(item))
            except Invalid as exc:
                raise exc.within(f"[{index}]") from None
        return out

    return coerce


def build_builder(
    key: str,
    defs: Mapping[str, MsgDef],
    types: Mapping[str, Any],
    cache: dict[str, Builder],
) -> Builder:
    """The mapping -> message-object builder of type ``key`` (memoised in
    ``cache``). ``types`` maps type names to the typestore's classes.

    The builder accepts a partial mapping: missing fields take the declared
    default or zero (nested types recursively); an unknown key or a value of
    the wrong type raises :class:`Invalid` naming the field path. Numeric
    arrays accept numpy arrays (any shape, flattened in C order), lists and
    tuples, and ``bytes``-like objects for 8-bit integer arrays."""
    build = cache.get(key)
    if build is not None:
        return build
    msgdef = defs[key]
    cls = types[key]
    entries: list[tuple[str, Callable[[Any], Any] | None, Any]] = []
    known: set[str] = set()
    for field in msgdef.fields:
        if field.name == DUMMY_FIELD and not msgdef.visible_fields:
            entries.append((field.name, None, 0))
            continue
        _attr(field, key)
        known.add(field.name)
        coerce: Callable[[Any], Any]
        if field.ref is not None:
            sub = build_builder(field.ref, defs, types, cache)
            if field.cardinality == SCALAR:
                coerce = sub
                default: Any = sub({})
            else:
                coerce = _nested_array_coercer(field, sub)
                default = [sub({}) for _ in range(field.size)] if field.cardinality == ARRAY else []
        elif field.cardinality == SCALAR:
            assert field.base is not None
            coerce = _scalar_coercer(field.base, field.string_bound)
            default = None
        else:
            coerce = _array_coercer(field)
            default = None
        if field.default is not None:
            try:
                default = coerce(
                    list(field.default) if isinstance(field.default, tuple) else field.default
                )
            except Invalid as exc:
                raise SchemaError(
                    f"type {key!r}: invalid default for field {field.name!r}: {exc.reason}"
                ) from None
        elif default is None:
            default = coerce(_zero(field))
        entries.append((field.name, coerce, default))
    frozen_known = frozenset(known)

    def build_message(data: Any) -> object:
        if isinstance(data, RosMessage):  # an instance, given alone or nested in a dict
            data = data.to_dict()
        if not isinstance(data, Mapping):
            raise Invalid(f"expected a mapping for {key}, got {_type_name(data)}")
        for name in data:
            if name not in frozen_known:
                names = ", ".join(e[0] for e in entries if e[1] is not None) or "none"
                raise Invalid(f"unknown field ({key} has: {names})", str(name))
        values = []
        for name, coerce_field, default_value in entries:
            if coerce_field is not None and name in data:
                try:
                    values.append(coerce_field(data[name]))
                except Invalid as exc:
                    raise exc.within(name) from None
            else:
                values.append(default_value)
        return cls(*values)

    cache[key] = build_message
    return build_message


def _zero(field: FieldSpec) -> Any:
    assert field.base is not None
    if field.cardinality == SCALAR:
        if field.base in FLOAT_TYPES:
            return 0.0
        if field.base == "bool":
            return False
        if field.base == "string":
            return ""
        return 0
    if field.base == "string":
        return [""] * field.size if field.cardinality == ARRAY else []
    dtype = _NUMPY_DTYPES.get(field.base, np.dtype(np.uint8))
    return np.zeros(field.size if field.cardinality == ARRAY else 0, dtype)
