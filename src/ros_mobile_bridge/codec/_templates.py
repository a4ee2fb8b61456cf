"""Zero-filled template dicts for ROS definitions and JSON Schemas."""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from .._errors import SchemaError
from ._model import ARRAY, FLOAT_TYPES, SCALAR, FieldDef, FieldSpec, MsgDef

__all__ = ["json_definition", "json_template", "ros_template", "zero_value"]

Resolver = Callable[[str], "MsgDef | None"]
_MAX_DEPTH = 64


def zero_value(base: str) -> object:
    """The zero of primitive type ``base``: ``0.0``, ``False``, ``""`` or ``0``."""
    if base in FLOAT_TYPES:
        return 0.0
    if base == "bool":
        return False
    if base in ("string", "wstring"):
        return ""
    return 0


def _default(field: FieldSpec) -> object:
    value = field.default
    if isinstance(value, tuple):
        items = list(value)
        if field.base in FLOAT_TYPES:
            return [float(v) for v in items]
        return items
    if field.base in FLOAT_TYPES and isinstance(value, int | float):
        return float(value)
    return value


def ros_template(msgdef: MsgDef, resolve: Resolver, depth: int = 0) -> dict[str, Any]:
    """A fresh dict with every (visible) field of ``msgdef``: declared defaults
    where the definition has them, else zeros; fixed-size arrays hold that many
    zero elements (a list), sequences are empty; complex fields are templated
    recursively through ``resolve``. Raises :class:`SchemaError` for a
    dependency ``resolve`` does not know."""
    if depth > _MAX_DEPTH:
        raise SchemaError(f"type {msgdef.name!r} nests too deeply (recursive definition?)")
    out: dict[str, Any] = {}
    for field in msgdef.visible_fields:
        if field.default is not None:
            out[field.name] = _default(field)
            continue
        if field.cardinality == SCALAR:
            out[field.name] = _element(field, msgdef, resolve, depth)
        elif field.cardinality == ARRAY:
            out[field.name] = [_element(field, msgdef, resolve, depth) for _ in range(field.size)]
        else:
            out[field.name] = []
    return out


def _element(field: FieldSpec, owner: MsgDef, resolve: Resolver, depth: int) -> object:
    if field.base is not None:
        return zero_value(field.base)
    assert field.ref is not None
    sub = resolve(field.ref)
    if sub is None:
        raise SchemaError(
            f"type {owner.name!r} uses {field.ref!r}, which has no definition "
            "(not sent by the server and not built in)"
        )
    return ros_template(sub, resolve, depth + 1)


# --------------------------------------------------------------------------- JSON Schema


def _resolve_ref(ref: str, root: Any) -> Any:
    if not ref.startswith("#"):
        return {}
    node = root
    for token in ref[1:].split("/"):
        if not token:
            continue
        token = token.replace("~1", "/").replace("~0", "~")
        if isinstance(node, dict) and token in node:
            node = node[token]
        elif isinstance(node, list) and token.isdigit() and int(token) < len(node):
            node = node[int(token)]
        else:
            return {}
    return node


def _schema_type(schema: dict[str, Any]) -> str | None:
    typ = schema.get("type")
    if isinstance(typ, list):
        typ = next((t for t in typ if t != "null"), typ[0] if typ else None)
    if typ is None:
        if "properties" in schema:
            return "object"
        if "items" in schema or "prefixItems" in schema:
            return "array"
    return typ if isinstance(typ, str) else None


def json_template(schema: Any, root: Any = None, depth: int = 0) -> Any:
    """A template value for a JSON Schema: ``default`` wins, then ``const``,
    then the first ``enum`` member; ``$ref`` (local ``#/...``) is followed;
    ``allOf`` is merged, ``anyOf``/``oneOf`` use their first branch; an object
    templates its ``properties``; number/integer -> ``0``, string -> ``""``,
    boolean -> ``False``, null -> ``None``; an array is ``[]`` unless
    ``minItems == maxItems``, then it holds that many element templates."""
    if root is None:
        root = schema
    if depth > _MAX_DEPTH or not isinstance(schema, dict):
        return None
    if "default" in schema:
        return copy.deepcopy(schema["default"])
    if "const" in schema:
        return copy.deepcopy(schema["const"])
    enum = schema.get("enum")
    if isinstance(enum, list) and enum:
        return copy.deepcopy(enum[0])
    ref = schema.get("$ref")
    if isinstance(ref, str):
        return json_template(_resolve_ref(ref, root), root, depth + 1)
    all_of = schema.get("allOf")
    if isinstance(all_of, list) and all_of:
        merged: Any = None
        for sub in all_of:
            value = json_template(sub, root, depth + 1)
            if isinstance(merged, dict) and isinstance(value, dict):
                merged.update(value)
            elif value is not None:
                merged = value
        return merged
    for key in ("anyOf", "oneOf"):
        options = schema.get(key)
        if isinstance(options, list) and options:
            return json_template(options[0], root, depth + 1)
    typ = _schema_type(schema)
    if typ == "object":
        props = schema.get("properties")
        if not isinstance(props, dict):
            return {}
        return {k: json_template(v, root, depth + 1) for k, v in props.items()}
    if typ in ("number", "integer"):
        return 0
    if typ == "string":
        return ""
    if typ == "boolean":
        return False
    if typ == "array":
        lo, hi = schema.get("minItems"), schema.get("maxItems")
        if isinstance(lo, int) and lo == hi and lo > 0:
            prefix = schema.get("prefixItems")
            items = schema.get("items")
            if isinstance(items, list):  # draft 4-2019 tuple validation
                prefix, items = items, schema.get("additionalItems")
            prefix = prefix if isinstance(prefix, list) else []
            return [
                json_template(prefix[i] if i < len(prefix) else items, root, depth + 1)
                for i in range(lo)
            ]
        return []
    return None


_JSON_PRIMITIVES = {"number": "float64", "integer": "int64", "string": "string", "boolean": "bool"}


def _json_element_type(schema: Any, root: Any) -> str:
    if not isinstance(schema, dict):
        return "object"
    ref = schema.get("$ref")
    if isinstance(ref, str):
        name = ref.rsplit("/", 1)[-1]
        target = _resolve_ref(ref, root)
        title = target.get("title") if isinstance(target, dict) else None
        return str(title or name or "object")
    typ = _schema_type(schema)
    if typ in _JSON_PRIMITIVES:
        return _JSON_PRIMITIVES[typ]
    title = schema.get("title")
    return str(title) if isinstance(title, str) and title else str(typ or "object")


def json_definition(schema: Any) -> list[FieldDef]:
    """Top-level fields of a JSON Schema object: number -> ``float64``,
    integer -> ``int64``, string -> ``string``, boolean -> ``bool``, a nested
    object -> its ``title`` (or ``"object"``); arrays have ``array=True``, a
    fixed length when ``minItems == maxItems`` and ``upper_bound = maxItems``
    otherwise; ``default`` is the schema's ``default``."""
    if not isinstance(schema, dict):
        return []
    props = schema.get("properties")
    if not isinstance(props, dict):
        return []
    out: list[FieldDef] = []
    for name, sub in props.items():
        default = copy.deepcopy(sub.get("default")) if isinstance(sub, dict) else None
        if isinstance(sub, dict) and _schema_type(sub) == "array":
            lo, hi = sub.get("minItems"), sub.get("maxItems")
            fixed = lo if isinstance(lo, int) and lo == hi else None
            bound = hi if fixed is None and isinstance(hi, int) else None
            items = sub.get("items")
            out.append(
                FieldDef(name, _json_element_type(items, schema), True, fixed, bound, default)
            )
        else:
            out.append(FieldDef(name, _json_element_type(sub, schema), False, None, None, default))
    return out
