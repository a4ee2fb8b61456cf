"""rmw_zenoh's naming conventions (ROS 2 Jazzy), both ways, as pure functions.

No sessions, no threads, no event loop: this module turns ROS names, types and
QoS into the Zenoh key expressions, liveliness tokens and attachments that
``rmw_zenoh_cpp`` uses, and parses what a peer sends back. The adapter
(``adapters/_zenoh.py``) owns the Zenoh session and feeds these functions.

The conventions, as ``rmw_zenoh_cpp`` (Jazzy) writes them:

* **Data keys** (publications, subscriptions, service queries)::

      <domain>/<name without its leading slash>/<pkg>::<kind>::dds_::<Type>_/RIHS01_<64 hex>

  e.g. ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...``. The name may
  hold slashes, so :func:`parse_key` reads the type and hash from the right.
* **Liveliness tokens** (the graph)::

      @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS|SS|SC>/<enclave>/<namespace>/<node>
              [/<name>/<dds type>/<type hash>/<qos>]

  with every ``/`` inside a name replaced by ``%`` and an empty part written
  ``%`` (:func:`mangle`). Node and entity ids count from 0 in every process,
  so only the whole token identifies an entity.
* **Attachments**: every publication, service request and reply carries the
  sequence number, the source timestamp (ns) and the 16-byte source gid,
  serialized with zenoh-ext (int64 little-endian; a string or a byte array
  as its length, one LEB128 byte here, then its bytes). Released
  ``rmw_zenoh_cpp`` versions send one of two forms:

  - the **fixed form**, 33 bytes: ``seq | stamp | 0x10 gid`` (Jazzy 0.2.4
    and later, every Kilted release, Rolling 0.6.0 and later): what we send;
  - the **keyed form**, 77 bytes: each value behind its name as a string,
    ``0x0f "sequence_number" seq | 0x10 "source_timestamp" stamp |
    0x0a "source_gid" 0x10 gid`` (Jazzy 0.2.0 to 0.2.3, Rolling 0.3.0 to
    0.5.0).

  Both are read (:func:`decode_attachment`). ``rmw_zenoh_cpp`` drops a
  sample without an attachment it can read, and so do we. (Releases before
  zenoh 1.0 used zenoh 0.11's attachment maps; their sessions cannot talk
  to a zenoh 1.x router at all.)
* **GIDs**: an entity's gid is the XXH3-128 hash (seed 0) of its whole
  liveliness key, the low 64 bits then the high 64 bits, each little-endian
  (:func:`entity_gid`).
* **Service servers** declare a *complete* queryable on the service's data
  key and an ``SS`` token. A reply carries the response's CDR on the
  service key and an attachment holding the *request's* sequence number and
  the *client's* gid (the server's own clock as its timestamp), by which the
  client matches it to its call.

Peer input never makes a parser do anything but return or raise
:class:`MalformedKey` / :class:`MalformedAttachment` (both ``ValueError``);
the caller logs and skips. Inputs are bounded: a key or token longer than
:data:`MAX_KEY_LENGTH` characters is refused before it is split. Bad *caller*
arguments to the formatting functions raise ``ValueError`` at once.
"""

from __future__ import annotations

import enum
import re
import struct
from dataclasses import dataclass
from typing import Final, TypeAlias

import xxhash

__all__ = [
    "ATTACHMENT_SIZE",
    "HASH_VERSION",
    "KEYED_ATTACHMENT_SIZE",
    "LIVELINESS_PREFIX",
    "MAX_KEY_LENGTH",
    "Attachment",
    "EntityKind",
    "InboxItem",
    "LivelinessChange",
    "MalformedAttachment",
    "MalformedKey",
    "Qos",
    "QueryDone",
    "Reply",
    "Request",
    "SampleData",
    "Samples",
    "SessionLost",
    "Token",
    "TopicKey",
    "UnsupportedHashVersion",
    "attachment_timestamp",
    "dds_type_name",
    "decode_attachment",
    "encode_attachment",
    "encode_keyed_attachment",
    "entity_gid",
    "format_key",
    "format_qos",
    "format_token",
    "liveliness_selector",
    "mangle",
    "parse_key",
    "parse_qos",
    "parse_token",
    "parse_type_hash",
    "ros_type_name",
    "unmangle",
]

LIVELINESS_PREFIX: Final = "@ros2_lv"
MAX_KEY_LENGTH: Final = 4096
"""The longest key or token (in characters) the parsers look at."""
ATTACHMENT_SIZE: Final = 33
"""The fixed form's size (what current ``rmw_zenoh_cpp`` releases send)."""
KEYED_ATTACHMENT_SIZE: Final = 77
"""The keyed form's size (``rmw_zenoh_cpp`` Jazzy 0.2.0-0.2.3, Rolling 0.3-0.5)."""
_GID_SIZE: Final = 16
_ATTACHMENT: Final = struct.Struct("<qqB16s")
_KEYS: Final = (b"\x0fsequence_number", b"\x10source_timestamp", b"\x0asource_gid\x10")
_KEYED: Final = struct.Struct(f"<{len(_KEYS[0])}sq{len(_KEYS[1])}sq{len(_KEYS[2])}s{_GID_SIZE}s")
_MAX_DOMAIN: Final = 232  # ROS 2's highest valid domain id
_HASH = re.compile(r"RIHS01_[0-9a-f]{64}")
_ANY_HASH_VERSION = re.compile(r"RIHS([0-9A-Fa-f]{2})_")
HASH_VERSION: Final = "RIHS01"
"""The only REP-2011 type hash version this library reads and writes."""
_NAME_PART = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_DDS_TYPE = re.compile(
    r"(?P<pkg>[A-Za-z_][A-Za-z0-9_]*)::(?P<kind>msg|srv|action)::dds_::(?P<type>[A-Za-z_][A-Za-z0-9_]*)_"
)
_ZID = re.compile(r"[0-9a-f]{1,32}")
_INT = re.compile(r"[0-9]{1,19}")


class MalformedKey(ValueError):
    """A key expression or liveliness token that does not follow rmw_zenoh's
    conventions (or is longer than :data:`MAX_KEY_LENGTH`)."""


class UnsupportedHashVersion(MalformedKey):
    """A type hash of another REP-2011 version than ``RIHS01`` (e.g. a
    future ``RIHS02_...``): this library reads RIHS01 only, so a type named
    with it is never matched with one of our definitions."""

    def __init__(self, version: str) -> None:
        super().__init__(
            f"type hash version {version}: this library reads {HASH_VERSION} hashes only "
            "(a newer ROS 2 distribution?)"
        )
        self.version = version


class MalformedAttachment(ValueError):
    """An attachment that is missing, short, long or not rmw_zenoh's layout."""


# -- names and types ----------------------------------------------------------------------
def mangle(name: str) -> str:
    """A name as one token part: ``/`` becomes ``%``; the empty name is ``%``."""
    return name.replace("/", "%") if name else "%"


def unmangle(part: str) -> str:
    """The inverse of :func:`mangle` (``%`` alone reads back as ``/``)."""
    return part.replace("%", "/")


def dds_type_name(type_name: str) -> str:
    """``pkg/msg/Type`` -> ``pkg::msg::dds_::Type_`` (also ``srv`` and ``action``).

    Raises ``ValueError`` for a name that is not ``pkg/<msg|srv|action>/Type``.
    """
    parts = type_name.split("/")
    if (
        len(parts) != 3
        or parts[1] not in ("msg", "srv", "action")
        or not all(_NAME_PART.fullmatch(p) for p in (parts[0], parts[2]))
    ):
        raise ValueError(f"not a ROS 2 type name of the form pkg/msg/Type: {type_name!r}")
    return f"{parts[0]}::{parts[1]}::dds_::{parts[2]}_"


def ros_type_name(dds_name: str) -> str:
    """``pkg::msg::dds_::Type_`` -> ``pkg/msg/Type``; :class:`MalformedKey` otherwise."""
    match = _DDS_TYPE.fullmatch(dds_name)
    if match is None:
        raise MalformedKey(f"not a DDS type name: {dds_name[:200]!r}")
    return f"{match['pkg']}/{match['kind']}/{match['type']}"


def _check_domain(domain: int) -> None:
    if isinstance(domain, bool) or not isinstance(domain, int) or not 0 <= domain <= _MAX_DOMAIN:
        raise ValueError(f"domain id must be an int in 0..{_MAX_DOMAIN}, got {domain!r}")


def _parse_domain(part: str) -> int:
    if not _INT.fullmatch(part) or int(part) > _MAX_DOMAIN:
        raise MalformedKey(f"bad domain id {part[:40]!r}")
    return int(part)


def _check_length(text: str) -> None:
    if len(text) > MAX_KEY_LENGTH:
        raise MalformedKey(f"longer than {MAX_KEY_LENGTH} characters ({len(text)})")


def parse_type_hash(text: str) -> str:
    """``text`` when it is a RIHS01 type hash (``"RIHS01_"`` + 64 lowercase
    hex digits). :class:`UnsupportedHashVersion` (a :class:`MalformedKey`)
    naming the version for a hash of another version, :class:`MalformedKey`
    for anything else."""
    if _HASH.fullmatch(text):
        return text
    version = _ANY_HASH_VERSION.match(text)
    if version is not None and version[1] != "01":
        raise UnsupportedHashVersion(f"RIHS{version[1]}")
    raise MalformedKey(f"not a RIHS01 type hash: {text[:80]!r}")


# -- data keys ----------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class TopicKey:
    """One data key: the domain, the ROS name (with its leading slash), the
    ROS type name (``pkg/msg/Type``) and its ``RIHS01_`` hash."""

    domain: int
    name: str
    type_name: str
    type_hash: str


def format_key(key: TopicKey) -> str:
    """The key expression of ``key``; ``ValueError`` for an invalid part."""
    _check_domain(key.domain)
    name = key.name.strip("/")
    if not name or "//" in name or any(c in name for c in "*$?#% "):
        raise ValueError(f"not a ROS name: {key.name!r}")
    if not _HASH.fullmatch(key.type_hash):
        raise ValueError(f"not a RIHS01 type hash: {key.type_hash!r}")
    return f"{key.domain}/{name}/{dds_type_name(key.type_name)}/{key.type_hash}"


def parse_key(key: str) -> TopicKey:
    """Parse a data key; :class:`MalformedKey` for anything else."""
    _check_length(key)
    parts = key.split("/")
    if len(parts) < 4 or not all(parts[1:-2]):
        raise MalformedKey(f"not <domain>/<name>/<type>/<hash>: {key[:200]!r}")
    domain = _parse_domain(parts[0])
    type_name = ros_type_name(parts[-2])
    type_hash = parse_type_hash(parts[-1])
    return TopicKey(domain, "/" + "/".join(parts[1:-2]), type_name, type_hash)


def liveliness_selector(domain: int) -> str:
    """The key expression matching every liveliness token of ``domain``."""
    _check_domain(domain)
    return f"{LIVELINESS_PREFIX}/{domain}/**"


# -- QoS ------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Qos:
    """The QoS settings this library reads and writes in a token's QoS part.

    Deadline, lifespan and liveliness are parsed for validity and otherwise
    ignored (written as defaults)."""

    reliable: bool = True
    transient_local: bool = False
    keep_all: bool = False
    depth: int = 10


def format_qos(qos: Qos) -> str:
    """``<rel>:<dur>:<hist>,<depth>:<deadline>:<lifespan>:<liveliness>``, with
    defaults (reliable, volatile, keep-last) left empty as rmw_zenoh does."""
    if isinstance(qos.depth, bool) or not isinstance(qos.depth, int) or qos.depth < 0:
        raise ValueError(f"QoS depth must be an int >= 0, got {qos.depth!r}")
    rel = "" if qos.reliable else "2"
    dur = "1" if qos.transient_local else ""
    hist = "2" if qos.keep_all else ""
    return f"{rel}:{dur}:{hist},{qos.depth}:,:,:,,"


def _enum(part: str, allowed: tuple[str, ...], what: str) -> str:
    if part not in allowed:
        raise MalformedKey(f"bad QoS {what} {part[:20]!r}")
    return part


def parse_qos(text: str) -> Qos:
    """Parse a token's QoS part; :class:`MalformedKey` for anything else.

    Reliability 1 = reliable, 2 = best effort; durability 1 = transient local,
    2 = volatile; history 1 = keep last, 2 = keep all; 0 or empty = default.
    """
    _check_length(text)
    parts = text.split(":")
    if len(parts) != 6:
        raise MalformedKey(f"QoS with {len(parts)} parts, expected 6: {text[:80]!r}")
    rel = _enum(parts[0], ("", "0", "1", "2"), "reliability")
    dur = _enum(parts[1], ("", "0", "1", "2"), "durability")
    history = parts[2].split(",")
    if len(history) != 2:
        raise MalformedKey(f"bad QoS history {parts[2][:40]!r}")
    hist = _enum(history[0], ("", "0", "1", "2"), "history")
    if history[1] and not _INT.fullmatch(history[1]):
        raise MalformedKey(f"bad QoS depth {history[1][:40]!r}")
    for index, count in ((3, 2), (4, 2), (5, 3)):
        fields = parts[index].split(",")
        if len(fields) != count or any(f and not _INT.fullmatch(f) for f in fields):
            raise MalformedKey(f"bad QoS part {parts[index][:40]!r}")
    return Qos(
        reliable=rel != "2",
        transient_local=dur == "1",
        keep_all=hist == "2",
        depth=int(history[1]) if history[1] else 10,
    )


# -- liveliness tokens ------------------------------------------------------------------------
class EntityKind(enum.Enum):
    """The entity kinds of a liveliness token."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


@dataclass(frozen=True, slots=True)
class Token:
    """One liveliness token. ``namespace`` and ``name`` are ROS names with
    their leading slash; ``name``, ``type_name``, ``type_hash`` and ``qos`` are
    ``None`` exactly for a node token."""

    domain: int
    zid: str
    node_id: int
    entity_id: int
    kind: EntityKind
    enclave: str
    namespace: str
    node_name: str
    name: str | None = None
    type_name: str | None = None
    type_hash: str | None = None
    qos: Qos | None = None


def format_token(token: Token) -> str:
    """The liveliness key of ``token``; ``ValueError`` for an invalid part."""
    _check_domain(token.domain)
    if not _ZID.fullmatch(token.zid):
        raise ValueError(f"not a zenoh id (lowercase hex): {token.zid!r}")
    if not _NAME_PART.fullmatch(token.node_name):
        raise ValueError(f"not a node name: {token.node_name!r}")
    head = (
        f"{LIVELINESS_PREFIX}/{token.domain}/{token.zid}/{token.node_id}/{token.entity_id}/"
        f"{token.kind.value}/{mangle(token.enclave)}/{mangle(token.namespace)}/{token.node_name}"
    )
    entity = (token.name, token.type_name, token.type_hash, token.qos)
    if token.kind is EntityKind.NODE:
        if any(part is not None for part in entity):
            raise ValueError("a node token has no name, type or QoS")
        return head
    if token.name is None or token.type_name is None or token.qos is None:
        raise ValueError(f"a {token.kind.name} token needs a name, a type and a QoS")
    if token.type_hash is None or not _HASH.fullmatch(token.type_hash):
        raise ValueError(f"not a RIHS01 type hash: {token.type_hash!r}")
    name = token.name if token.name.startswith("/") else "/" + token.name
    return (
        f"{head}/{mangle(name)}/{dds_type_name(token.type_name)}/{token.type_hash}/"
        f"{format_qos(token.qos)}"
    )


def parse_token(key: str) -> Token:
    """Parse a liveliness token; :class:`MalformedKey` for anything else."""
    _check_length(key)
    parts = key.split("/")
    if parts[0] != LIVELINESS_PREFIX or len(parts) not in (9, 13):
        raise MalformedKey(f"not an rmw_zenoh liveliness token: {key[:200]!r}")
    domain = _parse_domain(parts[1])
    zid = parts[2]
    if not _ZID.fullmatch(zid):
        raise MalformedKey(f"bad zenoh id {zid[:40]!r}")
    if not (_INT.fullmatch(parts[3]) and _INT.fullmatch(parts[4])):
        raise MalformedKey(f"bad node or entity id in {key[:200]!r}")
    try:
        kind = EntityKind(parts[5])
    except ValueError:
        raise MalformedKey(f"unknown entity kind {parts[5][:20]!r}") from None
    if not parts[8]:
        raise MalformedKey("empty node name")
    base = {
        "domain": domain,
        "zid": zid,
        "node_id": int(parts[3]),
        "entity_id": int(parts[4]),
        "kind": kind,
        "enclave": unmangle(parts[6]),
        "namespace": unmangle(parts[7]),
        "node_name": parts[8],
    }
    if kind is EntityKind.NODE:
        if len(parts) != 9:
            raise MalformedKey(f"a node token with entity parts: {key[:200]!r}")
        return Token(**base)  # type: ignore[arg-type]
    if len(parts) != 13:
        raise MalformedKey(f"a {kind.name} token without its entity parts: {key[:200]!r}")
    name = unmangle(parts[9])
    if not name.startswith("/") or name == "/":
        raise MalformedKey(f"bad entity name {parts[9][:80]!r}")
    parse_type_hash(parts[11])
    return Token(
        **base,  # type: ignore[arg-type]
        name=name,
        type_name=ros_type_name(parts[10]),
        type_hash=parts[11],
        qos=parse_qos(parts[12]),
    )


# -- attachments and gids ----------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Attachment:
    """A decoded attachment: sequence number, source timestamp (ns), gid."""

    sequence: int
    timestamp_ns: int
    gid: bytes


def encode_attachment(sequence: int, timestamp_ns: int, gid: bytes) -> bytes:
    """The 33-byte attachment; ``ValueError`` for out-of-range values."""
    if len(gid) != _GID_SIZE:
        raise ValueError(f"a gid is {_GID_SIZE} bytes, got {len(gid)}")
    try:
        return _ATTACHMENT.pack(sequence, timestamp_ns, _GID_SIZE, bytes(gid))
    except struct.error as exc:
        raise ValueError(f"attachment field out of range: {exc}") from None


def decode_attachment(data: bytes | bytearray | memoryview | None) -> Attachment:
    """Decode an attachment in either form a released ``rmw_zenoh_cpp``
    sends (see the module docstring); :class:`MalformedAttachment` if it is
    missing or neither form exactly (size, names, gid length)."""
    if data is None:
        raise MalformedAttachment("no attachment")
    size = len(data)
    if size == ATTACHMENT_SIZE:
        sequence, timestamp, gid_size, gid = _ATTACHMENT.unpack(bytes(data))
        if gid_size != _GID_SIZE:
            raise MalformedAttachment(f"gid length byte {gid_size}, expected {_GID_SIZE}")
        return Attachment(sequence, timestamp, gid)
    if size == KEYED_ATTACHMENT_SIZE:
        key1, sequence, key2, timestamp, key3, gid = _KEYED.unpack(bytes(data))
        if (key1, key2, key3) != _KEYS:
            raise MalformedAttachment("a 77-byte attachment without rmw_zenoh's keyed layout")
        return Attachment(sequence, timestamp, gid)
    raise MalformedAttachment(
        f"attachment of {size} bytes, expected {ATTACHMENT_SIZE} or {KEYED_ATTACHMENT_SIZE}"
    )


def encode_keyed_attachment(sequence: int, timestamp_ns: int, gid: bytes) -> bytes:
    """The keyed form (77 bytes) that ``rmw_zenoh_cpp`` Jazzy 0.2.0-0.2.3
    sent; we never send it (for tests and peers that speak it)."""
    if len(gid) != _GID_SIZE:
        raise ValueError(f"a gid is {_GID_SIZE} bytes, got {len(gid)}")
    try:
        return _KEYED.pack(_KEYS[0], sequence, _KEYS[1], timestamp_ns, _KEYS[2], bytes(gid))
    except struct.error as exc:
        raise ValueError(f"attachment field out of range: {exc}") from None


def attachment_timestamp(data: bytes | None) -> int | None:
    """The source timestamp (ns) of an attachment in either form; None when
    it is missing or malformed. The check per sample on the hot path: the
    fixed form is read by size and gid length byte, the keyed form by its
    names."""
    if data is None:
        return None
    size = len(data)
    if size == ATTACHMENT_SIZE and data[16] == _GID_SIZE:
        return int.from_bytes(data[8:16], "little", signed=True)
    if size == KEYED_ATTACHMENT_SIZE:
        try:
            return decode_attachment(data).timestamp_ns
        except MalformedAttachment:
            return None
    return None


def entity_gid(token_key: str) -> bytes:
    """The 16-byte gid of the entity whose liveliness key is ``token_key``,
    as ``rmw_zenoh_cpp`` derives it: XXH3-128 (seed 0) of the whole key's
    bytes, its low 64 bits then its high 64 bits, each little-endian."""
    return xxhash.xxh3_128_intdigest(token_key.encode()).to_bytes(_GID_SIZE, "little")


# -- what a session hands the adapter ----------------------------------------------------------
# One object per item a Zenoh session's threads hand to the event loop (one per
# batch of data samples on the hot path). Plain __slots__ classes with a plain __init__:
# the cheapest typed form to build (a slotted dataclass costs ~20% more, a
# frozen one ~5x). Read-only by convention.
class _Item:
    __slots__ = ()

    def __repr__(self) -> str:
        slots: tuple[str, ...] = self.__slots__
        fields = ", ".join(f"{name}={getattr(self, name)!r}" for name in slots)
        return f"{type(self).__name__}({fields})"


SampleData: TypeAlias = tuple[str, bytes, bytes | None]
"""One data sample: its key, payload and attachment (None when it carried none)."""


class Samples(_Item):
    """Data samples of the subscriber tagged ``tag``, oldest first, taken
    from zenoh together at ``receive_time_ns`` (``time.time_ns()``). One
    item per batch, not per sample: each sample is a plain
    :data:`SampleData` tuple (the cheapest form to build and to keep)."""

    __slots__ = ("receive_time_ns", "samples", "tag")

    def __init__(self, tag: int, samples: list[SampleData], receive_time_ns: int) -> None:
        self.tag = tag
        self.samples = samples
        self.receive_time_ns = receive_time_ns


class LivelinessChange(_Item):
    """A liveliness token of the subscriber tagged ``tag`` appeared
    (``alive``) or went away."""

    __slots__ = ("alive", "key", "tag")

    def __init__(self, tag: int, key: str, alive: bool) -> None:
        self.tag = tag
        self.key = key
        self.alive = alive


class Reply(_Item):
    """One reply to the query ``query_id``: ``ok`` with the replier's key,
    payload and attachment, or not ``ok`` with the error's bytes as
    ``payload`` (``key`` and ``attachment`` None)."""

    __slots__ = ("attachment", "key", "ok", "payload", "query_id")

    def __init__(
        self, query_id: int, key: str | None, payload: bytes, ok: bool, attachment: bytes | None
    ) -> None:
        self.query_id = query_id
        self.key = key
        self.payload = payload
        self.ok = ok
        self.attachment = attachment


class Request(_Item):
    """A query on the queryable tagged ``tag`` (a call to a service this
    client serves): ``query_id`` names it to the session's ``reply`` and
    ``reply_error``; its key, payload (empty when it carried none) and
    attachment (None when it carried none)."""

    __slots__ = ("attachment", "key", "payload", "query_id", "tag")

    def __init__(
        self, tag: int, query_id: int, key: str, payload: bytes, attachment: bytes | None
    ) -> None:
        self.tag = tag
        self.query_id = query_id
        self.key = key
        self.payload = payload
        self.attachment = attachment


class QueryDone(_Item):
    """The query ``query_id`` will get no more replies."""

    __slots__ = ("query_id",)

    def __init__(self, query_id: int) -> None:
        self.query_id = query_id


class SessionLost(_Item):
    """The session lost its router, for ``reason``."""

    __slots__ = ("reason",)

    def __init__(self, reason: str) -> None:
        self.reason = reason


InboxItem: TypeAlias = Samples | LivelinessChange | Reply | Request | QueryDone | SessionLost
"""Anything a session's inbox holds."""
