"""REP-2011 type descriptions as the codec's definitions.

A ROS 2 node (Iron and later) answers ``~/get_type_description``
(``type_description_interfaces/srv/GetTypeDescription``) with the
*type description* of any type it uses: the main type's fields and those of
every type it refers to, directly or not, each as an
``IndividualTypeDescription`` (``type_name`` and ``fields``, each field
``{"name", "type": {"type_id", "capacity", "string_capacity",
"nested_type_name"}, "default_value"}``), plus the interface source texts
(``type_sources``) when asked for them. The share/``<pkg>``/``<kind>``/``*.json``
files rosidl installs hold the same thing under ``"type_description_msg"``.

This module turns such a description (as a plain mapping) into

* its RIHS01 hash, computed with the same canonical JSON and digest as
  :func:`~._typehash.type_hash` (default values are not part of it), and
* the :class:`~._model.MsgDef` of every type the codec has to build (a
  service's or action's own composite types are left out: ``type_hash``
  synthesises them), with the default values the description gives and,
  when a ``msg`` source text describes exactly the same fields, that
  text's constants and defaults; the ``msg`` texts are kept for schema text.

:class:`DescriptionCache` keeps what a process learnt, keyed by hash, so a
second connection does not ask again. Everything here is pure and
thread-safe; input from the network raises :class:`SchemaError` (or its
:class:`HashMismatch`) and nothing else.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterable, Mapping
from typing import Any, Final

from .._errors import SchemaError
from ..interfaces._base import RosMessage
from ._convert import Invalid, check_default
from ._lru import LruCache
from ._model import DUMMY_FIELD, SCALAR, DescribedTypes, FieldSpec, MsgDef
from ._names import is_valid_type_name
from ._parse import parse_ros2msg
from ._typehash import (
    ARRAY_OFFSET,
    BOUNDED_SEQUENCE_OFFSET,
    BOUNDED_STRING_IDS,
    FIELD_TYPE_NESTED_TYPE,
    PRIMITIVE_IDS,
    UNBOUNDED_SEQUENCE_OFFSET,
    Field,
    TypeDesc,
    desc_from_msgdef,
    digest,
    is_derived_composite,
)

__all__ = [
    "DESCRIPTION_CACHE",
    "DESCRIPTION_CACHE_MAX",
    "MAX_DESCRIBED_TYPES",
    "DescribedTypes",
    "DescriptionCache",
    "HashMismatch",
    "describe",
    "description_hash",
]

MAX_DESCRIBED_TYPES: Final = 512
"""The most individual types one description may hold (a peer cannot make
the codec build without bound)."""
DESCRIPTION_CACHE_MAX: Final = 256
"""How many fetched descriptions (by hash) a process keeps."""
_FIELD_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,254}")
_CHAR_ID: Final = 13
_MAX_DEFAULT: Final = 65536
_ELEMENT: Final = {type_id: base for base, type_id in PRIMITIVE_IDS.items() if base != "char"}
_KINDS = (
    (0, SCALAR),
    (ARRAY_OFFSET, 1),
    (BOUNDED_SEQUENCE_OFFSET, 2),
    (UNBOUNDED_SEQUENCE_OFFSET, 2),
)


class HashMismatch(SchemaError):
    """A description whose RIHS01 hash is not the one asked for: it
    describes another definition, and decoding with it would deliver
    garbage."""

    def __init__(self, type_name: str, expected: str, actual: str) -> None:
        super().__init__(
            f"the description of {type_name} hashes to {actual}, not {expected} (the hash of "
            "the type in use): refused"
        )
        self.type_name = type_name
        self.expected = expected
        self.actual = actual


def _get(mapping: Any, key: str, kind: type | tuple[type, ...], where: str) -> Any:
    value = mapping.get(key) if isinstance(mapping, Mapping) else None
    if kind is int:
        item = getattr(value, "item", None)
        if item is not None and not isinstance(value, list | tuple):
            value = item()  # a numpy scalar from a decoded response
        if isinstance(value, bool) or not isinstance(value, int):
            raise SchemaError(f"type description: {where}.{key} is not an integer: {value!r:.80}")
        return value
    if not isinstance(value, kind):
        raise SchemaError(f"type description: {where}.{key} is missing or wrong: {value!r:.80}")
    return value


def _field(owner: str, index: int, raw: Any) -> tuple[Field, str]:
    where = f"{owner}.fields[{index}]"
    name = _get(raw, "name", str, where)
    if not _FIELD_NAME.fullmatch(name):
        raise SchemaError(f"type description: {where} has the invalid name {name!r:.80}")
    typ = _get(raw, "type", Mapping, where)
    type_id = _get(typ, "type_id", int, f"{where}.type")
    capacity = _get(typ, "capacity", int, f"{where}.type")
    string_capacity = _get(typ, "string_capacity", int, f"{where}.type")
    nested = _get(typ, "nested_type_name", str, f"{where}.type")
    default = raw.get("default_value", "") if isinstance(raw, Mapping) else ""
    if not isinstance(default, str):
        default = ""
    if not (0 <= type_id < 192 and 0 <= capacity < 2**32 and 0 <= string_capacity < 2**32):
        raise SchemaError(f"type description: {where} has an invalid type {typ!r:.120}")
    element = type_id % ARRAY_OFFSET
    if element == FIELD_TYPE_NESTED_TYPE:
        if not is_valid_type_name(nested):
            raise SchemaError(f"type description: {where} nests the invalid type {nested!r:.80}")
    elif nested:
        raise SchemaError(f"type description: {where} names a nested type for a primitive")
    elif element == _CHAR_ID:
        raise SchemaError(
            f"type description: {where} is an IDL char, which no .msg interface uses and this "
            "library does not read"
        )
    elif element not in _ELEMENT and element not in BOUNDED_STRING_IDS.values():
        raise SchemaError(f"type description: {where} has the unknown type id {type_id}")
    return (name, int(type_id), int(capacity), int(string_capacity), nested), default


def _individual(raw: Any, where: str) -> tuple[TypeDesc, tuple[str, ...]]:
    name = _get(raw, "type_name", str, where)
    if not is_valid_type_name(name):
        raise SchemaError(f"type description: {where} has the invalid type name {name!r:.80}")
    fields = _get(raw, "fields", (list, tuple), where)
    if not fields:
        raise SchemaError(f"type description: {name} has no fields")
    parsed = [_field(name, i, f) for i, f in enumerate(fields)]
    return TypeDesc(name, tuple(f for f, _ in parsed), None), tuple(d for _, d in parsed)


def _individuals(description: Any) -> tuple[TypeDesc, dict[str, tuple[TypeDesc, tuple[str, ...]]]]:
    top, top_defaults = _individual(
        _get(description, "type_description", Mapping, "description"),
        "type_description",
    )
    refs = _get(description, "referenced_type_descriptions", (list, tuple), "description")
    if len(refs) + 1 > MAX_DESCRIBED_TYPES:
        raise SchemaError(
            f"type description of {top.name}: {len(refs) + 1} types, over {MAX_DESCRIBED_TYPES}"
        )
    out = {top.name: (top, top_defaults)}
    for index, raw in enumerate(refs):
        desc, defaults = _individual(raw, f"referenced_type_descriptions[{index}]")
        if desc.name in out:
            if out[desc.name][0].fields != desc.fields:
                raise SchemaError(f"type description: {desc.name} is described twice, differently")
            continue
        out[desc.name] = (desc, defaults)
    for desc, _ in out.values():
        for ref in desc.refs:
            if ref not in out:
                raise SchemaError(
                    f"type description of {top.name}: {desc.name} uses {ref}, which it does not "
                    "describe"
                )
    return top, out


def description_hash(description: Any) -> str:
    """The RIHS01 hash of a REP-2011 ``TypeDescription`` (a mapping with
    ``type_description`` and ``referenced_type_descriptions``), computed as
    rosidl does: default values do not count, the referenced types in name
    order. :class:`SchemaError` for a description that is not well formed
    (missing parts, invalid names or type ids, a type used but not
    described)."""
    top, individuals = _individuals(description)
    return digest(top, (desc for desc, _ in individuals.values()))


def _default(owner: str, spec: FieldSpec, text: str) -> object | None:
    """The default value ``text`` of primitive field ``spec``, in the form
    rosidl writes it (the Python ``str`` of the value: a string as is,
    ``True``, ``1.125``, an array as a tuple), checked against the type."""
    if not text:
        return None
    where = f"type description: {owner}.{spec.name}"
    if len(text) > _MAX_DEFAULT:
        raise SchemaError(f"{where}: a default value over {_MAX_DEFAULT} characters")
    value: object
    if spec.cardinality == SCALAR and spec.base in ("string", "wstring"):
        value = text
    else:
        try:
            value = ast.literal_eval(text)
        except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
            raise SchemaError(f"{where}: bad default {text!r:.80}") from None
        if spec.cardinality != SCALAR:
            if not isinstance(value, tuple | list):
                raise SchemaError(f"{where}: the default of an array is not a list")
            value = tuple(value)
    checked = FieldSpec(
        spec.name, spec.base, None, spec.string_bound, spec.cardinality, spec.size, value
    )
    try:
        check_default(checked)
    except Invalid as exc:
        raise SchemaError(f"{where}: bad default {text!r:.80}: {exc.reason}") from None
    except SchemaError:
        pass  # a type the CDR codec does not build (wstring): said when a codec is asked
    return value


def _msgdef(desc: TypeDesc, defaults: tuple[str, ...]) -> MsgDef:
    specs: list[FieldSpec] = []
    for spec, text in zip(desc.fields, defaults, strict=True):
        name, type_id, capacity, string_capacity, nested = spec
        offset = type_id - type_id % ARRAY_OFFSET
        cardinality = dict(_KINDS)[offset]
        size = capacity if offset in (ARRAY_OFFSET, BOUNDED_SEQUENCE_OFFSET) else 0
        element = type_id % ARRAY_OFFSET
        if element == FIELD_TYPE_NESTED_TYPE:
            specs.append(FieldSpec(name, None, nested, 0, cardinality, size))
            continue
        if element in BOUNDED_STRING_IDS.values():
            base = next(b for b, i in BOUNDED_STRING_IDS.items() if i == element)
            bound = string_capacity
        else:
            base, bound = _ELEMENT[element], 0
        plain = FieldSpec(name, base, None, bound, cardinality, size)
        default = _default(desc.name, plain, text)
        specs.append(
            FieldSpec(name, base, None, bound, cardinality, size, default)
            if default is not None
            else plain
        )
    if len(specs) == 1 and specs[0].name == DUMMY_FIELD:
        specs = [FieldSpec(DUMMY_FIELD, "uint8", None)]
    return MsgDef(desc.name, tuple(specs))


def _from_sources(
    described: dict[str, TypeDesc], sources: Iterable[Any]
) -> tuple[dict[str, MsgDef], dict[str, str]]:
    """The definitions the ``msg``/``srv``/``action`` source texts give that
    describe exactly the fields of the description (their constants and
    defaults kept), and the ``msg`` texts of those types."""
    defs: dict[str, MsgDef] = {}
    texts: dict[str, str] = {}
    for index, raw in enumerate(sources):
        if index >= MAX_DESCRIBED_TYPES:
            break
        try:
            name = _get(raw, "type_name", str, "type_sources")
            encoding = _get(raw, "encoding", str, "type_sources")
            text = _get(raw, "raw_file_contents", str, "type_sources")
            if encoding not in ("msg", "srv", "action") or not is_valid_type_name(name):
                continue
            _mains, parsed = parse_ros2msg(name, text)
        except SchemaError:
            continue  # the description alone still defines the type
        for type_name, msgdef in parsed.items():
            want = described.get(type_name)
            if want is not None and desc_from_msgdef(type_name, msgdef).fields == want.fields:
                defs[type_name] = msgdef
        if encoding == "msg" and name in defs:
            texts[name] = text
    return defs, texts


def describe(
    description: Any,
    type_sources: Iterable[Any] = (),
    *,
    expected_hash: str | None = None,
    max_fields: int | None = None,
) -> DescribedTypes:
    """The definitions a REP-2011 ``TypeDescription`` gives (see the module
    docstring), with the ``TypeSource`` entries of the same answer.

    :class:`HashMismatch` when ``expected_hash`` is given and the
    description's hash differs (nothing is returned for it);
    :class:`SchemaError` for a description that is not well formed, over
    :data:`MAX_DESCRIBED_TYPES` types or ``max_fields`` fields in all, or
    whose types the codec cannot build. Source texts that do not parse or
    describe other fields are ignored. Each may be a message instance (a
    ``type_description_interfaces`` class) or its dict."""
    if isinstance(description, RosMessage):
        description = description.to_dict()
    type_sources = [s.to_dict() if isinstance(s, RosMessage) else s for s in type_sources]
    top, individuals = _individuals(description)
    actual = digest(top, (desc for desc, _ in individuals.values()))
    if expected_hash is not None and actual != expected_hash:
        raise HashMismatch(top.name, expected_hash, actual)
    total = sum(len(desc.fields) for desc, _ in individuals.values())
    if max_fields is not None and total > max_fields:
        raise SchemaError(
            f"the description of {top.name} has {total} fields in {len(individuals)} types, "
            f"over max_schema_fields={max_fields}"
        )
    wanted = {name: entry for name, entry in individuals.items() if not is_derived_composite(name)}
    from_sources, texts = _from_sources({n: d for n, (d, _) in wanted.items()}, type_sources)
    defs = {
        name: from_sources.get(name) or _msgdef(desc, defaults)
        for name, (desc, defaults) in wanted.items()
    }
    return DescribedTypes(top.name, actual, defs, texts)


class DescriptionCache(LruCache[str, DescribedTypes]):
    """Descriptions learnt from the robot, by RIHS01 hash, shared by every
    connection in the process (a hash names one definition, whoever serves
    it). Bounded at ``max_entries`` (default :data:`DESCRIPTION_CACHE_MAX`),
    least recently used out first; ``evicted``, ``hits`` and ``stored`` count
    what happened. Thread-safe."""

    def __init__(self, max_entries: int = DESCRIPTION_CACHE_MAX) -> None:
        super().__init__(max_entries)

    def remember(self, described: DescribedTypes) -> None:
        """Keep ``described`` under its hash."""
        self.put(described.type_hash, described)


DESCRIPTION_CACHE = DescriptionCache()
"""The process's cache of fetched descriptions."""
