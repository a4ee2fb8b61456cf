"""The codec's internal model of a ROS message definition, and :class:`FieldDef`."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from rosbags.interfaces import Nodetype

__all__ = [
    "DUMMY_FIELD",
    "FLOAT_TYPES",
    "INT_RANGES",
    "PRIMITIVE_TYPES",
    "DescribedTypes",
    "FieldDef",
    "FieldSpec",
    "MsgDef",
    "msgdef_from_rosbags",
]

DUMMY_FIELD = "structure_needs_at_least_one_member"
"""The placeholder member ROS 2 gives an empty message; hidden from users."""

INT_RANGES: dict[str, tuple[int, int]] = {
    "byte": (-128, 255),  # an octet; rosbags stores it signed, ROS 2 unsigned
    "char": (0, 255),
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}
FLOAT_TYPES = frozenset({"float32", "float64", "float128"})
PRIMITIVE_TYPES = frozenset({*INT_RANGES, *FLOAT_TYPES, "bool", "string", "wchar", "wstring"})

SCALAR = 0
ARRAY = 1
SEQUENCE = 2


@dataclass(frozen=True, slots=True)
class FieldDef:
    """One field of a message definition, as :meth:`CodecRegistry.definition` reports it.

    ``type`` is the element type as written in a ``.msg`` file: a primitive
    (``"float64"``, ``"uint8"``, ``"string"``, ``"byte"``, ...) or a normalised
    complex type name (``"geometry_msgs/msg/Vector3"``). A bounded string is
    ``"string"`` with its bound in ``upper_bound`` when the field is a scalar,
    and ``"string<=N"`` when it is the element of an array. ``array`` says
    whether the field is an array; ``array_length`` is the length of a
    fixed-size array (``None`` otherwise); ``upper_bound`` is the bound of a
    bounded sequence (``T[<=N]``) or of a scalar bounded string, else ``None``.
    ``default`` is the default value the definition declares (a list for array
    fields), ``None`` when it declares none.
    """

    name: str
    type: str
    array: bool
    array_length: int | None
    upper_bound: int | None
    default: object | None = None


@dataclass(frozen=True, slots=True)
class FieldSpec:
    """A field as the codec needs it. Exactly one of ``base`` (primitive type)
    and ``ref`` (complex type, canonical name) is set. ``cardinality`` is
    :data:`SCALAR`, :data:`ARRAY` (``size`` = length) or :data:`SEQUENCE`
    (``size`` = bound, 0 = unbounded). ``default`` is the declared default
    (a tuple for arrays) or ``None``."""

    name: str
    base: str | None
    ref: str | None
    string_bound: int = 0
    cardinality: int = SCALAR
    size: int = 0
    default: object | None = None

    @property
    def desc(self) -> Any:
        """The field's rosbags ``FieldDesc``."""
        inner: tuple[Any, Any] = (
            (Nodetype.BASE, (self.base, self.string_bound))
            if self.base is not None
            else (Nodetype.NAME, self.ref)
        )
        if self.cardinality == SCALAR:
            return inner
        node = Nodetype.ARRAY if self.cardinality == ARRAY else Nodetype.SEQUENCE
        return (node, (inner, self.size))

    def with_ref(self, ref: str) -> FieldSpec:
        """A copy referring to ``ref`` instead."""
        return FieldSpec(
            self.name, None, ref, self.string_bound, self.cardinality, self.size, self.default
        )

    def to_fielddef(self) -> FieldDef:
        """The public description of this field."""
        if self.base is not None:
            typ = self.base
            if self.base == "string" and self.string_bound and self.cardinality != SCALAR:
                typ = f"string<={self.string_bound}"
        else:
            assert self.ref is not None
            typ = self.ref
        default = list(self.default) if isinstance(self.default, tuple) else self.default
        if self.cardinality == SCALAR:
            bound = self.string_bound if self.base == "string" and self.string_bound else None
            return FieldDef(self.name, typ, False, None, bound, default)
        if self.cardinality == ARRAY:
            return FieldDef(self.name, typ, True, self.size, None, default)
        return FieldDef(self.name, typ, True, None, self.size or None, default)


@dataclass(frozen=True, slots=True)
class MsgDef:
    """A parsed message definition: canonical ``name``, fields in wire order
    (an empty message has the single hidden :data:`DUMMY_FIELD`) and the
    constants as rosbags ``(name, type, value)`` triples."""

    name: str
    fields: tuple[FieldSpec, ...]
    constants: tuple[tuple[str, str, Any], ...] = ()

    @property
    def wire(self) -> tuple[tuple[str, Any], ...]:
        """The rosbags field list; two definitions with equal ``wire`` values
        serialise identically."""
        return tuple((f.name, f.desc) for f in self.fields)

    @property
    def visible_fields(self) -> tuple[FieldSpec, ...]:
        """The fields a user sees (the empty-message placeholder is hidden)."""
        if len(self.fields) == 1 and self.fields[0].name == DUMMY_FIELD:
            return ()
        return self.fields

    def refs(self) -> Iterable[str]:
        """Names of the complex types this definition uses."""
        return (f.ref for f in self.fields if f.ref is not None)

    def rosbags_entry(self, rename: dict[str, str] | None = None) -> tuple[list[Any], list[Any]]:
        """The rosbags ``Typesdict`` value for this definition, with type
        references renamed through ``rename``."""
        fields = self.fields
        if rename:
            fields = tuple(
                f.with_ref(rename[f.ref]) if f.ref is not None and f.ref in rename else f
                for f in fields
            )
        return list(self.constants), [(f.name, f.desc) for f in fields]


def _spec_from_desc(name: str, desc: Any, default: object | None) -> FieldSpec:
    node = desc[0]
    cardinality = SCALAR
    size = 0
    if node in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        cardinality = ARRAY if node == Nodetype.ARRAY else SEQUENCE
        desc, size = desc[1]
        node = desc[0]
        if isinstance(default, list):
            default = tuple(default)
    if node == Nodetype.NAME:
        return FieldSpec(name, None, str(desc[1]), 0, cardinality, int(size), default)
    base, bound = desc[1]
    if base in _FLOATS:
        default = _as_float(default)
    return FieldSpec(name, str(base), None, int(bound), cardinality, int(size), default)


_FLOATS = frozenset({"float32", "float64"})


def _as_float(default: object | None) -> object | None:
    """A float field's default as floats (a ``.msg`` may write ``1`` for
    ``1.0``), so templates and JSON carry the field's type."""
    if type(default) is int:
        return float(default)
    if isinstance(default, tuple):
        return tuple(float(v) if type(v) is int else v for v in default)
    return default


def msgdef_from_rosbags(
    name: str,
    constants: Sequence[Any],
    fields: Sequence[tuple[str, Any]],
    defaults: Sequence[object | None] | None = None,
) -> MsgDef:
    """Build a :class:`MsgDef` from a rosbags ``Typesdict`` entry (plus the
    per-field default values, which rosbags does not keep)."""
    if defaults is None:
        defaults = [None] * len(fields)
    specs = tuple(
        _spec_from_desc(fname, desc, default)
        for (fname, desc), default in zip(fields, defaults, strict=True)
    )
    if not specs:
        specs = (FieldSpec(DUMMY_FIELD, "uint8", None),)
    consts = tuple((str(c[0]), str(c[1]), c[2]) for c in constants)
    return MsgDef(name, specs, consts)


@dataclass(frozen=True, slots=True)
class DescribedTypes:
    """What one description defines: the main type's name and hash, the
    codec definitions by canonical name, and the ``.msg`` source texts by
    type name (those the description carried and that match it)."""

    type_name: str
    type_hash: str
    defs: Mapping[str, MsgDef]
    sources: Mapping[str, str] = field(default_factory=dict)
