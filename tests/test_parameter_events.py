"""adapters/_parameter_events.py: one ``ParameterEvent`` to the watched
``/node:param`` values it changes, shared by the Zenoh and rosbridge
watches; anything that is not a ``ParameterEvent`` is ``None`` (counted as
malformed by the adapters), never an exception."""

from __future__ import annotations

from typing import Any

import pytest

from ros_mobile_bridge.adapters._parameter_events import by_node, watched_values

WATCHED = {"/robot:gain", "/robot:old", "/robot:bytes", "/robot:list"}


def test_new_changed_and_deleted_watched_parameters() -> None:
    event = {
        "node": "/robot",
        "new_parameters": [
            {"name": "bytes", "value": {"type": 5, "byte_array_value": [1, 2]}},
            {"name": "other", "value": {"type": 2, "integer_value": 1}},
        ],
        "changed_parameters": [
            {"name": "gain", "value": {"type": 3, "double_value": 0.75}},
            {"name": "list", "value": {"type": 7, "integer_array_value": (1, 2)}},
        ],
        "deleted_parameters": [{"name": "old"}, {"name": "unwatched"}],
    }
    assert watched_values(event, WATCHED) == {
        "/robot:bytes": b"\x01\x02",
        "/robot:gain": 0.75,
        "/robot:list": [1, 2],
        "/robot:old": None,
    }


def test_a_value_not_set_is_none_and_an_unwatched_event_is_empty() -> None:
    unset = {"node": "/robot", "changed_parameters": [{"name": "gain", "value": {"type": 0}}]}
    assert watched_values(unset, WATCHED) == {"/robot:gain": None}
    assert watched_values({"node": "/elsewhere", "changed_parameters": []}, WATCHED) == {}
    assert watched_values({"node": "/robot"}, WATCHED) == {}  # no lists: nothing changed


@pytest.mark.parametrize(
    "event",
    [
        None,
        "text",
        [],
        {},
        {"node": ""},
        {"node": "robot"},
        {"node": 7},
        {"node": "/robot", "changed_parameters": 5},
        {"node": "/robot", "changed_parameters": "gain"},
        {"node": "/robot", "deleted_parameters": {"name": "old"}},
        {
            "node": "/robot",
            "changed_parameters": [
                {"name": "list", "value": {"type": 7, "integer_array_value": 3}}
            ],
        },
        {
            "node": "/robot",
            "new_parameters": [{"name": "bytes", "value": {"type": 5, "byte_array_value": [300]}}],
        },
    ],
)
def test_what_is_not_a_parameter_event_is_none(event: Any) -> None:
    assert watched_values(event, WATCHED) is None


def test_names_are_node_colon_param() -> None:
    assert by_node(["/a:x", "/a:y", "/b:z"]) == {"/a": ["x", "y"], "/b": ["z"]}
    for bad in ("speed", "a:x", "/a:", "/a"):
        with pytest.raises(ValueError, match="/node:param"):
            by_node([bad])
