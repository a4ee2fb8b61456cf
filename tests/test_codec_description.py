"""REP-2011 type descriptions -> RIHS01 hashes and codec definitions
(codec/_description.py), the registry's add_description, the process cache,
and the hash-version check of wire/rmw_zenoh."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

from peers.ros_env import PeerEnv
from ros_mobile_bridge import SchemaError
from ros_mobile_bridge.codec import (
    CodecRegistry,
    DescribedTypes,
    DescriptionCache,
    HashMismatch,
    describe,
    description_hash,
    type_hash,
)
from ros_mobile_bridge.codec._typehash import TypeDesc, desc_from_msgdef
from ros_mobile_bridge.wire import rmw_zenoh as rz

pytest_plugins = ["peers.ros_fixtures"]

NESTED_MSG = """\
# a comment that only the source text keeps
int32 LIMIT=7
Inner inner
Inner[2] pair
Inner[<=3] few
Inner[] many
string<=8 short_name "robot"
string<=4[2] tags
float64[3] gains [1.0, 2.0, 3.5]
uint8[<=4] bytes_bounded
bool flag True
"""
INNER_MSG = "uint64 big 18446744073709551615\nint8[] small\n"


def _description(registry: CodecRegistry, name: str) -> dict[str, Any]:
    """The REP-2011 description of ``name`` made from ``registry``'s
    definitions, with the default values a .msg gives (as rosidl writes them)."""
    with registry.ros_lookup() as find:
        found = find(name)
        assert found is not None
    top = found[1]
    names = {name}
    stack = [top]
    descs: dict[str, TypeDesc] = {}
    defaults: dict[str, list[str]] = {}
    while stack:
        msgdef = stack.pop()
        assert not isinstance(msgdef, dict)
        desc = desc_from_msgdef(msgdef.name, msgdef)  # type: ignore[arg-type]
        descs[desc.name] = desc
        defaults[desc.name] = [
            ""
            if f.default is None
            else str(tuple(f.default))
            if isinstance(f.default, tuple)
            else str(f.default)
            for f in msgdef.fields  # type: ignore[union-attr]
        ]
        for ref in desc.refs:
            if ref not in names:
                names.add(ref)
                with registry.ros_lookup() as find:
                    sub = find(ref)
                assert sub is not None
                stack.append(sub[1])  # type: ignore[arg-type]

    def individual(n: str) -> dict[str, Any]:
        out = descs[n].as_json()
        for f, default in zip(out["fields"], defaults[n], strict=True):
            f["default_value"] = default
        return out

    return {
        "type_description": individual(name),
        "referenced_type_descriptions": [individual(n) for n in sorted(descs) if n != name],
    }


@pytest.fixture
def nested_registry() -> CodecRegistry:
    registry = CodecRegistry()
    registry.add_schema("rmbtest/msg/Inner", "ros2msg", INNER_MSG)
    registry.add_schema("rmbtest/msg/Outer", "ros2msg", NESTED_MSG)
    return registry


def test_a_description_hashes_as_the_registry_definition_it_came_from(
    nested_registry: CodecRegistry,
) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    assert description_hash(description) == type_hash(nested_registry, "rmbtest/msg/Outer")


def test_default_values_order_and_duplicates_do_not_change_the_hash(
    nested_registry: CodecRegistry,
) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    want = description_hash(description)
    changed = copy.deepcopy(description)
    for f in changed["type_description"]["fields"]:
        f["default_value"] = ""
    refs = changed["referenced_type_descriptions"]
    changed["referenced_type_descriptions"] = [*reversed(refs), refs[0]]
    assert description_hash(changed) == want


def test_described_definitions_round_trip_to_the_same_hash_and_codec(
    nested_registry: CodecRegistry,
) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    described = describe(description)
    assert set(described.defs) == {"rmbtest/msg/Outer", "rmbtest/msg/Inner"}
    fresh = CodecRegistry()
    fresh.add_description(described)
    assert type_hash(fresh, "rmbtest/msg/Outer") == description_hash(description)
    fields = {f.name: f for f in fresh.definition("rmbtest/msg/Outer")}
    assert (fields["pair"].array_length, fields["few"].upper_bound) == (2, 3)
    assert fields["many"].array and fields["many"].upper_bound is None
    assert (fields["short_name"].type, fields["short_name"].upper_bound) == ("string", 8)
    assert fields["tags"].type == "string<=4"
    assert fields["short_name"].default == "robot"
    assert fields["gains"].default == [1.0, 2.0, 3.5]
    assert fields["flag"].default is True
    inner = {f.name: f for f in fresh.definition("rmbtest/msg/Inner")}
    assert inner["big"].default == 2**64 - 1
    message = fresh.template("rmbtest/msg/Outer")
    message["many"] = [{"big": 5, "small": [1, -2]}]
    message["tags"] = ["ab", "cd"]
    payload = fresh.encoder("rmbtest/msg/Outer", "cdr")(message)
    assert payload == nested_registry.encoder("rmbtest/msg/Outer", "cdr")(message)
    decoded = fresh.decoder("rmbtest/msg/Outer", "cdr")(memoryview(payload))
    # a type learnt from a description decodes to a class made from it
    assert type(decoded).__ros_type__ == "rmbtest/msg/Outer"
    assert type(decoded).__ros_hash__ == description_hash(description)
    assert decoded.many[0].big == 5
    assert list(decoded.many[0].small) == [1, -2]
    assert decoded.short_name == "robot"
    assert fresh.message_class("rmbtest/msg/Outer") is type(decoded)


def test_msg_sources_give_constants_and_the_schema_text(nested_registry: CodecRegistry) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    sources = [
        {"type_name": "rmbtest/msg/Outer", "encoding": "msg", "raw_file_contents": NESTED_MSG},
        {"type_name": "rmbtest/msg/Inner", "encoding": "msg", "raw_file_contents": INNER_MSG},
        {"type_name": "rmbtest/msg/Bad", "encoding": "msg", "raw_file_contents": "nonsense ["},
    ]
    described = describe(description, sources)
    assert described.defs["rmbtest/msg/Outer"].constants == (("LIMIT", "int32", 7),)
    registry = CodecRegistry()
    registry.add_description(described)
    text = registry.ros2msg_text("rmbtest/msg/Outer")
    assert text.startswith("# a comment that only the source text keeps\n")
    assert "=" * 80 + "\nMSG: rmbtest/Inner\nuint64 big 18446744073709551615" in text


def test_a_source_that_describes_other_fields_is_ignored(nested_registry: CodecRegistry) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    wrong = NESTED_MSG.replace("bool flag True", "int32 flag 1")
    described = describe(
        description,
        [{"type_name": "rmbtest/msg/Outer", "encoding": "msg", "raw_file_contents": wrong}],
    )
    assert described.defs["rmbtest/msg/Outer"].constants == ()
    assert "rmbtest/msg/Outer" not in described.sources


def test_a_description_with_another_hash_is_refused(nested_registry: CodecRegistry) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    good = description_hash(description)
    description["type_description"]["fields"][0]["name"] = "renamed"
    with pytest.raises(HashMismatch, match="refused") as caught:
        describe(description, expected_hash=good)
    assert caught.value.expected == good
    assert caught.value.actual == description_hash(description)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda d: d.pop("type_description"), "missing"),
        (lambda d: d["type_description"].update(type_name="no slashes"), "invalid type name"),
        (lambda d: d["type_description"]["fields"][-1]["type"].update(type_id=13), "IDL char"),
        (lambda d: d["type_description"]["fields"][-1]["type"].update(type_id=47), "unknown"),
        (lambda d: d["type_description"]["fields"][0]["type"].update(type_id="x"), "integer"),
        (lambda d: d["type_description"].update(fields=[]), "no fields"),
        (lambda d: d.update(referenced_type_descriptions=[]), "does not describe"),
        (lambda d: d["type_description"]["fields"][0].update(name="bad name"), "invalid name"),
    ],
)
def test_malformed_descriptions_raise_schema_error(
    nested_registry: CodecRegistry, change: Any, match: str
) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    change(description)
    with pytest.raises(SchemaError, match=match):
        describe(description)


def test_a_bad_default_value_raises_schema_error(nested_registry: CodecRegistry) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    flag = description["type_description"]["fields"][-1]
    flag["default_value"] = "300"  # a bool
    with pytest.raises(SchemaError, match="bad default"):
        describe(description)


def test_too_many_fields_are_refused(nested_registry: CodecRegistry) -> None:
    description = _description(nested_registry, "rmbtest/msg/Outer")
    with pytest.raises(SchemaError, match="max_schema_fields=3"):
        describe(description, max_fields=3)


def test_described_definitions_win_over_bundled_ones_for_that_registry() -> None:
    registry = CodecRegistry()
    other = {
        "type_description": {
            "type_name": "std_msgs/msg/String",
            "fields": [
                {
                    "name": "data",
                    "type": {
                        "type_id": 8,
                        "capacity": 0,
                        "string_capacity": 0,
                        "nested_type_name": "",
                    },
                }
            ],
        },
        "referenced_type_descriptions": [],
    }
    registry.add_description(describe(other))
    assert [f.type for f in registry.definition("std_msgs/msg/String")] == ["int64"]
    assert type_hash(registry, "std_msgs/msg/String") == description_hash(other)
    assert [f.type for f in CodecRegistry().definition("std_msgs/msg/String")] == ["string"]


def test_the_cache_is_bounded_and_counts() -> None:
    cache = DescriptionCache(max_entries=2)
    entries = [DescribedTypes(f"p/msg/T{i}", f"RIHS01_{i:064x}", {}) for i in range(3)]
    for entry in entries:
        cache.remember(entry)
    assert len(cache) == 2
    assert (cache.stored, cache.evicted) == (3, 1)
    assert cache.get(entries[0].type_hash) is None
    assert cache.get(entries[2].type_hash) is entries[2]
    assert cache.hits == 1


def test_a_hash_of_another_version_is_named_and_refused() -> None:
    good = "RIHS01_" + "ab" * 32
    assert rz.parse_type_hash(good) == good
    with pytest.raises(rz.UnsupportedHashVersion, match="RIHS02: this library reads RIHS01"):
        rz.parse_type_hash("RIHS02_" + "ab" * 32)
    with pytest.raises(rz.UnsupportedHashVersion, match="RIHS02"):
        rz.parse_key("0/chatter/std_msgs::msg::dds_::String_/RIHS02_" + "ab" * 32)
    for bad in ("RIHS01_" + "AB" * 32, "RIHS01_abc", "nothing"):
        with pytest.raises(rz.MalformedKey) as caught:
            rz.parse_type_hash(bad)
        assert not isinstance(caught.value, rz.UnsupportedHashVersion)


def _official(env: PeerEnv) -> list[Path]:
    return sorted(env.prefix.glob("share/*/*/*.json"))


def test_every_official_description_hashes_to_its_official_hash(ros_peer_env: PeerEnv) -> None:
    checked = 0
    for path in _official(ros_peer_env):
        try:
            document = json.loads(path.read_text())
        except ValueError:
            continue
        if not isinstance(document, dict) or "type_description_msg" not in document:
            continue
        description = document["type_description_msg"]
        official = document["type_hashes"][0]["hash_string"]
        assert description_hash(description) == official, path
        described = describe(description, expected_hash=official)
        registry = CodecRegistry()
        registry.add_description(described)
        assert type_hash(registry, described.type_name) == official, path
        checked += 1
    assert checked > 200  # every interface package of the peer env
