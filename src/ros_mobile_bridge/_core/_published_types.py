"""The type policy of a publish: every type resolves to a definition, agrees
with the graph and, on a velocity topic, is a Twist; and the definitions the
user registered, carried to every connection."""

from __future__ import annotations

from collections.abc import Sequence

from .._checks import check_schema
from .._errors import SchemaError
from .._types import TopicInfo
from ..adapters import Adapter
from ..codec import CodecRegistry, same_type_name

__all__ = ["PublishTypes"]


class PublishTypes:
    """What :meth:`Client.publish` checks before anything is sent, and the
    types :meth:`Client.register_type` added."""

    def __init__(self, stop_topics: Sequence[str]) -> None:
        self._stop_topics = stop_topics
        self._user_types: dict[str, tuple[str, str | bytes]] = {}
        self._user_types_in: Adapter | None = None  # the adapter that holds them
        self._checked: set[tuple[str, str, bool]] = set()
        self._checked_for: tuple[Adapter, list[TopicInfo]] | None = None

    def is_velocity_topic(self, topic: str) -> bool:
        return topic.endswith("cmd_vel") or topic in self._stop_topics

    async def check(
        self,
        adapter: Adapter,
        graph: list[TopicInfo],
        topic: str,
        schema: str,
        check_velocity: bool,
        is_velocity_type: bool,
    ) -> None:
        """The checks of ``Client.publish`` (``SchemaError``); nothing is
        sent unless resolving ``schema`` needs the server's definition. A
        passed check is remembered until the graph or the connection
        changes, so the hot path pays one set lookup."""
        seen = self._checked_for
        if seen is None or seen[0] is not adapter or seen[1] is not graph:
            self._checked = set()
            self._checked_for = (adapter, graph)
        key = (topic, schema, check_velocity)
        if key in self._checked:
            return
        self.apply(adapter)
        velocity_topic = self.is_velocity_topic(topic)
        resolved = adapter.codecs.resolves(schema) or any(
            same_type_name(t.schema_name, schema) for t in graph
        )
        describer = adapter.descriptions
        if not resolved and describer is not None and not (check_velocity and velocity_topic):
            # (a velocity topic refuses an unresolved type anyway: no round trip)
            resolved = await describer.fetch_definition(schema)
        if not resolved:
            raise SchemaError(
                f"unknown type {schema!r} for {topic}: no definition is bundled, the server "
                "offers none and none was registered (Client.register_type); misspelled?"
            )
        for info in graph:
            if (
                info.name == topic
                and info.schema_name
                and not same_type_name(info.schema_name, schema)
            ):
                raise SchemaError(
                    f"{topic} carries {info.schema_name!r} on the robot; publishing {schema!r} "
                    "there contradicts it"
                )
        if check_velocity and velocity_topic and not is_velocity_type:
            raise SchemaError(
                f"{topic} is a velocity topic and {schema!r} is not geometry_msgs/msg/Twist or "
                "TwistStamped: the robot would not obey it, nor stop on it "
                "(check_velocity=False, or rmb pub --no-velocity-check, sends it anyway)"
            )
        self._checked.add(key)

    def register(self, name: str, definition: str | bytes, encoding: str) -> None:
        """Check and keep a user definition (see ``Client.register_type``)."""
        check_schema(name)
        if not isinstance(definition, str | bytes):
            raise TypeError(f"definition must be str or bytes, not {type(definition).__name__}")
        if encoding not in ("ros2msg", "ros2idl", "ros2action"):
            raise ValueError(
                f"encoding must be 'ros2msg', 'ros2idl' or 'ros2action', got {encoding!r}"
            )
        scratch = CodecRegistry()
        for known, (known_encoding, text) in self._user_types.items():
            scratch.add_schema(known, known_encoding, text)
        scratch.add_schema(name, encoding, definition)
        if encoding == "ros2action":
            checked = [f"{name}_SendGoal_Request", f"{name}_GetResult_Response"]
            checked.append(f"{name}_FeedbackMessage")
        elif "/srv/" in name:
            checked = list(CodecRegistry.service_type_names(name))
        else:
            checked = [name]
        for each in checked:
            scratch.encoder(each, "cdr")  # every type it uses resolves
        self._user_types[name] = (encoding, definition)
        self._user_types_in = None
        self._checked = set()

    def apply(self, adapter: Adapter) -> None:
        """Give ``adapter``'s codecs the registered types (once per adapter)."""
        if self._user_types and self._user_types_in is not adapter:
            for name, (encoding, text) in self._user_types.items():
                adapter.codecs.add_schema(name, encoding, text)
            self._user_types_in = adapter
