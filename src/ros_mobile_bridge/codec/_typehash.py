"""ROS 2 type hashes (``RIHS01_...``, REP-2011 type description hashes).

A ROS 2 Iron+ graph names every topic, service and action type with a hash
of its *type description*: the type's fields plus the descriptions of every
type it refers to, directly or not. rmw implementations (rmw_zenoh in
particular) put that hash into their key expressions and discovery data, so a
client has to compute it exactly as ``rosidl_generator_type_description``
does:

* a type description is ``{"type_name": ..., "fields": [...]}``; each field is
  ``{"name": ..., "type": {"type_id": ..., "capacity": ...,
  "string_capacity": ..., "nested_type_name": ...}}`` with the
  ``type_description_interfaces/msg/FieldType`` ids (a primitive's id, +48
  for a fixed-size array, +96 for a bounded sequence, +144 for an unbounded
  one; ``capacity`` is the array length or sequence bound, ``string_capacity``
  the bound of a bounded string). Default values and constants are not part
  of the hash, and neither are comments;
* the hashed text is ``json.dumps`` (separators ``", "`` and ``": "``, keys
  in the order above) of ``{"type_description": <the type>,
  "referenced_type_descriptions": [<every referenced type, once, sorted by
  name>]}``; the hash is ``"RIHS01_"`` + the lowercase hex SHA-256 of its
  UTF-8 bytes;
* a service ``pkg/srv/S`` is described as a type with the fields
  ``request_message``, ``response_message`` and ``event_message`` (of types
  ``S_Request``, ``S_Response`` and ``S_Event``); ``S_Event`` has the fields
  ``info`` (``service_msgs/msg/ServiceEventInfo``), ``request``
  (``S_Request[<=1]``) and ``response`` (``S_Response[<=1]``);
* an action ``pkg/action/A`` is described with the fields ``goal``,
  ``result``, ``feedback`` (``A_Goal``, ``A_Result``, ``A_Feedback``),
  ``send_goal_service`` and ``get_result_service`` (the services
  ``A_SendGoal`` and ``A_GetResult``) and ``feedback_message``
  (``A_FeedbackMessage``).

The definitions come from a :class:`CodecRegistry` (server schemas, then the
built-in ROS 2 Jazzy ones). The types ROS derives from a service or an action
(``S_Event``, the service and action descriptions themselves, and - when the
registry lacks them - an action's ``A_SendGoal_Request``,
``A_SendGoal_Response``, ``A_GetResult_Request``, ``A_GetResult_Response`` and
``A_FeedbackMessage``) are synthesised here from their parts.
"""

from __future__ import annotations

import hashlib
import json
import threading
import weakref
from collections.abc import Callable, Iterable, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeAlias

from .._errors import SchemaError
from ._model import ARRAY, DUMMY_FIELD, SCALAR, FieldSpec, MsgDef
from ._names import canonical_name, is_valid_type_name, lookup_candidates, split_type_name

__all__ = [
    "ARRAY_OFFSET",
    "BOUNDED_SEQUENCE_OFFSET",
    "BOUNDED_STRING_IDS",
    "FIELD_TYPE_NESTED_TYPE",
    "PRIMITIVE_IDS",
    "UNBOUNDED_SEQUENCE_OFFSET",
    "TypeDesc",
    "definitions_closure",
    "definitions_hash",
    "desc_from_msgdef",
    "digest",
    "is_derived_composite",
    "type_description",
    "type_hash",
]

_Find: TypeAlias = Callable[[str], "tuple[str, object] | None"]
"""A registry's ROS definition lookup (:meth:`CodecRegistry.ros_lookup`):
``(the name found, its definition)`` or ``None``."""


class CodecRegistry(Protocol):
    """What this module needs of a :class:`~._registry.CodecRegistry`: its
    definition lookup, held for a block (named so, not imported: the
    registry builds classes, whose hashes this module computes)."""

    def ros_lookup(self) -> AbstractContextManager[_Find]: ...


FIELD_TYPE_NESTED_TYPE = 1
"""``type_description_interfaces/msg/FieldType.FIELD_TYPE_NESTED_TYPE``."""

PRIMITIVE_IDS: dict[str, int] = {
    "int8": 2,
    "uint8": 3,
    # A ROS 2 ``.msg`` ``char`` is an unsigned 8-bit integer (rosidl maps it to
    # IDL ``uint8``), so it hashes as FIELD_TYPE_UINT8 (e.g. the ``char[16]``
    # of service_msgs/msg/ServiceEventInfo). The codec's model cannot tell it
    # from a native IDL ``char`` (FIELD_TYPE_CHAR = 13), which ROS interfaces
    # generated from ``.msg`` files never contain.
    "char": 3,
    "int16": 4,
    "uint16": 5,
    "int32": 6,
    "uint32": 7,
    "int64": 8,
    "uint64": 9,
    "float32": 10,
    "float64": 11,
    "float128": 12,
    "wchar": 14,
    "bool": 15,
    "byte": 16,
    "string": 17,
    "wstring": 18,
}
"""FieldType ids of the primitive element types, as the codec's model names them."""

BOUNDED_STRING_IDS = {"string": 21, "wstring": 22}
ARRAY_OFFSET = 48
BOUNDED_SEQUENCE_OFFSET = 96
UNBOUNDED_SEQUENCE_OFFSET = 144

_SERVICE_INFO = "service_msgs/msg/ServiceEventInfo"
_UUID = "unique_identifier_msgs/msg/UUID"
_TIME = "builtin_interfaces/msg/Time"

# (field name, type id, capacity, string capacity, nested type name)
Field = tuple[str, int, int, int, str]


@dataclass(frozen=True, slots=True)
class TypeDesc:
    """One individual type description (REP-2011 ``IndividualTypeDescription``
    without default values); ``source`` is the registry definition it was
    made from (``None`` when synthesised from the name alone or read from a
    description)."""

    name: str
    fields: tuple[Field, ...]
    source: MsgDef | None

    @property
    def refs(self) -> tuple[str, ...]:
        return tuple(f[4] for f in self.fields if f[4])

    def as_json(self) -> dict[str, Any]:
        return {
            "type_name": self.name,
            "fields": [
                {
                    "name": name,
                    "type": {
                        "type_id": type_id,
                        "capacity": capacity,
                        "string_capacity": string_capacity,
                        "nested_type_name": nested,
                    },
                }
                for name, type_id, capacity, string_capacity, nested in self.fields
            ],
        }


def _nested(name: str, type_name: str) -> Field:
    return (name, FIELD_TYPE_NESTED_TYPE, 0, 0, type_name)


def _field_from_spec(owner: str, spec: FieldSpec) -> Field:
    """The description of one :class:`~._model.FieldSpec` of ``owner``."""
    if spec.cardinality == SCALAR:
        offset, capacity = 0, 0
    elif spec.cardinality == ARRAY:
        offset, capacity = ARRAY_OFFSET, int(spec.size)
    elif spec.size:
        offset, capacity = BOUNDED_SEQUENCE_OFFSET, int(spec.size)
    else:
        offset, capacity = UNBOUNDED_SEQUENCE_OFFSET, 0
    if spec.ref is not None:
        return (spec.name, offset + FIELD_TYPE_NESTED_TYPE, capacity, 0, str(spec.ref))
    base = str(spec.base)
    bound = int(spec.string_bound) if base in BOUNDED_STRING_IDS else 0
    type_id = BOUNDED_STRING_IDS[base] if bound else PRIMITIVE_IDS.get(base)
    if type_id is None:
        raise SchemaError(
            f"cannot hash {owner!r}: field {spec.name!r} has the type {base!r}, "
            "which has no REP-2011 field type id"
        )
    return (spec.name, offset + type_id, capacity, bound, "")


def desc_from_msgdef(name: str, msgdef: MsgDef) -> TypeDesc:
    fields = tuple(_field_from_spec(name, f) for f in msgdef.fields)
    if not fields:  # ROS gives an empty message one placeholder member
        fields = ((DUMMY_FIELD, PRIMITIVE_IDS["uint8"], 0, 0, ""),)
    return TypeDesc(name, fields, msgdef)


def _synthesised(name: str) -> tuple[Field, ...] | None:
    """The fields of the derived type ``name`` (canonical), when ROS derives
    it from a service or an action; ``None`` for any other name."""
    pkg, kind, typ = split_type_name(name)
    if kind not in ("srv", "action"):
        return None
    base = f"{pkg}/{kind}/{typ}"
    if typ.endswith("_Event"):
        service = base.removesuffix("_Event")
        return (
            _nested("info", _SERVICE_INFO),
            (
                "request",
                BOUNDED_SEQUENCE_OFFSET + FIELD_TYPE_NESTED_TYPE,
                1,
                0,
                f"{service}_Request",
            ),
            (
                "response",
                BOUNDED_SEQUENCE_OFFSET + FIELD_TYPE_NESTED_TYPE,
                1,
                0,
                f"{service}_Response",
            ),
        )
    if kind == "srv" or typ.endswith(("_SendGoal", "_GetResult")):
        if typ.endswith(("_Request", "_Response")):
            return None  # a service's own messages must be defined
        return (
            _nested("request_message", f"{base}_Request"),
            _nested("response_message", f"{base}_Response"),
            _nested("event_message", f"{base}_Event"),
        )
    action_derived: dict[str, tuple[Field, ...]] = {
        "_SendGoal_Request": (_nested("goal_id", _UUID), _nested("goal", "{}_Goal")),
        "_SendGoal_Response": (
            ("accepted", PRIMITIVE_IDS["bool"], 0, 0, ""),
            _nested("stamp", _TIME),
        ),
        "_GetResult_Request": (_nested("goal_id", _UUID),),
        "_GetResult_Response": (
            ("status", PRIMITIVE_IDS["int8"], 0, 0, ""),
            _nested("result", "{}_Result"),
        ),
        "_FeedbackMessage": (_nested("goal_id", _UUID), _nested("feedback", "{}_Feedback")),
    }
    for suffix, fields in action_derived.items():
        if typ.endswith(suffix):
            action = base.removesuffix(suffix)
            return tuple((f[0], f[1], f[2], f[3], f[4].format(action)) for f in fields)
    if typ.endswith(("_Goal", "_Result", "_Feedback", "_Request", "_Response")):
        return None  # an action's own messages must be defined
    return (
        _nested("goal", f"{base}_Goal"),
        _nested("result", f"{base}_Result"),
        _nested("feedback", f"{base}_Feedback"),
        _nested("send_goal_service", f"{base}_SendGoal"),
        _nested("get_result_service", f"{base}_GetResult"),
        _nested("feedback_message", f"{base}_FeedbackMessage"),
    )


def _registered(find: _Find, name: str) -> MsgDef | None:
    """The registry's ROS definition of exactly ``name`` (server schemas, then
    built-in ones; the same type under another kind does not count)."""
    found = find(name)
    if found is None or found[0] != name or not isinstance(found[1], MsgDef):
        return None
    return found[1]


def _describe(find: _Find, name: str, memo: dict[str, TypeDesc]) -> TypeDesc | None:
    """The description of ``name``: the registry's definition, else the
    synthesised one of a derived type, else ``None``. ``memo`` keeps earlier
    descriptions; one made from a definition is reused only while the registry
    still holds that very definition object."""
    msgdef = _registered(find, name)
    desc = memo.get(name)
    if desc is not None and desc.source is msgdef:
        return desc
    if msgdef is not None:
        desc = desc_from_msgdef(name, msgdef)
    else:
        fields = _synthesised(name)
        if fields is None:
            return None
        desc = TypeDesc(name, fields, None)
    memo[name] = desc
    return desc


def _top_name(find: _Find, type_name: str) -> str:
    """The canonical name ``type_name`` refers to. A name without a kind
    segment (``std_srvs/SetBool``) is the first candidate kind that the
    registry defines (or, for a derived type, whose first part it defines)."""
    pkg, kind, _ = split_type_name(type_name)
    if kind is not None or not pkg:
        name = canonical_name(type_name)
    else:
        candidates = lookup_candidates(type_name)
        name = next((c for c in candidates if _defined(find, c)), candidates[0])
    if not is_valid_type_name(name):
        raise ValueError(f"{type_name!r} is not a valid ROS type name (package/kind/Type)")
    return name


def _defined(find: _Find, name: str) -> bool:
    if _registered(find, name) is not None:
        return True
    fields = _synthesised(name)
    return fields is not None and _registered(find, fields[0][4]) is not None


def _closure(find: _Find, name: str, memo: dict[str, TypeDesc]) -> dict[str, TypeDesc]:
    """``name`` and every type it uses, directly or not, by name."""
    top = _describe(find, name, memo)
    if top is None:
        raise SchemaError(
            f"cannot compute the type hash of {name!r}: unknown type (no ROS definition "
            "registered and none built in)"
        )
    closure = {name: top}
    stack = [top]
    while stack:
        current = stack.pop()
        for ref in current.refs:
            if ref in closure:
                continue
            desc = _describe(find, ref, memo)
            if desc is None:
                raise SchemaError(
                    f"cannot compute the type hash of {name!r}: it needs {ref!r} (used by "
                    f"{current.name!r}), which has no definition (not registered and not "
                    "built in)"
                )
            closure[ref] = desc
            stack.append(desc)
    return closure


def digest(top: TypeDesc, referenced: Iterable[TypeDesc]) -> str:
    """The RIHS01 hash of the type ``top`` whose closure is ``referenced``
    (every type it uses, directly or not, each once; any order): the one
    canonical JSON text and SHA-256 every hash of this library goes
    through."""
    refs = {desc.name: desc for desc in referenced if desc.name != top.name}
    document = {
        "type_description": top.as_json(),
        "referenced_type_descriptions": [refs[name].as_json() for name in sorted(refs)],
    }
    text = json.dumps(document, separators=(", ", ": "), sort_keys=False)
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def definitions_closure(type_name: str, defs: Mapping[str, MsgDef]) -> dict[str, MsgDef]:
    """The definitions of the message type ``type_name`` and of every type
    it uses, directly or not, from ``defs`` (by canonical name; other
    entries are left out), ``type_name`` first, then in the order they are
    first used. Raises :class:`SchemaError` naming a type that is missing."""
    top = defs.get(type_name)
    if top is None:
        raise SchemaError(f"no definition of {type_name!r}")
    closure = {type_name: top}
    stack = [top]
    while stack:
        current = stack.pop(0)
        for ref in current.refs():
            if ref in closure:
                continue
            sub = defs.get(ref)
            if sub is None:
                raise SchemaError(
                    f"{type_name!r} needs {ref!r} (used by {current.name!r}), which has no "
                    "definition here"
                )
            closure[ref] = sub
            stack.append(sub)
    return closure


def definitions_hash(type_name: str, defs: Mapping[str, MsgDef]) -> str:
    """The RIHS01 hash of the message type ``type_name`` from ``defs``
    alone (its definition and those of every type it uses, by canonical
    name): what :func:`type_hash` gives from a registry holding these
    definitions. Raises :class:`SchemaError` as :func:`definitions_closure`
    does, and for a field type with no REP-2011 id."""
    closure = definitions_closure(type_name, defs)
    descs = [desc_from_msgdef(name, msgdef) for name, msgdef in closure.items()]
    return digest(descs[0], descs)


def _digest(name: str, closure: dict[str, TypeDesc]) -> str:
    return digest(closure[name], closure.values())


def is_derived_composite(name: str) -> bool:
    """Whether ``name`` (canonical) is a type ROS describes only as the sum
    of other types and never sends: a service (``pkg/srv/S``), its
    ``S_Event``, an action (``pkg/action/A``) or its ``A_SendGoal`` /
    ``A_GetResult`` services. This module synthesises those from their
    parts, so they need no registered definition."""
    fields = _synthesised(name)
    return fields is not None and fields[0][0] in ("request_message", "info", "goal")


@dataclass(slots=True)
class _Memo:
    """What :func:`type_hash` keeps per registry (used under its lock):
    individual descriptions, and each hash with the descriptions it covered."""

    descs: dict[str, TypeDesc] = field(default_factory=dict)
    hashes: dict[str, tuple[tuple[TypeDesc, ...], str]] = field(default_factory=dict)


_memo_lock = threading.Lock()
_memos: weakref.WeakKeyDictionary[CodecRegistry, _Memo] = weakref.WeakKeyDictionary()


def _memo(registry: CodecRegistry) -> _Memo:
    with _memo_lock:
        memo = _memos.get(registry)
        if memo is None:
            memo = _memos[registry] = _Memo()
        return memo


def type_hash(registry: CodecRegistry, type_name: str) -> str:
    """The ROS 2 type hash (``"RIHS01_"`` + 64 lowercase hex digits) of
    ``type_name``, as ``rosidl_generator_type_description`` computes it.

    ``type_name`` is a message (``pkg/msg/T``), a service (``pkg/srv/S``), an
    action (``pkg/action/A``) or a type ROS derives from one (``S_Request``,
    ``S_Response``, ``S_Event``, ``A_Goal``, ``A_Result``, ``A_Feedback``,
    ``A_SendGoal``, ``A_GetResult``, ``A_SendGoal_Request``, ...,
    ``A_FeedbackMessage``), in any spelling :func:`normalize_type_name`
    accepts (a name without a kind segment is looked up as a message, a
    service and an action). Definitions come from ``registry``: the ROS
    (``ros2msg``, ``ros2idl``, ``ros2action``) schemas registered there, then
    the built-in ROS 2 Jazzy definitions; a nested type name must match a
    definition exactly (``pkg/msg/T`` is not found as ``pkg/srv/T``). The
    result depends only on the field names and types (array and string
    bounds included), never on comments, default values or constants.

    Raises :class:`SchemaError` naming the type when ``type_name`` or a type
    it uses, directly or not, has no definition (or a field's type has no
    REP-2011 id); ``ValueError`` for a name that is not ``pkg/kind/Type`` and
    ``TypeError`` for a non-``str`` name. Thread-safe. Results are cached per
    registry and recomputed when a definition they used has been replaced.
    """
    memo = _memo(registry)
    with registry.ros_lookup() as find:
        name = _top_name(find, type_name)
        closure = _closure(find, name, memo.descs)
        descs = tuple(closure.values())
        cached = memo.hashes.get(name)
        if (
            cached is not None
            and len(cached[0]) == len(descs)
            and all(a is b for a, b in zip(cached[0], descs, strict=True))
        ):
            return cached[1]
        digest = _digest(name, closure)
        memo.hashes[name] = (descs, digest)
        return digest


def _default_text(value: object) -> str:
    """A default value as rosidl writes it in a description (``str`` of the
    Python value; arrays as tuples)."""
    if value is None:
        return ""
    if isinstance(value, list | tuple):
        return str(tuple(value))
    return str(value)


def _with_defaults(desc: TypeDesc) -> dict[str, Any]:
    out = desc.as_json()
    source = desc.source
    if source is not None and len(source.fields) == len(out["fields"]):
        for entry, spec in zip(out["fields"], source.fields, strict=True):
            entry["default_value"] = _default_text(spec.default)
    else:
        for entry in out["fields"]:
            entry["default_value"] = ""
    return out


def type_description(registry: CodecRegistry, type_name: str) -> dict[str, Any]:
    """The REP-2011 ``TypeDescription`` of ``type_name`` from ``registry``'s
    definitions, as a plain mapping (``type_description`` and the
    ``referenced_type_descriptions`` in name order, each field with its
    ``default_value`` text): what a node answers on
    ``get_type_description``; its hash is :func:`type_hash`'s. Raises as
    :func:`type_hash` does."""
    memo = _memo(registry)
    with registry.ros_lookup() as find:
        name = _top_name(find, type_name)
        closure = _closure(find, name, memo.descs)
    return {
        "type_description": _with_defaults(closure[name]),
        "referenced_type_descriptions": [
            _with_defaults(closure[ref]) for ref in sorted(closure) if ref != name
        ],
    }
