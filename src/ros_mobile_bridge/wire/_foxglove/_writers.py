"""Writing what the client sends: the checks of the caller's arguments (they
raise ``TypeError`` / ``ValueError`` at once) and the encoders of the client
messages that need no engine state (part of
:mod:`ros_mobile_bridge.wire.foxglove`). The engine's client-side methods
keep the state and call these; their docstrings say what each message is."""

from __future__ import annotations

import base64
import json
from collections.abc import Iterable, Sequence

from ._events import Parameter
from ._protocol import (
    CLIENT_MESSAGE_HEADER,
    OP_CLIENT_MESSAGE_DATA,
    OP_PLAYBACK_CONTROL_REQUEST,
    OP_SERVICE_CALL_REQUEST,
    PLAYBACK_REQUEST_HEADER,
    SERVICE_REQUEST_HEADER,
    U32_MAX,
)

__all__ = [
    "check_id",
    "check_ids",
    "check_names",
    "check_payload",
    "check_str",
    "dumps",
    "encode_fetch_asset",
    "encode_get_parameters",
    "encode_message_data",
    "encode_parameter",
    "encode_playback_control",
    "encode_service_call_request",
    "encode_set_parameters",
    "encode_subscribe_connection_graph",
    "encode_subscribe_parameter_updates",
    "encode_unsubscribe_connection_graph",
    "encode_unsubscribe_parameter_updates",
    "float_arg",
    "is_number",
]


# --------------------------------------------------------------------------
# Argument checks for the client-side methods (raise at once).


def check_id(value: object, what: str, *, u32: bool = False) -> int:
    if type(value) is not int:
        raise TypeError(f"{what} must be an int, got {type(value).__name__}")
    if value < 0:
        raise ValueError(f"{what} must be non-negative, got {value}")
    if u32 and value > U32_MAX:
        raise ValueError(f"{what} must fit in 32 bits, got {value}")
    return value


def check_str(value: object, what: str, *, nonempty: bool = False) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{what} must be a str, got {type(value).__name__}")
    if nonempty and not value:
        raise ValueError(f"{what} must not be empty")
    return value


def check_ids(values: Iterable[int], what: str, *, u32: bool = False) -> list[int]:
    if isinstance(values, (str, bytes, bytearray, memoryview)) or not isinstance(values, Iterable):
        raise TypeError(f"{what} must be an iterable of ints, got {type(values).__name__}")
    ids = [check_id(v, f"each of {what}", u32=u32) for v in values]
    return list(dict.fromkeys(ids))  # de-duplicated, order kept


def check_names(names: Sequence[str], what: str) -> list[str]:
    if isinstance(names, (str, bytes, bytearray)) or not isinstance(names, Iterable):
        raise TypeError(f"{what} must be a sequence of str, got {type(names).__name__}")
    return [check_str(n, f"each of {what}") for n in names]


def check_payload(payload: object) -> None:
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise TypeError(f"payload must be bytes-like, got {type(payload).__name__}")


def is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def float_arg(value: object, what: str) -> float:
    if not is_number(value):
        raise TypeError(f"{what} must be a float, got {type(value).__name__}")
    try:
        return float(value)  # type: ignore[arg-type]
    except OverflowError:
        raise ValueError(f"{what} is out of float64 range") from None


def encode_parameter(param: Parameter) -> dict[str, object]:
    if not isinstance(param, Parameter):
        raise TypeError(f"parameters must be Parameter instances, got {type(param).__name__}")
    name = check_str(param.name, "Parameter.name")
    ptype = param.type
    if ptype is not None:
        check_str(ptype, "Parameter.type")
    value = param.value
    out: dict[str, object] = {"name": name}
    if value is None:  # unset the parameter
        return out
    if ptype is None:
        if isinstance(value, (bytes, bytearray, memoryview)):
            ptype = "byte_array"
        elif isinstance(value, float):
            ptype = "float64"
        elif (
            isinstance(value, (list, tuple))
            and any(isinstance(v, float) for v in value)
            and all(is_number(v) for v in value)
        ):
            ptype = "float64_array"
    if ptype == "byte_array":
        if not isinstance(value, (bytes, bytearray, memoryview)):
            raise TypeError(f"parameter {name!r}: a byte_array value must be bytes-like")
        out["value"] = base64.b64encode(value).decode("ascii")
    elif ptype == "float64":
        out["value"] = float_arg(value, f"parameter {name!r}")
    elif ptype == "float64_array":
        if not isinstance(value, (list, tuple)):
            raise TypeError(f"parameter {name!r}: a float64_array value must be a list")
        out["value"] = [float_arg(v, f"an entry of parameter {name!r}") for v in value]
    else:
        out["value"] = value
    if ptype is not None:
        out["type"] = ptype
    return out


def dumps(obj: object) -> str:
    """Compact JSON; NaN / infinity and unserialisable values raise ValueError / TypeError."""
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


# --------------------------------------------------------------------------
# Client messages that need no engine state


def encode_message_data(client_channel_id: int, payload: bytes | bytearray | memoryview) -> bytes:
    """A client message-data frame (see :meth:`FoxgloveEngine.message_data`)."""
    check_payload(payload)
    return b"".join(
        (CLIENT_MESSAGE_HEADER.pack(OP_CLIENT_MESSAGE_DATA, client_channel_id), payload)
    )


def encode_service_call_request(
    service_id: int, call_id: int, encoding: str, payload: bytes | bytearray | memoryview
) -> bytes:
    """A service-call-request frame (see :meth:`FoxgloveEngine.service_call_request`)."""
    check_id(service_id, "service_id", u32=True)
    check_id(call_id, "call_id", u32=True)
    enc = check_str(encoding, "encoding", nonempty=True).encode("utf-8")
    check_payload(payload)
    header = SERVICE_REQUEST_HEADER.pack(OP_SERVICE_CALL_REQUEST, service_id, call_id, len(enc))
    return b"".join((header, enc, payload))


def encode_get_parameters(names: Sequence[str], request_id: str | None = None) -> str:
    """``getParameters`` (see :meth:`FoxgloveEngine.get_parameters`)."""
    msg: dict[str, object] = {
        "op": "getParameters",
        "parameterNames": check_names(names, "names"),
    }
    if request_id is not None:
        msg["id"] = check_str(request_id, "request_id")
    return dumps(msg)


def encode_set_parameters(params: Sequence[Parameter], request_id: str | None = None) -> str:
    """``setParameters`` (see :meth:`FoxgloveEngine.set_parameters`)."""
    if isinstance(params, Parameter) or not isinstance(params, Iterable):
        raise TypeError("params must be a sequence of Parameter")
    msg: dict[str, object] = {
        "op": "setParameters",
        "parameters": [encode_parameter(p) for p in params],
    }
    if request_id is not None:
        msg["id"] = check_str(request_id, "request_id")
    return dumps(msg)


def encode_subscribe_parameter_updates(names: Sequence[str]) -> str:
    """``subscribeParameterUpdates``."""
    return dumps({"op": "subscribeParameterUpdates", "parameterNames": check_names(names, "names")})


def encode_unsubscribe_parameter_updates(names: Sequence[str]) -> str:
    """``unsubscribeParameterUpdates``."""
    return dumps(
        {"op": "unsubscribeParameterUpdates", "parameterNames": check_names(names, "names")}
    )


def encode_subscribe_connection_graph() -> str:
    """``subscribeConnectionGraph``."""
    return dumps({"op": "subscribeConnectionGraph"})


def encode_unsubscribe_connection_graph() -> str:
    """``unsubscribeConnectionGraph``."""
    return dumps({"op": "unsubscribeConnectionGraph"})


def encode_fetch_asset(uri: str, request_id: int) -> str:
    """``fetchAsset`` (see :meth:`FoxgloveEngine.fetch_asset`)."""
    check_str(uri, "uri", nonempty=True)
    check_id(request_id, "request_id", u32=True)
    return dumps({"op": "fetchAsset", "uri": uri, "requestId": request_id})


def encode_playback_control(
    play: bool, speed: float, seek_ns: int | None, request_id: str
) -> bytes:
    """A playback-control-request frame (see :meth:`FoxgloveEngine.playback_control`)."""
    if not isinstance(play, bool):
        raise TypeError(f"play must be a bool, got {type(play).__name__}")
    speed = float_arg(speed, "speed")
    if not (0.0 < speed < float("inf")):
        raise ValueError(f"speed must be a positive number, got {speed!r}")
    if seek_ns is not None and (type(seek_ns) is not int or not 0 <= seek_ns < 1 << 64):
        raise ValueError(f"seek_ns must be None or an int in 0 ..< 2**64, got {seek_ns!r}")
    rid = check_str(request_id, "request_id", nonempty=True).encode("utf-8")
    header = PLAYBACK_REQUEST_HEADER.pack(
        OP_PLAYBACK_CONTROL_REQUEST,
        0 if play else 1,
        speed,
        seek_ns is not None,
        seek_ns or 0,
        len(rid),
    )
    return header + rid
