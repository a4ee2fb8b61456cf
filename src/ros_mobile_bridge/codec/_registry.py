"""The per-connection schema registry and codec factory."""

from __future__ import annotations

import functools
import json
import re
import threading
from collections.abc import Callable, Hashable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Final, cast

import numpy as np
from rosbags.typesys.store import Typestore

from .._errors import DecodeError, MessageError, SchemaError
from ..interfaces._base import RosMessage
from ._bundled import bundled_definition, bundled_interface
from ._cdr import build_class_decoder
from ._cdr_encode import build_class_encoder
from ._classes import class_for, known_generation
from ._convert import Builder, Converter, Invalid, build_builder, build_converter
from ._dict_classes import build_dict_converter
from ._flat import build_flat_decoder
from ._lru import LruCache
from ._model import DescribedTypes, FieldDef, MsgDef
from ._names import (
    canonical_name,
    is_valid_type_name,
    lookup_candidates,
    same_type_name,
    service_type_names,
    split_type_name,
)
from ._parse import action_texts, parse_jsonschema, parse_ros2idl, parse_ros2msg
from ._templates import json_definition, json_template, ros_template
from ._wellknown import builtin_definitions
from ._workspace import InterfacePaths

__all__ = ["CodecRegistry", "SchemaTooLarge"]

Decoder = Callable[[memoryview], Any]
Encoder = Callable[[Mapping[str, Any] | RosMessage], bytes]


@dataclass(frozen=True, slots=True)
class _JsonSchema:
    schema: dict[str, Any] | bool


@dataclass(slots=True)
class _Generation:
    """One rosbags typestore and everything built on it. A typestore cannot
    hold two definitions of one name, so when a type is redefined the registry
    starts a new generation; codecs made earlier keep theirs alive."""

    store: Typestore = field(default_factory=Typestore)
    defs: dict[str, MsgDef] = field(default_factory=dict)
    converters: dict[str, Converter] = field(default_factory=dict)
    builders: dict[str, Builder] = field(default_factory=dict)
    decoders: dict[str, Decoder] = field(default_factory=dict)
    encoders: dict[str, Encoder] = field(default_factory=dict)


_PARSED = ("ros2msg", "ros2idl", "ros2action", "jsonschema")

SHARED_CODECS_MAX: Final = 512
"""How many built CDR codecs the process keeps for reuse by any registry."""


class _SharedCodecs(LruCache[Hashable, object]):
    """Built CDR codecs shared by every registry in the process, keyed by the
    type and the exact definitions of it and everything it uses: a thousand
    connections that see the same ``std_msgs/String`` build its decoder once
    (rosbags generates and compiles code per typestore, about 40 KB and a
    millisecond a type). A codec is a pure function of those definitions, so
    sharing it is safe; a redefined type is another key. Bounded at
    :data:`SHARED_CODECS_MAX` entries, least recently used first out
    (``evicted`` counts them; a registry keeps the codecs it built itself
    either way). Thread-safe."""

    def __init__(self, max_entries: int = SHARED_CODECS_MAX) -> None:
        super().__init__(max_entries)


_SHARED = _SharedCodecs()


class SchemaTooLarge(SchemaError):
    """A schema over the registry's ``max_schema_size`` or
    ``max_schema_fields``: refused before its codecs are built."""


def _encoding(message_encoding: str) -> str:
    if not isinstance(message_encoding, str):
        raise TypeError(f"message_encoding must be a str, not {type(message_encoding).__name__}")
    return message_encoding.strip().lower()


def _json_decode(payload: memoryview | bytes | str) -> Any:
    """``json.loads`` of a UTF-8 payload; raises :class:`DecodeError` only."""
    try:
        text = payload if isinstance(payload, str) else str(payload, "utf-8")
        return json.loads(text)
    except Exception as exc:
        raise DecodeError(f"invalid JSON payload: {exc}") from exc


def _json_default(value: Any) -> Any:
    if isinstance(value, RosMessage):
        return value.to_dict()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bytes | bytearray | memoryview):
        return list(bytes(value))
    if isinstance(value, set | frozenset):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _dumps(value: Any) -> bytes:
    return json.dumps(value, separators=(",", ":"), default=_json_default).encode()


def _merge(template: Any, data: Any, strict: bool, path: str) -> Any:
    """``data`` laid over ``template`` (dicts merged recursively, anything else
    replaced). With ``strict`` (a ROS definition) keys the template lacks and
    non-mappings in place of a message raise :class:`Invalid`."""
    if not isinstance(template, dict):
        return data
    if isinstance(data, RosMessage):
        data = data.to_dict()
    if not isinstance(data, Mapping):
        if strict:
            raise Invalid(f"expected a mapping, got {type(data).__name__}", path)
        return data
    out = dict(template)
    for key, value in data.items():
        where = f"{path}.{key}" if path else str(key)
        if key in template:
            out[key] = _merge(template[key], value, strict, where)
        elif strict:
            known = ", ".join(template) or "none"
            raise Invalid(f"unknown field (known fields: {known})", where)
        else:
            out[key] = value
    return out


def _misfit(typename: str, exc: Invalid) -> MessageError:
    """The caller's value does not fit ``typename``: one error class for it."""
    return MessageError(typename, exc.reason, exc.path or None)


def _make_cdr_decoder(typename: str, store: Typestore, conv: Converter) -> Decoder:
    msgdef = store.get_msgdef(typename)
    little = msgdef.deserialize_cdr_le
    big = msgdef.deserialize_cdr_be
    cls = msgdef.cls

    def decode(payload: memoryview) -> Any:
        """Decode one CDR payload (4-byte encapsulation header + body) into a
        dict. Raises :class:`DecodeError` and nothing else."""
        size = -1
        try:
            view = payload if type(payload) is memoryview else memoryview(payload)
            if view.format != "B" or view.ndim != 1:
                view = view.cast("B")
            size = len(view)
            if size < 4 or view[0] != 0:
                raise DecodeError(
                    f"cannot decode {typename}: not a CDR payload "
                    f"({size} bytes, encapsulation {bytes(view[:2]).hex() or 'missing'})"
                )
            kind = view[1]
            if kind == 1:
                message, pos = little(view[4:], 0, cls, store)
            elif kind == 0:
                message, pos = big(view[4:], 0, cls, store)
            else:
                raise DecodeError(
                    f"cannot decode {typename}: unsupported CDR encapsulation 0x{kind:04x} "
                    "(only plain CDR / XCDR1 is supported)"
                )
            if pos + 7 < size:
                raise DecodeError(
                    f"cannot decode {typename}: {size - 4 - pos} bytes left over after the "
                    "message (wrong type or definition?)"
                )
            return conv(message)
        except DecodeError:
            raise
        except Exception as exc:
            raise DecodeError(
                f"cannot decode {typename} from {size} bytes: {type(exc).__name__}: {exc}"
            ) from exc

    return decode


_SCRATCH_MIN = 1 << 16
_SCRATCH_MAX = 1 << 26


def _make_cdr_encoder(typename: str, store: Typestore, build: Builder) -> Encoder:
    msgdef = store.get_msgdef(typename)
    getsize = msgdef.getsize_cdr
    serialize = msgdef.serialize_cdr_le
    # Large messages are serialised into a reused, zeroed scratch buffer and
    # copied out once: a fresh bytearray per call plus the final bytes() copy
    # costs ~1 ms for a 900 kB image (page faults), the scratch path ~50 us.
    scratch_lock = threading.Lock()
    scratch: list[np.ndarray[Any, np.dtype[np.uint8]]] = [np.zeros(0, np.uint8)]

    def encode(data: Mapping[str, Any] | RosMessage) -> bytes:
        """Encode a message instance or a (partial) mapping as little-endian
        CDR with the 4-byte encapsulation header. Raises
        :class:`MessageError` naming the field for an unknown field or a
        value of the wrong type."""
        try:
            message = build(data)
        except Invalid as exc:
            raise _misfit(typename, exc) from None
        try:
            size = getsize(0, message, store)
            total = size + 4
            if _SCRATCH_MIN <= total <= _SCRATCH_MAX and scratch_lock.acquire(blocking=False):
                try:
                    if scratch[0].size < total:
                        scratch[0] = np.zeros(total, np.uint8)
                    else:
                        scratch[0][:total] = 0  # CDR padding must not leak old bytes
                    view = scratch[0].data[:total]
                    view[1] = 1
                    end = serialize(view[4:], 0, message, store)
                    out = bytes(view)
                finally:
                    scratch_lock.release()
            else:
                buffer = bytearray(total)
                buffer[1] = 1
                end = serialize(memoryview(buffer)[4:], 0, message, store)
                out = bytes(buffer)
        except Exception as exc:
            raise MessageError(typename, f"{type(exc).__name__}: {exc}") from exc
        if end != size:
            raise MessageError(typename, f"size mismatch ({end} != {size})")
        return out

    return encode


_MSG_SEPARATOR_LINE: Final = "=" * 80 + "\n"
_MSG_SEPARATOR: Final = re.compile(r"^={80}\n", re.MULTILINE)


def _with_class_encoder(
    key: str,
    closure: Mapping[str, MsgDef],
    classes: Callable[[str], type[RosMessage]],
    general: Encoder,
) -> Encoder:
    """``general`` (a mapping, or any instance, via its dict), with an
    instance of the type's own class encoded by the generated class
    encoder: no dict, no builder, the same bytes. A type the class encoder
    does not cover keeps ``general`` alone."""
    try:
        cls = classes(key)
        direct = build_class_encoder(key, closure, classes)
    except SchemaError:
        return general

    def encode(data: Mapping[str, Any] | RosMessage) -> bytes:
        if data.__class__ is cls:
            return direct(data)
        return general(data)

    return encode


def _builtin(name: str) -> MsgDef | None:
    """rosbags' Jazzy definition of ``name`` (the last fallback: message
    packages the bundle does not hold), read on first use."""
    return builtin_definitions().get(name)


def _unsupported(message_encoding: str, schema_name: str) -> SchemaError:
    return SchemaError(
        f"unsupported message encoding {message_encoding!r} for {schema_name!r} "
        "(supported: cdr, json)"
    )


class CodecRegistry:
    """Per-connection schema registry and codec factory.

    Holds the schemas one server advertised (:meth:`add_schema`) and makes
    decoders and encoders for them (:meth:`decoder`, :meth:`encoder`). Type
    names are looked up tolerantly (``std_msgs/String`` finds
    ``std_msgs/msg/String``, see :func:`~ros_mobile_bridge.codec.same_type_name`).
    A name the server did not register falls back, in this order, to the
    local interface files of ``interfaces`` (a colcon workspace, a ROS
    installation: see :class:`InterfacePaths`), to the interfaces bundled
    with the package (every message, service and action of the standard ROS 2
    Jazzy packages, with the types ROS derives from services and actions:
    ``pkg/srv/X_Request``, ``pkg/action/X_SendGoal_Request``, ...), and last
    to rosbags' own Jazzy message definitions. Server definitions win over
    local ones, local ones over bundled ones; a schema's own type wins over
    a dependency definition embedded in another schema.

    Each registry has its own rosbags typestore (nothing global is mutated).
    The registry is thread-safe; the decoders and encoders it returns are
    plain functions that may be called from any thread.
    """

    def __init__(
        self,
        *,
        max_schema_size: int | None = None,
        max_schema_fields: int | None = None,
        interfaces: InterfacePaths | None = None,
    ) -> None:
        self.max_schema_size = max_schema_size
        """Characters of one schema text :meth:`add_schema` accepts (None: any)."""
        self.max_schema_fields = max_schema_fields
        """Fields one schema may define, over all its definitions (None: any)."""
        self._lock = threading.RLock()
        self._own: dict[str, MsgDef | _JsonSchema] = {}
        self._deps: dict[str, MsgDef] = {}
        self._no_schema: set[str] = set()
        self._described: dict[str, MsgDef] = {}
        self._sources: dict[str, str] = {}
        self._gen: _Generation | None = None
        self.interfaces = interfaces
        """The local interface files this registry falls back to (None: none)."""
        local = interfaces.definition if interfaces is not None else None
        self._layers: tuple[Callable[[str], MsgDef | _JsonSchema | None], ...] = (
            self._described.get,
            self._own.get,
            self._deps.get,
            *((local,) if local is not None else ()),
            bundled_definition,
            _builtin,
        )

    # ------------------------------------------------------------------ schemas

    def add_schema(self, name: str, schema_encoding: str, data: str | bytes) -> None:
        """Register the schema the server sent for type ``name``.

        ``schema_encoding`` is ``"ros2msg"`` (``.msg`` text, optionally with
        its dependencies appended in the concatenated ``=====``/``MSG:
        pkg/Type`` form; a service's ``X_Request``/``X_Response`` arrive as
        ``.msg`` texts under ``pkg/srv/X_Request`` names), ``"ros2idl"`` (IDL
        text, optionally several blocks each introduced by the ``=====`` line
        and ``IDL: pkg/msg/Type``), ``"ros2action"`` (an ``.action`` text
        for ``pkg/action/X``: registers the types ROS derives from it, see
        :func:`action_texts`) or ``"jsonschema"``. ``""`` or any other
        encoding records the name as having no schema, which changes nothing
        else (built-in and earlier definitions stay usable).

        Raises :class:`SchemaError` (naming the type, with the parser's
        message) when the text does not parse, and ``ValueError`` for an empty
        name. Registering a name again with a different definition replaces
        it for codecs created afterwards; codecs created earlier keep the
        definition they captured.
        """
        key = canonical_name(name)
        encoding = schema_encoding.strip().lower() if isinstance(schema_encoding, str) else ""
        limit = self.max_schema_size
        if limit is not None and encoding in _PARSED and len(data) > limit:
            raise SchemaTooLarge(
                f"the schema of {name!r} is {len(data)} characters long, over "
                f"max_schema_size={limit}"
            )
        if encoding == "ros2action":
            for derived, text in action_texts(name, data).items():
                self.add_schema(derived, "ros2msg", text)
            return
        if encoding == "ros2msg":
            mains, defs = parse_ros2msg(name, data)
        elif encoding == "ros2idl":
            mains, defs = parse_ros2idl(name, data)
        elif encoding == "jsonschema":
            schema = parse_jsonschema(name, data)
            with self._lock:
                self._own[key] = _JsonSchema(schema)
            return
        else:
            with self._lock:
                self._no_schema.add(key)
            return
        fields = sum(len(d.fields) for d in defs.values())
        if self.max_schema_fields is not None and fields > self.max_schema_fields:
            raise SchemaTooLarge(
                f"the schema of {name!r} defines {fields} fields in {len(defs)} types, over "
                f"max_schema_fields={self.max_schema_fields}"
            )
        with self._lock:
            for type_name, msgdef in defs.items():
                if type_name in mains:
                    self._own[type_name] = msgdef
                else:
                    self._deps[type_name] = msgdef

    def add_description(self, described: DescribedTypes) -> None:
        """Register the definitions a REP-2011 type description gave (see
        :func:`~ros_mobile_bridge.codec.describe`): the robot's own, checked
        against the type's hash, so for this registry they win over every
        other definition of the same names (bundled, registered, or a
        server's schema). Their ``.msg`` texts, when the description carried
        them, become :meth:`ros2msg_text`'s. :class:`SchemaTooLarge` over
        ``max_schema_fields``."""
        fields = sum(len(d.fields) for d in described.defs.values())
        if self.max_schema_fields is not None and fields > self.max_schema_fields:
            raise SchemaTooLarge(
                f"the description of {described.type_name!r} defines {fields} fields in "
                f"{len(described.defs)} types, over max_schema_fields={self.max_schema_fields}"
            )
        with self._lock:
            self._described.update(described.defs)
            for name in described.defs:
                self._sources.pop(name, None)
            self._sources.update(described.sources)

    def has_schema(self, name: str) -> bool:
        """Whether a definition of ``name`` is available: registered by the
        server (``ros2msg``, ``ros2idl`` or ``jsonschema``) or built in. A name
        registered without a schema does not count."""
        try:
            with self._lock:
                return self._find(name, ros_only=False) is not None
        except (TypeError, ValueError):
            return False

    def resolves(self, name: str) -> bool:
        """Like :meth:`has_schema`, but an explicit kind segment must match
        (``pkg/srv/Twist`` does not find ``pkg/msg/Twist``): whether a
        publish of type ``name`` has a definition to go by."""
        try:
            with self._lock:
                found = self._find(name, ros_only=False)
        except (TypeError, ValueError):
            return False
        return found is not None and same_type_name(found[0], name)

    @contextmanager
    def ros_lookup(self) -> Iterator[Callable[[str], tuple[str, MsgDef | _JsonSchema] | None]]:
        """Internal, for :func:`~ros_mobile_bridge.codec.type_hash`: holds the
        registry's lock for the block, which gets the function that finds a
        ROS definition by name (``(the name found, its definition)`` or
        ``None``; server schemas, then built-in ones, looked up tolerantly),
        so that every lookup in the block sees the same definitions."""
        with self._lock:
            yield functools.partial(self._find, ros_only=True)

    def _find(self, name: str, *, ros_only: bool) -> tuple[str, MsgDef | _JsonSchema] | None:
        for candidate in lookup_candidates(name):
            for layer in self._layers:
                entry = layer(candidate)
                if entry is None or (ros_only and isinstance(entry, _JsonSchema)):
                    continue
                return candidate, entry
        return None

    def _find_ros(self, name: str) -> tuple[str, MsgDef]:
        found = self._find(name, ros_only=True)
        if found is None:
            raise SchemaError(
                f"unknown type {name!r}: the server sent no ros2msg/ros2idl schema for it "
                "and it is not built in"
            )
        key, entry = found
        assert isinstance(entry, MsgDef)
        return key, entry

    def _resolve_ref(self, name: str) -> MsgDef | None:
        found = self._find(name, ros_only=True)
        if found is None:
            return None
        entry = found[1]
        return entry if isinstance(entry, MsgDef) else None

    def _closure(self, key: str, msgdef: MsgDef) -> dict[str, MsgDef]:
        closure = {key: msgdef}
        stack = [msgdef]
        while stack:
            current = stack.pop()
            for ref in current.refs():
                if ref in closure:
                    continue
                sub = self._resolve_ref(ref)
                if sub is None:
                    raise SchemaError(
                        f"type {key!r} needs {ref!r} (used by {current.name!r}), which has no "
                        "definition (not sent by the server and not built in)"
                    )
                closure[ref] = sub
                stack.append(sub)
        return closure

    def _prepare(self, key: str, msgdef: MsgDef) -> _Generation:
        """Make sure ``key`` and everything it uses is registered, with the
        current definitions, in the current typestore (starting a new one if a
        definition changed) and return that generation."""
        closure = self._closure(key, msgdef)
        gen = self._gen
        if gen is not None and any(
            (have := gen.defs.get(k)) is not None and have != d for k, d in closure.items()
        ):
            gen = None
        if gen is None:
            gen = _Generation()
            self._gen = gen
        new = {k: d for k, d in closure.items() if k not in gen.defs}
        if new:
            for type_name in new:
                if not is_valid_type_name(type_name):
                    raise SchemaError(f"invalid type name {type_name!r}")
            try:
                gen.store.register({k: d.rosbags_entry() for k, d in new.items()})
                for type_name in new:
                    gen.store.get_msgdef(type_name)
            except Exception as exc:
                # The store may now hold part of the batch: start afresh next time.
                self._gen = None
                raise SchemaError(f"cannot build a codec for {key!r}: {exc}") from exc
            gen.defs.update(new)
        return gen

    # ------------------------------------------------------------------ codecs

    def decoder(self, schema_name: str, message_encoding: str) -> Callable[[memoryview], Any]:
        """A function decoding one payload of type ``schema_name``.

        When the registry knows the type's ROS definition, a payload becomes
        an instance of the type's message class (:meth:`message_class`):
        nested messages are instances, arrays of messages lists of them,
        arrays of numeric primitives numpy arrays (read-only views into the
        payload when it is little-endian CDR - copy them to keep them beyond
        the payload buffer's lifetime), ``string[]`` lists of ``str``,
        ``byte`` values 0..255; ``.to_dict()`` gives the dict form.
        ``"cdr"`` needs that definition. ``"json"``: ``json.loads`` of the
        UTF-8 payload, made an instance of the class when the registry has a
        ROS definition of ``schema_name`` (every field must be present), a
        plain dict otherwise (a JSON Schema, an unknown type).

        The returned function raises :class:`DecodeError` (and nothing else)
        for a payload that does not decode. ``decoder`` itself raises
        :class:`SchemaError` for a type without a definition (cdr) or an
        unsupported encoding. The decoder keeps the definitions current at
        creation time, whatever is registered later.
        """
        encoding = _encoding(message_encoding)
        if encoding == "json":
            from_dict = self.dict_converter(schema_name)
            if from_dict is None:
                return _json_decode
            return lambda payload: from_dict(_json_decode(payload))
        if encoding != "cdr":
            raise _unsupported(message_encoding, schema_name)
        with self._lock:
            key, msgdef = self._find_ros(schema_name)
            closure = self._closure(key, msgdef)
            shared_key = ("decode", key, frozenset(closure.items()), known_generation())
            shared = _SHARED.get(shared_key)
            if shared is not None:
                return cast(Decoder, shared)
            for type_name in closure:
                if not is_valid_type_name(type_name):
                    raise SchemaError(f"invalid type name {type_name!r}")
            try:
                decode: Decoder = build_class_decoder(key, closure, self._classes(closure))
            except SchemaError as exc:
                raise SchemaError(f"cannot build a decoder for {key!r}: {exc}") from exc
            _SHARED.put(shared_key, decode)
            return decode

    def dict_decoder(self, schema_name: str) -> Callable[[memoryview], dict[str, Any]]:
        """A function decoding one CDR payload of type ``schema_name`` into
        a plain dict (what :meth:`RosMessage.to_dict` gives of the instance
        :meth:`decoder`'s function makes), for code that reads fields by
        name. Raises as :meth:`decoder` does."""
        with self._lock:
            key, msgdef = self._find_ros(schema_name)
            return self._dict_decoder(key, msgdef)

    def _dict_decoder(self, key: str, msgdef: MsgDef) -> Decoder:
        shared_key = ("decode-dict", key, frozenset(self._closure(key, msgdef).items()))
        shared = _SHARED.get(shared_key)
        if shared is not None:
            return cast(Decoder, shared)
        gen = self._prepare(key, msgdef)
        decode = gen.decoders.get(key)
        if decode is None:
            conv = build_converter(key, gen.defs, gen.converters)
            decode = _make_cdr_decoder(key, gen.store, conv)
            decode = build_flat_decoder(key, gen.defs, decode) or decode
            gen.decoders[key] = decode
        _SHARED.put(shared_key, decode)
        return decode

    def dict_converter(self, schema_name: str) -> Callable[[Any], Any] | None:
        """A function turning a decoded mapping of type ``schema_name`` (a
        JSON bridge's message: nested dicts and lists, ``uint8[]`` as a list
        or base64 text) into an instance of its class; None when the registry
        has no ROS definition of it (a JSON Schema, an unknown type), whose
        messages stay dicts. The function raises :class:`DecodeError`
        naming the field that does not fit."""
        with self._lock:
            try:
                found = self._find(schema_name, ros_only=False)
            except (TypeError, ValueError):
                return None
            if found is None or isinstance(found[1], _JsonSchema):
                return None
            key, msgdef = found[0], found[1]
            closure = self._closure(key, msgdef)
            shared_key = ("from-dict", key, frozenset(closure.items()), known_generation())
            shared = _SHARED.get(shared_key)
            if shared is None:
                shared = build_dict_converter(key, closure, self._classes(closure))
                _SHARED.put(shared_key, shared)
            return cast(Callable[[Any], Any], shared)

    def message_class(self, schema_name: str) -> type[RosMessage]:
        """The message class of ``schema_name`` as this registry defines it:
        the bundled class (``ros_mobile_bridge.interfaces...``) when the
        definitions are the bundled ones, else a class made from the
        definitions this registry holds (the server's, the robot's, a
        workspace's, a registered one), one per distinct definition in the
        process. :class:`SchemaError` when it has no ROS definition."""
        with self._lock:
            key, msgdef = self._find_ros(schema_name)
            closure = self._closure(key, msgdef)
        return class_for(key, closure)

    def _classes(self, closure: Mapping[str, MsgDef]) -> Callable[[str], type[RosMessage]]:
        """The class of each type of ``closure`` (a closure itself)."""

        def classes(name: str) -> type[RosMessage]:
            return class_for(name, closure)  # (it takes the part ``name`` uses)

        return classes

    def ros2msg_text(self, schema_name: str) -> str:
        """The ``.msg`` text of ``schema_name`` with the definition of every
        type it uses appended in the concatenated form (an ``=`` * 80 line,
        then ``MSG: pkg/Type`` and its text): what an MCAP file's ``ros2msg``
        schema and rosbag2 carry. Each message that comes from an interface
        file (bundled or local) is that file's text, comments and defaults
        included; any other (a server's schema, a type derived from a service
        or an action) is generated from the definition this registry decodes
        and encodes with. When a type description from the robot carried the
        ``.msg`` texts of the type and of everything it uses
        (:meth:`add_description`), those texts. :class:`SchemaError` when it
        has none."""
        with self._lock:
            key, msgdef = self._find_ros(schema_name)
            closure = self._closure(key, msgdef)
            if all(name in self._sources for name in closure):
                return self._described_text(key, closure)
            gen = self._prepare(key, msgdef)
            text, _digest = gen.store.generate_msgdef(key, ros_version=2)
            blocks = _MSG_SEPARATOR.split(text)
            out = [self._source_text(key, gen.defs[key]) or blocks[0]]
            for block in blocks[1:]:
                header, _, body = block.partition("\n")
                name = header.removeprefix("MSG: ").strip()
                try:
                    dep = canonical_name(name)
                except (TypeError, ValueError):
                    dep = name
                source = self._source_text(dep, gen.defs.get(dep))
                out.append(f"{header}\n{source or body}")
        return _MSG_SEPARATOR_LINE.join(out)

    def _source_text(self, key: str, msgdef: MsgDef | None) -> str | None:
        """The interface file text of the message ``key`` when ``msgdef`` is
        the definition that file gives (local files first), else None."""
        if msgdef is None or split_type_name(key)[1] != "msg":
            return None
        text: str | None = None
        local = self.interfaces
        if local is not None and local.definition(key) == msgdef:
            text = local.text(key)
        elif bundled_definition(key) == msgdef:
            found = bundled_interface(key)
            text = found.text if found is not None and found.name == key else None
        if text is None:
            return None
        return text if text.endswith("\n") else text + "\n"

    def _described_text(self, key: str, closure: Mapping[str, MsgDef]) -> str:
        """The concatenated ``.msg`` form of the source texts a type
        description carried (comments and constants kept)."""
        parts = [self._sources[key].rstrip("\n") + "\n"]
        for name in sorted(closure):
            if name != key:
                pkg, _kind, typ = name.split("/")
                text = self._sources[name].rstrip("\n")
                parts.append(f"{'=' * 80}\nMSG: {pkg}/{typ}\n{text}\n")
        return "".join(parts)

    def jsonschema(self, schema_name: str) -> dict[str, Any] | bool | None:
        """The JSON schema registered for ``schema_name`` (a channel with
        ``jsonschema`` encoding), or None."""
        with self._lock:
            entry = self._own.get(canonical_name(schema_name))
        return entry.schema if isinstance(entry, _JsonSchema) else None

    def encoder(
        self, schema_name: str, message_encoding: str
    ) -> Callable[[Mapping[str, Any] | RosMessage], bytes]:
        """A function encoding one message of type ``schema_name``: an
        instance of a message class (the type's, or any with the same
        fields), or a mapping.

        ``"cdr"``: a (partial) mapping -> little-endian CDR bytes with the
        4-byte header. Missing fields are filled from the template (so
        ``{"linear": {"x": 0.2}}`` is a whole ``Twist``); numeric arrays
        accept numpy arrays, lists and tuples, and ``bytes`` for 8-bit integer
        arrays (``uint8[]``). ``"json"``: compact ``json.dumps`` of the data
        laid over the template when the schema is known (as given otherwise),
        numpy arrays and ``bytes`` becoming lists.

        The returned function raises :class:`MessageError` (a ``DecodeError``) naming the field for
        an unknown field or a value of the wrong type or range. ``encoder``
        itself raises :class:`SchemaError` for a type without a definition
        (cdr) or an unsupported encoding.
        """
        encoding = _encoding(message_encoding)
        if encoding == "json":
            return self._json_encoder(schema_name)
        if encoding != "cdr":
            raise _unsupported(message_encoding, schema_name)
        with self._lock:
            key, msgdef = self._find_ros(schema_name)
            closure = self._closure(key, msgdef)
            shared_key = ("encode", key, frozenset(closure.items()), known_generation())
            shared = _SHARED.get(shared_key)
            if shared is not None:
                return cast(Encoder, shared)
            gen = self._prepare(key, msgdef)
            encode = gen.encoders.get(key)
            if encode is None:
                build = build_builder(key, gen.defs, gen.store.types, gen.builders)
                encode = _with_class_encoder(
                    key, closure, self._classes(closure), _make_cdr_encoder(key, gen.store, build)
                )
                gen.encoders[key] = encode
            _SHARED.put(shared_key, encode)
            return encode

    def _json_encoder(self, schema_name: str) -> Encoder:
        with self._lock:
            found = self._find(schema_name, ros_only=False)
            template: Any = None
            strict = False
            if found is not None:
                _, entry = found
                if isinstance(entry, _JsonSchema):
                    template = json_template(entry.schema)
                else:
                    template = ros_template(entry, self._resolve_ref)
                    strict = True
        typename = schema_name

        def encode(data: Mapping[str, Any] | RosMessage) -> bytes:
            """Encode a message instance or a (partial) mapping as compact
            JSON (UTF-8 bytes)."""
            try:
                merged = _merge(template, data, strict, "") if template is not None else data
            except Invalid as exc:
                raise _misfit(typename, exc) from None
            try:
                return _dumps(merged)
            except Exception as exc:
                raise MessageError(typename, f"not JSON: {exc}") from exc

        return encode

    # ------------------------------------------------------------------ introspection

    def template(self, schema_name: str) -> dict[str, Any]:
        """A fresh zero-filled dict of type ``schema_name``.

        For a ROS definition: every field, with the definition's default
        values where it declares them, else zeros (``0``, ``0.0``, ``False``,
        ``""``); a fixed-size array is a list of that many zero elements
        (``uint8[16]`` -> 16 zeros), a sequence ``[]``, nested messages are
        templated recursively. For a JSON Schema: see
        :func:`json_template` (an object's properties, numbers ``0``, strings
        ``""``, booleans ``False``, arrays ``[]`` unless ``minItems ==
        maxItems``, ``enum`` -> first member, ``const``, ``default`` wins); a
        schema whose top level is not an object gives ``{}``.

        Raises :class:`SchemaError` for an unknown type.
        """
        with self._lock:
            found = self._find(schema_name, ros_only=False)
            if found is None:
                raise SchemaError(f"unknown type {schema_name!r}")
            _, entry = found
            if isinstance(entry, _JsonSchema):
                value = json_template(entry.schema)
                return value if isinstance(value, dict) else {}
            return ros_template(entry, self._resolve_ref)

    def definition(self, schema_name: str) -> list[FieldDef]:
        """The top-level fields of ``schema_name`` in wire order (for a JSON
        Schema: its top-level properties, see :func:`json_definition`).
        Raises :class:`SchemaError` for an unknown type."""
        with self._lock:
            found = self._find(schema_name, ros_only=False)
        if found is None:
            raise SchemaError(f"unknown type {schema_name!r}")
        _, entry = found
        if isinstance(entry, _JsonSchema):
            return json_definition(entry.schema)
        return [f.to_fielddef() for f in entry.visible_fields]

    @staticmethod
    def service_type_names(service_type: str) -> tuple[str, str]:
        """``"std_srvs/srv/SetBool"`` or ``"std_srvs/SetBool"`` ->
        ``("std_srvs/srv/SetBool_Request", "std_srvs/srv/SetBool_Response")``."""
        return service_type_names(service_type)
