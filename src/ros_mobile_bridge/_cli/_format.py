"""What ``rmb`` reads and prints: YAML input (like ``ros2``), messages as
``ros2``'s YAML documents or one JSON object per line, field selection.

PyYAML is imported here, lazily (this module is loaded by the command line
only, never by ``import ros_mobile_bridge``)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

from ..interfaces._base import RosMessage

__all__ = [
    "UsageError",
    "check_fields",
    "csv_line",
    "dump_flow",
    "dump_yaml",
    "finite_or_none",
    "json_line",
    "parse_yaml_mapping",
    "parse_yaml_value",
    "plain",
    "select_field",
]


class UsageError(Exception):
    """A mistake in what the user typed: ``rmb`` prints it on one line and
    exits 2 (runtime failures exit 1)."""


_ELLIPSIS = "..."


def plain(
    value: Any, *, truncate: int | None = None, no_arr: bool = False, no_str: bool = False
) -> Any:
    """A copy of a decoded message built from dicts, lists, str, bytes-free
    numbers and bools (numpy arrays and scalars, bytes and memoryviews become
    lists / Python numbers). Floats stay floats, NaN and infinities included.

    ``truncate``: arrays and strings longer than that keep their first
    ``truncate`` items and end with ``'...'`` (as ``ros2 topic echo``'s
    ``--truncate-length``). ``no_arr`` / ``no_str``: array / string fields
    become a ``'<array: N items>'`` / ``'<string: N chars>'`` placeholder.
    A message instance is taken as its dict (``to_dict()``)."""
    if isinstance(value, RosMessage):
        value = value.to_dict()
    if isinstance(value, Mapping):
        return {
            str(k): plain(v, truncate=truncate, no_arr=no_arr, no_str=no_str)
            for k, v in value.items()
        }
    if isinstance(value, str):
        if no_str:
            return f"<string: {len(value)} chars>"
        if truncate is not None and len(value) > truncate:
            return value[:truncate] + _ELLIPSIS
        return value
    is_numpy = getattr(value, "ndim", 0) > 0 and callable(getattr(value, "tolist", None))
    if isinstance(value, list | tuple | bytes | bytearray | memoryview) or is_numpy:
        length = len(value)
        if no_arr:
            return f"<array: {length} items>"
        cut = truncate is not None and length > truncate
        part = value[:truncate] if cut else value  # cut first: an image is large
        if isinstance(part, bytes | bytearray | memoryview):
            items: list[Any] = list(bytes(part))
        elif is_numpy:
            items = part.tolist()
        else:
            items = list(part)
        out = [plain(v, truncate=truncate, no_str=no_str) for v in items]
        if cut:
            out.append(_ELLIPSIS)
        return out
    if not isinstance(value, bool | int | float) and callable(getattr(value, "tolist", None)):
        return value.tolist()  # a numpy scalar
    return value


def finite_or_none(value: Any) -> Any:
    """``value`` (made by :func:`plain`) with NaN and the infinities, which
    JSON cannot spell, replaced by ``None``."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list):
        return [finite_or_none(v) for v in value]
    return value


def json_line(record: Mapping[str, Any]) -> str:
    """``record`` (made by :func:`plain`) as one line of strict JSON: NaN and
    the infinities, which JSON cannot spell, become ``null``."""
    return json.dumps(finite_or_none(record), separators=(", ", ": "), allow_nan=False)


def _yaml() -> Any:
    """PyYAML, imported on first use (through importlib: it ships no type
    hints, so everything from it is ``Any`` here)."""
    import importlib

    return importlib.import_module("yaml")


def _dumper() -> Any:
    yaml = _yaml()
    return getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def dump_yaml(value: Any) -> str:
    """``value`` (made by :func:`plain`) in block-style YAML, keys in message
    order, as ``ros2 topic echo`` prints it (``.nan``, ``.inf`` for the
    non-finite floats). Ends with a newline; no document markers."""
    yaml = _yaml()
    text: str = yaml.dump(
        value, Dumper=_dumper(), default_flow_style=False, sort_keys=False, allow_unicode=True
    )
    if text.endswith("\n...\n"):  # a bare scalar ends its document explicitly
        text = text[: -len("...\n")]
    return text


def dump_flow(value: Any) -> str:
    """``value`` in one line of flow-style YAML (``{linear: {x: 0.1}}``)."""
    yaml = _yaml()
    text: str = yaml.dump(
        value, Dumper=_dumper(), default_flow_style=True, sort_keys=False, width=1 << 30
    )
    return text.strip().removesuffix("...").strip()


def _yaml_problem(exc: Exception) -> str:
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    mark = getattr(exc, "problem_mark", None)
    where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
    return f"{problem}{where}"


def parse_yaml_value(text: str, what: str) -> Any:
    """``text`` read as YAML (``yaml.safe_load``; so JSON too); a
    :class:`UsageError` naming ``what`` when it does not parse."""
    yaml = _yaml()
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise UsageError(f"{what} is not valid YAML: {_yaml_problem(exc)}") from None


def parse_yaml_mapping(text: str, what: str) -> dict[str, Any]:
    """``text`` read as a YAML mapping (``'{linear: {x: 0.1}}'``, or JSON);
    empty text is ``{}``. A :class:`UsageError` otherwise."""
    value = parse_yaml_value(text, what) if text.strip() else {}
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise UsageError(
            f"{what} must be a YAML mapping such as '{{linear: {{x: 0.1}}}}', "
            f"got {type(value).__name__} {text!r}"
        )
    return {str(k): v for k, v in value.items()}


def select_field(value: Any, path: str) -> Any:
    """The part of a message ``path`` names (``pose.pose.position.x``;
    a number indexes an array). :class:`UsageError` when it names nothing."""
    current = value.to_dict() if isinstance(value, RosMessage) else value
    for part in path.split("."):
        if not isinstance(current, Mapping | list | tuple) and callable(
            getattr(current, "tolist", None)
        ):
            current = current.tolist()  # a numpy array
        if isinstance(current, Mapping) and part in current:
            current = current[part]
        elif isinstance(current, list | tuple) and part.lstrip("-").isdigit():
            try:
                current = current[int(part)]
            except IndexError:
                raise UsageError(f"--field {path}: index {part} is out of range") from None
        else:
            known = ", ".join(map(str, current)) if isinstance(current, Mapping) else ""
            hint = f" (fields there: {known})" if known else ""
            raise UsageError(f"--field {path}: the message has no field {part!r}{hint}")
    return current


def check_fields(
    robot: Any, typename: str, data: Mapping[str, Any], call: str, *, _top: str = "", _at: str = ""
) -> None:
    """Refuse a key of ``data`` that type ``typename`` has no field for,
    before anything is sent: the library's :class:`MessageError` (the same
    class and words ``publish``, ``call_service`` and ``send_action_goal``
    raise), naming ``call`` (``"publish /cmd_vel"``), the dotted field and
    the known ones. Types whose definition this client does not know are not
    checked here (the server or the encoder refuses then)."""
    from .._errors import MessageError, RosBridgeError

    try:
        fields = robot.schema_definition(typename)
    except (RosBridgeError, ValueError, TypeError):
        return
    top = _top or typename
    by_name = {f.name: f for f in fields}
    for key, item in data.items():
        spec = by_name.get(key)
        path = f"{_at}.{key}" if _at else str(key)
        if spec is None:
            known = ", ".join(by_name) or "none"
            raise MessageError(top, f"unknown field (its fields: {known})", path, call)
        if "/" not in spec.type:
            continue
        if isinstance(item, Mapping) and not spec.array:
            check_fields(robot, spec.type, item, call, _top=top, _at=path)
        elif isinstance(item, list) and spec.array:
            for i, element in enumerate(item):
                if isinstance(element, Mapping):
                    check_fields(robot, spec.type, element, call, _top=top, _at=f"{path}[{i}]")


def csv_line(value: Any) -> str:
    """``value`` (made by :func:`plain`) as ``ros2 topic echo --csv`` prints a
    message: every leaf in field order, depth first, array items in order,
    joined by commas (no quoting; an empty array adds nothing between its
    commas); numbers and booleans as Python spells them, strings as they
    are."""
    if isinstance(value, Mapping):
        return ",".join(csv_line(v) for v in value.values())
    if isinstance(value, list):
        return ",".join(csv_line(v) for v in value)
    return str(value)
