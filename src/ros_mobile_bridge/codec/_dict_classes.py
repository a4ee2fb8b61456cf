"""Decoded mappings -> message class instances, generated per type.

A JSON bridge (rosbridge, a Foxglove ``json`` channel of a ROS type) hands
over a message as nested dicts and lists; :func:`build_dict_converter` makes,
for one type and the definitions it uses, a function that turns such a
mapping into an instance of the type's class, built as a decoder builds one
(``cls.__new__`` and a store per slot; no constructor) when every field is
present; a message with fields left out is completed with the defaults
through :meth:`RosMessage.from_dict` (slower, and checked). Values are taken as the bridge wrote them, converted
only where the class's form differs from JSON's: a ``float`` field given an
``int`` (``0`` for ``0.0``) is made a float, a numeric or bool array becomes a
numpy array of the field's dtype (from a list, or from the base64 text
rosbridge sends for ``uint8[]``/``byte[]``/``char[]``, or kept when it is
one already), an array of strings a new list. A mapping that does not fit
(an unknown field, a value of the wrong shape) raises
:class:`~ros_mobile_bridge.DecodeError` naming the type and the field."""

from __future__ import annotations

import base64
import binascii
import keyword
import sys
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from .._errors import DecodeError
from ..interfaces._base import _DTYPES, RosMessage
from ._model import DUMMY_FIELD, FLOAT_TYPES, INT_RANGES, SCALAR, FieldSpec, MsgDef

__all__ = ["build_dict_converter"]

_STRINGS = frozenset({"string", "wstring"})


if sys.version_info >= (3, 11):

    def _from_base64(text: str) -> bytes:
        """Strict base64 (binascii's own check: twice as fast as base64's)."""
        return binascii.a2b_base64(text, strict_mode=True)

else:  # pragma: no cover - Python 3.10 has no strict_mode

    def _from_base64(text: str) -> bytes:
        return base64.b64decode(text, validate=True)


def _array(value: Any, dtype: np.dtype[Any]) -> np.ndarray[Any, Any]:
    """A numeric or bool array field's value as a numpy array of ``dtype``."""
    if type(value) is np.ndarray:
        return value if value.dtype == dtype else value.astype(dtype)
    if isinstance(value, str):  # rosbridge: uint8[] / byte[] / char[] as base64
        try:
            raw = _from_base64(value)
        except (binascii.Error, ValueError) as exc:
            raise ValueError(f"not base64: {exc}") from None
        return np.frombuffer(raw, np.uint8).view(dtype)
    if isinstance(value, bytes | bytearray | memoryview):
        return np.frombuffer(value, np.uint8).view(dtype)
    return np.array(value, dtype)


def _strings(value: Any) -> list[str]:
    if isinstance(value, str) or not isinstance(value, list | tuple):
        raise TypeError(f"expected a list of strings, got {type(value).__name__}")
    return list(value)


class _Source:
    """The generated module: one function per type of the closure."""

    def __init__(self, defs: Mapping[str, MsgDef], classes: Callable[[str], type[RosMessage]]):
        self.defs = defs
        self.classes = classes
        self.names: dict[str, str] = {}
        self.lines: list[str] = []
        self.env: dict[str, Any] = {
            "new": object.__new__,
            "float": float,
            "int": int,
            "bool": bool,
            "str": str,
            "setattr": setattr,
            "_array": _array,
            "_strings": _strings,
        }

    def function(self, key: str) -> str:
        name = self.names.get(key)
        if name is not None:
            return name
        index = len(self.names)
        name = self.names[key] = f"conv_{index}"
        self.env[f"C_{index}"] = self.classes(key)
        body: list[str] = [f"def {name}(d):", f"    o = new(C_{index})"]
        for spec in self.defs[key].fields:
            if spec.name == DUMMY_FIELD:
                continue
            body.append("    " + self._store(spec, self._value(spec, f"d[{spec.name!r}]")))
        body.append("    return o")
        self.lines.extend(body)
        self.lines.append("")
        return name

    def _store(self, spec: FieldSpec, value: str) -> str:
        if keyword.iskeyword(spec.name):  # not an attribute name in source
            return f"setattr(o, {spec.name!r}, {value})"
        return f"o.{spec.name} = {value}"

    def _value(self, spec: FieldSpec, item: str) -> str:
        if spec.ref is not None:
            sub = self.function(spec.ref)
            if spec.cardinality == SCALAR:
                return f"{sub}({item})"
            return f"[{sub}(v) for v in {item}]"
        base = spec.base
        assert base is not None
        if spec.cardinality != SCALAR:
            if base in _STRINGS:
                return f"_strings({item})"
            dtype = _DTYPES.get(base)
            if dtype is None:
                raise DecodeError(f"no array form for {base}[]")
            self.env[f"D_{dtype}"] = np.dtype(dtype)
            return f"_array({item}, D_{dtype})"
        if base in FLOAT_TYPES:
            return f"float({item})"
        if base in INT_RANGES:  # (the codec's integer types)
            return f"int({item})"
        if base == "bool":
            return f"bool({item})"
        return f"str({item})"


def build_dict_converter(
    key: str, defs: Mapping[str, MsgDef], classes: Callable[[str], type[RosMessage]]
) -> Callable[[Any], RosMessage]:
    """A function turning a decoded mapping of type ``key`` into an instance
    of ``classes(key)``; ``defs`` holds ``key`` and every type it uses,
    ``classes`` gives each one's class. The function raises
    :class:`~ros_mobile_bridge.DecodeError` and nothing else. A message
    with fields left out (a JSON channel may leave out zeros) is completed
    with the definition's defaults (:meth:`RosMessage.from_dict`, with its
    checks: a slower path)."""
    source = _Source(defs, classes)
    top = source.function(key)
    text = "\n".join(source.lines)
    exec(compile(text, f"<dict converter of {key}>", "exec"), source.env)
    convert: Callable[[Any], RosMessage] = source.env[top]

    cls = classes(key)

    def to_instance(data: Any) -> RosMessage:
        """``data`` (nested mappings and lists) as an instance of its class."""
        try:
            return convert(data)
        except KeyError as exc:
            missing = exc.args[0]
        except Exception as exc:
            raise DecodeError(f"cannot decode {key}: {type(exc).__name__}: {exc}") from None
        try:  # a partial message (a JSON channel may leave out zeros): the defaults fill it
            return cls.from_dict(data)
        except Exception as exc:
            raise DecodeError(
                f"cannot decode {key}: field {missing!r} missing, and as a partial message: {exc}"
            ) from None

    return to_instance
