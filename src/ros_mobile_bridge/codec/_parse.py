"""Schema text -> :class:`MsgDef` objects, using rosbags' ``.msg`` and IDL parsers.

rosbags' own ``get_types_from_msg``/``get_types_from_idl`` drop the default
values a ``.msg`` field declares, and ``get_types_from_msg`` renames a service
type ``pkg/srv/X_Request`` to ``pkg/srv/msg/X_Request``. So this module drives
the parsers (``MSGParser``, ``IDLParser``) itself, one definition block at a
time, and fixes the names up.
"""

from __future__ import annotations

import dataclasses
import json
import re
from typing import Any

from rosbags.typesys.base import make_typesdict
from rosbags.typesys.idl import IDLParser
from rosbags.typesys.msg import MSGParser

from .._errors import SchemaError
from ._convert import Invalid, check_default
from ._model import FieldSpec, MsgDef, msgdef_from_rosbags
from ._names import canonical_name, is_valid_type_name, same_type_name, split_type_name

__all__ = ["parse_jsonschema", "parse_ros2idl", "parse_ros2msg", "parse_srv"]

_SEPARATOR = re.compile(r"^={10,}[ \t]*$", re.MULTILINE)
_BLOCK_HEADER = re.compile(r"[ \t]*(MSG|IDL):[ \t]*(\S+)[ \t]*")
_SPLIT_LINE = re.compile(r"^---[ \t]*$", re.MULTILINE)
_NESTED_KIND = re.compile(r"([A-Za-z][A-Za-z0-9_]*)/(srv|action)/msg/([A-Za-z][A-Za-z0-9_]*)")
_MAX_MESSAGE = 800


def _short(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    return text if len(text) <= _MAX_MESSAGE else text[:_MAX_MESSAGE] + " ..."


def _blocks(text: str) -> list[tuple[str | None, str]]:
    """Split concatenated definitions into ``(header name, body)`` pairs; the
    first block has no header (``None``)."""
    chunks = _SEPARATOR.split(text)
    blocks: list[tuple[str | None, str]] = [(None, chunks[0])]
    for chunk in chunks[1:]:
        body = chunk.lstrip("\n")
        header, _, body = body.partition("\n")
        match = _BLOCK_HEADER.fullmatch(header)
        if match is None:
            raise ValueError(
                f"expected 'MSG: <type>' or 'IDL: <type>' after a separator, got {header!r}"
            )
        blocks.append((match.group(2), body))
    return blocks


def _as_text(data: str | bytes) -> str:
    if isinstance(data, bytes | bytearray | memoryview):
        data = bytes(data).decode("utf-8")
    if not isinstance(data, str):
        raise TypeError(f"schema data must be str or bytes, not {type(data).__name__}")
    return data.replace("\r\n", "\n").replace("\r", "\n")


def _checked_name(name: str) -> str:
    canon = canonical_name(name)
    if not is_valid_type_name(canon):
        raise ValueError(f"{name!r} is not a valid ROS type name (package/kind/Type)")
    return canon


def _fix_ref(ref: str, renames: dict[str, str]) -> str:
    if ref in renames:
        return renames[ref]
    match = _NESTED_KIND.fullmatch(ref)
    if match is not None:
        return f"{match.group(1)}/{match.group(2)}/{match.group(3)}"
    return _checked_name(ref)


def _wstring(spec: FieldSpec) -> FieldSpec:
    """rosbags' ``.msg`` parser reads the primitive ``wstring`` as a type name
    of the package; it is the primitive (a type hash needs it; rosbags'
    CDR codec refuses it)."""
    return dataclasses.replace(spec, base="wstring", ref=None)


def _to_msgdefs(messages: list[Any], renames: dict[str, str]) -> dict[str, MsgDef]:
    typesdict = make_typesdict(messages)
    out: dict[str, MsgDef] = {}
    for message in messages:
        constants, fields = typesdict[message.name]
        defaults = [field.value for field in message.fields]
        msgdef = msgdef_from_rosbags(
            renames.get(message.name, message.name), constants, fields, defaults
        )
        specs = tuple(
            _wstring(f)
            if f.ref is not None and f.ref.endswith("/wstring")
            else f.with_ref(_fix_ref(f.ref, renames))
            if f.ref is not None
            else f
            for f in msgdef.fields
        )
        name = _checked_name(msgdef.name)
        seen: set[str] = set()
        for spec in specs:
            if spec.name in seen:  # rosidl refuses it too
                raise ValueError(f"{name}: field {spec.name!r} is defined twice")
            seen.add(spec.name)
            if spec.default is None:
                continue
            if spec.ref is not None:
                raise ValueError(
                    f"{name}: field {spec.name!r} of complex type {spec.ref!r} cannot have a "
                    "default value"
                )
            try:
                check_default(spec)
            except Invalid as exc:
                raise ValueError(
                    f"{name}: invalid default value for field {spec.name!r}: {exc.reason}"
                ) from None
        out[name] = MsgDef(name, specs, msgdef.constants)
    return out


def _parse_msg_blocks(blocks: list[tuple[str, str]]) -> dict[str, MsgDef]:
    """Parse ``(canonical name, .msg body)`` pairs. Every block is parsed under
    a ``pkg/msg/Type`` alias so that rosbags resolves relative type names
    against the package's ``msg`` folder (as ``rosidl`` does for services and
    actions) and does not mangle ``srv``/``action`` names."""
    messages: list[Any] = []
    renames: dict[str, str] = {}
    for canon, body in blocks:
        pkg, _, typ = canon.split("/")
        alias = f"{pkg}/msg/{typ}"
        if alias != canon:
            renames[alias] = canon
        messages.extend(MSGParser(f"MSG: {alias}\n{body}").specification())
    return _to_msgdefs(messages, renames)


def _split_interface(canon: str, body: str) -> list[tuple[str, str]] | None:
    """A ``.srv`` (``---`` once) or ``.action`` (``---`` twice) text registered
    under the interface's own name -> its message blocks; ``None`` for a
    plain message."""
    parts = _SPLIT_LINE.split(body)
    if len(parts) == 1:
        return None
    pkg, kind, typ = canon.split("/")
    suffixes: tuple[str, ...]
    if len(parts) == 2:
        suffixes = ("_Request", "_Response")
        kind = "srv" if kind == "msg" else kind
    elif len(parts) == 3:
        suffixes = ("_Goal", "_Result", "_Feedback")
        kind = "action" if kind == "msg" else kind
    else:
        raise ValueError("too many '---' separator lines")
    return [(f"{pkg}/{kind}/{typ}{s}", part) for s, part in zip(suffixes, parts, strict=True)]


def parse_ros2msg(name: str, data: str | bytes) -> tuple[list[str], dict[str, MsgDef]]:
    """Parse a ``ros2msg`` schema: the ``.msg`` text of ``name``, optionally
    followed by its dependencies in the concatenated ``=====``/``MSG: pkg/Type``
    form. Returns the canonical names of the schema's own types (``[name]``)
    and all definitions by canonical name.

    A ``.srv``/``.action`` text (``---`` separated) registered under the
    interface name has the own types ``<name>_Request``/``<name>_Response``
    (or ``_Goal``/``_Result``/``_Feedback``). Raises :class:`SchemaError` when
    the text does not parse."""
    try:
        canon = _checked_name(name)
        text = _as_text(data)
        raw_blocks = _blocks(text)
        blocks: list[tuple[str, str]] = []
        head = raw_blocks[0][1]
        if (split := _split_interface(canon, head)) is not None:
            blocks.extend(split)
        else:
            blocks.append((canon, head))
        mains = [canon for canon, _ in blocks]
        for header, body in raw_blocks[1:]:
            assert header is not None
            blocks.append((_checked_name(header), body))
        return mains, _parse_msg_blocks(blocks)
    except SchemaError:
        raise
    except Exception as exc:
        raise SchemaError(f"cannot parse ros2msg schema for {name!r}: {_short(exc)}") from exc


def parse_srv(name: str, text: str) -> dict[str, MsgDef]:
    """Parse the ``.srv`` text of service ``name`` (``pkg/srv/X``) into
    ``pkg/srv/X_Request`` and ``pkg/srv/X_Response`` (and their dependencies)."""
    return parse_ros2msg(name, text if _SPLIT_LINE.search(text) else text + "\n---\n")[1]


def action_texts(name: str, data: str | bytes) -> dict[str, str]:
    """The ``.msg`` texts of every type ROS 2 derives from the ``.action``
    text of action ``name`` (``pkg/action/X``): ``X_Goal``, ``X_Result``,
    ``X_Feedback``, the ``X_SendGoal`` and ``X_GetResult`` service requests
    and responses, and ``X_FeedbackMessage``, by canonical name. Raises
    :class:`SchemaError` when the text is not three sections split by
    ``---``."""
    canon = _checked_name(name)
    pkg, _, short = canon.split("/")
    base = f"{pkg}/action/{short}"
    sections = _SPLIT_LINE.split(_as_text(data))
    if len(sections) != 3:
        raise SchemaError(
            f"an .action text has three sections split by '---' (goal, result, feedback); "
            f"{name!r} has {len(sections)}"
        )
    goal, result, feedback = sections
    uuid = "unique_identifier_msgs/msg/UUID goal_id\n"
    return {
        f"{base}_Goal": goal,
        f"{base}_Result": result,
        f"{base}_Feedback": feedback,
        f"{base}_SendGoal_Request": f"{uuid}{base}_Goal goal\n",
        f"{base}_SendGoal_Response": "bool accepted\nbuiltin_interfaces/msg/Time stamp\n",
        f"{base}_GetResult_Request": uuid,
        f"{base}_GetResult_Response": f"int8 status\n{base}_Result result\n",
        f"{base}_FeedbackMessage": f"{uuid}{base}_Feedback feedback\n",
    }


def _strip_preprocessor(text: str) -> str:
    return "\n".join("" if line.lstrip().startswith("#") else line for line in text.split("\n"))


def parse_ros2idl(name: str, data: str | bytes) -> tuple[list[str], dict[str, MsgDef]]:
    """Parse a ``ros2idl`` schema: one IDL text, or several IDL texts each
    introduced by the ``=====`` separator line and ``IDL: pkg/msg/Type``.
    Preprocessor lines (``#include``, include guards) are ignored. Returns
    ``([name], defs)``, ``defs`` holding every struct by canonical name.
    Raises :class:`SchemaError` when the text does not parse or does not
    define ``name``."""
    try:
        canon = _checked_name(name)
        text = _as_text(data)
        messages: list[Any] = []
        for _, body in _blocks(text):
            body = _strip_preprocessor(body)
            if body.strip():
                messages.extend(IDLParser(body).specification())
        defs = _to_msgdefs(messages, {})
    except Exception as exc:
        raise SchemaError(f"cannot parse ros2idl schema for {name!r}: {_short(exc)}") from exc
    main = defs.get(canon)
    if main is None:
        main_key = next((k for k in defs if same_type_name(k, name)), None)
        if main_key is None:
            _, _, typ = split_type_name(canon)
            main_key = next((k for k in defs if k.rsplit("/", 1)[-1] == typ), None)
        if main_key is None:
            raise SchemaError(f"ros2idl schema for {name!r} does not define {canon!r}")
        main = defs[main_key]
    return [canon], {canon: MsgDef(canon, main.fields, main.constants)} | {
        k: v for k, v in defs.items() if k != canon
    }


def parse_jsonschema(name: str, data: str | bytes) -> dict[str, Any] | bool:
    """Parse a JSON Schema text. Raises :class:`SchemaError` when it is not
    JSON or not a schema (an object or a boolean)."""
    try:
        schema = json.loads(_as_text(data))
    except Exception as exc:
        raise SchemaError(f"cannot parse jsonschema schema for {name!r}: {_short(exc)}") from exc
    if not isinstance(schema, dict | bool):
        raise SchemaError(
            f"cannot parse jsonschema schema for {name!r}: "
            f"expected a JSON object, got {type(schema).__name__}"
        )
    return schema
