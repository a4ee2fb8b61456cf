"""Types a Zenoh connection learns from the robot (:class:`ZenohDescriptions`,
the type descriptions part of :class:`~._zenoh.ZenohAdapter`): REP-2011
``get_type_description``.

Every rmw_zenoh key and liveliness token names its type with the type's
RIHS01 hash. When the codec has no definition of a type, or ours hashes
differently, the adapter asks a node that publishes or serves it (found in
the graph's liveliness tokens) on ``<namespace>/<node>/get_type_description``
(``type_description_interfaces/srv/GetTypeDescription``, with the type
sources), hashes the answer and compares with the key's hash:

* a match is registered in this connection's registry (winning over any
  other definition of those names) and kept in the process cache
  (:data:`~ros_mobile_bridge.codec.DESCRIPTION_CACHE`), so no other
  connection asks again;
* a mismatch is refused, never decoded: a ``"type_hash_mismatch"``
  rejection, logged;
* a node that does not answer within ``options.type_description_timeout``,
  refuses (``successful: false``, or an error reply), or answers a
  description whose hash differs (or that does not parse) is one failure,
  counted in the rejections by its kind (``type_description_timeout``,
  ``type_description_refused``, ``type_hash_mismatch``,
  ``type_description_invalid``) and logged with the node's name; the next
  node using the type is asked, publishers and servers first, until one
  answers with the right hash. A node whose query reaches no queryable (its
  token seen before its service's route) is asked again, within its
  timeout;
* when every node failed (or none serves ``get_type_description``): a
  :class:`SchemaError` naming the type, every node asked and why (its
  ``failures``), and how to register the definition by hand.

The other way round, once this client publishes, its node answers
``/<our node>/get_type_description`` for the types it publishes, as a
well-behaved ROS node does (no type sources: a description made from the
definitions it encodes with).

Never more than one fetch per (type, hash) is in flight; everyone who needs
it waits on that one. A fetch runs in a task of the reader's task group, so
it ends with the connection. A success is kept for the connection's life. A
failure is kept until the graph shows a node using the type that was not
asked yet (a new node, or one that left and came back, or the first that
serves ``get_type_description``): :meth:`ZenohDescriptions.retry_failed`
then starts a fetch that asks the new nodes only, and its error names every
node asked for the type on this connection that is still in the graph.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

import anyio
from anyio.abc import TaskGroup

from .._errors import NotConnected, SchemaError, ServiceError, ServiceTimeout
from ..codec import (
    DESCRIPTION_CACHE,
    CodecRegistry,
    DescribedTypes,
    HashMismatch,
    describe,
    same_type_name,
    type_description,
)
from ..wire import rmw_zenoh as rz
from ..wire._limits import truncate_for_log
from ._seam import ServiceHost
from ._zenoh_calls import NoServerAnswered, ZenohQueries
from ._zenoh_node import ZenohNode
from ._zenoh_serving import ZenohServing

__all__ = ["DESCRIBE_SERVICE_TYPE", "ZenohDescriptions"]

DESCRIBE_SERVICE_TYPE: Final = "type_description_interfaces/srv/GetTypeDescription"
_SERVICE_SUFFIX: Final = "/get_type_description"
_NOT_ROUTED_PAUSE: Final = 0.05
"""Seconds before a node whose query reached no queryable is asked again
(doubling, up to 0.4 s, within ``type_description_timeout``)."""
_BY_HAND: Final = (
    "register it by hand with Client.register_type(name, msg_text) or point "
    "ClientOptions.interface_paths at a directory holding its .msg/.srv/.action files"
)


@dataclass(slots=True)
class _Fetch:
    """One (type, hash) being learnt: ``done`` is set once ``error`` (None
    on success) is final. ``failures``: node -> why it did not describe
    the type (the nodes asked, in the order asked)."""

    type_name: str
    type_hash: str
    done: anyio.Event = field(default_factory=anyio.Event)
    error: SchemaError | None = None
    failures: dict[str, str] = field(default_factory=dict)


class ZenohDescriptions:
    """REP-2011 type descriptions fetched from the graph's nodes, and our
    node's own ``get_type_description`` (see the module docstring); a
    :class:`~._seam.TypeDescriber`."""

    def __init__(
        self,
        node: ZenohNode,
        queries: ZenohQueries,
        serving: ZenohServing,
        *,
        published: Callable[[], Mapping[str, str]],
        on_described: Callable[[str, str], None],
    ) -> None:
        """``published`` is what this client publishes now (topic -> type:
        the types our node describes); ``on_described(type, hash)`` is
        called when a fetch ends, whatever its outcome (the samples held
        for it can go on)."""
        self._codecs = node.codecs
        self._options = node.options
        self._log = node.log
        self._events = node.events
        self._graph = node.graph
        self._type_hash = node.type_hash
        self._node_name = node.node_name
        self._queries = queries
        self._serving = serving
        self._published = published
        self._on_described = on_described
        self._fetches: dict[tuple[str, str], _Fetch] = {}
        self.group: TaskGroup | None = None
        """The reader's task group, where fetches run (None while no reader
        runs: a fetch then runs in the task that needs it)."""
        self.description_requests = 0
        """get_type_description requests this connection sent."""
        self.descriptions_served = 0
        """get_type_description requests this connection's node answered."""
        self._describing = False

    # -- what is known ----------------------------------------------------------------
    def knows(self, type_name: str, type_hash: str) -> bool:
        """Whether our definition of ``type_name`` has ``type_hash``; a
        description in the process cache is registered on the way."""
        try:
            if self._type_hash(type_name) == type_hash:
                return True
        except SchemaError:
            pass
        cached = DESCRIPTION_CACHE.get(type_hash)
        if cached is None or cached.type_name != type_name:
            return False
        try:
            self._codecs.add_description(cached)
        except SchemaError:
            return False
        return True

    def failed(self, type_name: str, type_hash: str) -> SchemaError | None:
        """The error of a finished, failed fetch of this (type, hash)."""
        fetch = self._fetches.get((type_name, type_hash))
        return fetch.error if fetch is not None and fetch.done.is_set() else None

    def describers(self, type_name: str, type_hash: str) -> list[str]:
        """The ``get_type_description`` services of the nodes that use
        (type, hash): publishers and servers first, then the others."""
        tokens = self._graph.tokens
        services = {
            token.name
            for token in tokens.values()
            if token.kind is rz.EntityKind.SERVICE
            and token.type_name == DESCRIBE_SERVICE_TYPE
            and token.name is not None
        }
        order = {
            rz.EntityKind.PUBLISHER: 0,
            rz.EntityKind.SERVICE: 0,
            rz.EntityKind.SUBSCRIPTION: 1,
            rz.EntityKind.CLIENT: 1,
        }
        found: dict[str, int] = {}
        for token in tokens.values():
            if token.type_name != type_name or token.type_hash != type_hash:
                continue
            namespace = token.namespace.rstrip("/")
            service = f"{namespace}/{token.node_name}{_SERVICE_SUFFIX}"
            if service in services:
                rank = order.get(token.kind, 2)
                found[service] = min(rank, found.get(service, rank))
        return sorted(found, key=lambda s: (found[s], s))

    # -- fetching -----------------------------------------------------------------------
    def want(self, type_name: str, type_hash: str) -> _Fetch | None:
        """The fetch of (type, hash), started in the reader's task group if
        none is under way; None when the reader is not running."""
        key = (type_name, type_hash)
        fetch = self._fetches.get(key)
        if fetch is not None:
            return fetch
        group = self.group
        if group is None:
            return None
        fetch = self._fetches[key] = _Fetch(type_name, type_hash)
        group.start_soon(self._run_fetch, fetch)
        return fetch

    async def ensure_described(self, type_name: str, type_hash: str) -> None:
        """Return once our definition of ``type_name`` has ``type_hash``,
        fetching it from a node if need be; :class:`SchemaError` (see the
        module docstring) when it cannot be learnt."""
        if self.knows(type_name, type_hash):
            return
        fetch = self.want(type_name, type_hash)
        if fetch is None:  # no reader (yet): fetch in the caller's task
            fetch = self._fetches.setdefault((type_name, type_hash), _Fetch(type_name, type_hash))
            if not fetch.done.is_set():
                await self._run_fetch(fetch)
        await fetch.done.wait()
        if fetch.error is not None:
            raise fetch.error

    async def describe_entity(self, name: str, kind: rz.EntityKind) -> None:
        """Learn the type of the graph's entity ``name`` from its node when
        our definition lacks it or hashes differently; ``SchemaError`` when
        it cannot be learnt."""
        announced = self._graph.graph_hash(name, (kind,))
        if announced is not None:
            await self.ensure_described(*announced)

    async def fetch_definition(self, schema: str) -> bool:
        """Known, or learnt from a node of the graph that uses a type of
        that name: whether a definition with the graph's hash is known now.
        ``SchemaError`` when a node was asked and did not tell."""
        announced = self._graph.announced(schema)
        if announced is None:
            return self._codecs.resolves(schema)
        await self.ensure_described(*announced)
        return True

    def retry_failed(self) -> list[tuple[str, str]]:
        """After a change of the graph: start a new fetch of each failed
        (type, hash) that a node not asked yet now uses (the nodes that
        failed and are still in the graph are not asked again); returns
        the (type, hash) pairs fetched again. Needs the reader's task
        group (none while it does not run)."""
        group = self.group
        if group is None:
            return []
        retried: list[tuple[str, str]] = []
        for key, fetch in list(self._fetches.items()):
            if not fetch.done.is_set() or fetch.error is None:
                continue
            nodes = [_node_of(s) for s in self.describers(*key)]
            if all(node in fetch.failures for node in nodes):
                continue
            again = self._fetches[key] = _Fetch(*key)
            # a node that left the graph may come back as another process
            again.failures = {n: why for n, why in fetch.failures.items() if n in nodes}
            group.start_soon(self._run_fetch, again)
            retried.append(key)
        return retried

    async def _run_fetch(self, fetch: _Fetch) -> None:
        try:
            await self._fetch(fetch)
        except SchemaError as exc:
            fetch.error = exc
            self._log.warning("%s", truncate_for_log(str(exc)))
        except NotConnected as exc:  # no node's fault: asked again when the graph changes
            fetch.error = SchemaError(f"cannot learn {fetch.type_name} ({fetch.type_hash}): {exc}")
            self._log.warning("%s", truncate_for_log(str(fetch.error)))
        except Exception as exc:  # a bug must not kill the reader's task group
            fetch.error = SchemaError(
                f"cannot learn {fetch.type_name} ({fetch.type_hash}): {type(exc).__name__}: {exc}"
            )
            self._log.exception("fetching the type description of %s failed", fetch.type_name)
        finally:
            fetch.done.set()
            self._on_described(fetch.type_name, fetch.type_hash)

    async def _fetch(self, fetch: _Fetch) -> None:
        """Ask each node using (type, hash) not asked yet, in turn, until
        one describes it with that hash (see the module docstring)."""
        type_name, type_hash = fetch.type_name, fetch.type_hash
        if self.knows(type_name, type_hash):
            return
        services = [
            s for s in self.describers(type_name, type_hash) if _node_of(s) not in fetch.failures
        ]
        if not services and not fetch.failures:
            raise SchemaError(
                f"no definition of {type_name} ({type_hash}) and no node using it serves "
                f"get_type_description to ask; {_BY_HAND}"
            )
        for service in services:
            node = _node_of(service)
            failure = await self._ask(service, node, type_name, type_hash)
            if failure is None:
                return
            kind, why = failure
            fetch.failures[node] = why
            self._events.reject(kind, f"{type_name}: node {node} {why}")
        asked = "; ".join(f"node {node} {why}" for node, why in fetch.failures.items())
        raise SchemaError(
            f"no definition of {type_name} ({type_hash}): {asked}; {_BY_HAND}",
            failures=fetch.failures,
        )

    async def _ask(
        self, service: str, node: str, type_name: str, type_hash: str
    ) -> tuple[str, str] | None:
        """Ask one node; None once its description is registered, else the
        failure's kind (a rejection reason) and why."""
        timeout = self._options.type_description_timeout
        request = {"type_name": type_name, "type_hash": type_hash, "include_type_sources": True}
        deadline = anyio.current_time() + timeout
        pause = _NOT_ROUTED_PAUSE
        try:
            while True:
                self.description_requests += 1
                try:
                    left = max(deadline - anyio.current_time(), _NOT_ROUTED_PAUSE)
                    answer = await self._queries.request(
                        service, DESCRIBE_SERVICE_TYPE, request, left
                    )
                    break
                except NoServerAnswered:
                    # its token came before its queryable's route: asked
                    # again until the timeout
                    if anyio.current_time() + pause >= deadline:
                        raise
                    await anyio.sleep(pause)
                    pause = min(pause * 2, _NOT_ROUTED_PAUSE * 8)
        except ServiceTimeout:
            return "type_description_timeout", (
                f"did not describe it within {timeout:g} s (type_description_timeout)"
            )
        except ServiceError as exc:
            return "type_description_refused", f"could not describe it: {exc.reason}"
        if not _field(answer, "successful"):
            reason = _field(answer, "failure_reason") or "no reason given"
            return "type_description_refused", f"could not describe it: {reason}"
        try:
            described = describe(
                _field(answer, "type_description"),
                _field(answer, "type_sources") or (),
                expected_hash=type_hash,
                max_fields=self._options.max_schema_fields,
            )
        except HashMismatch as exc:
            return "type_hash_mismatch", f"described another {type_name}: {exc}"
        except SchemaError as exc:
            return "type_description_invalid", f"sent a description that does not parse: {exc}"
        if described.type_name != type_name:
            return "type_description_invalid", (
                f"described {described.type_name} when asked for {type_name}"
            )
        await anyio.to_thread.run_sync(self._register_described, described)
        DESCRIPTION_CACHE.remember(described)
        return None

    def _register_described(self, described: DescribedTypes) -> None:
        """Register in this connection's registry and build the codecs the
        first message will need (in a worker thread: code generation)."""
        self._codecs.add_description(described)
        name = described.type_name
        try:
            if name in described.defs:
                self._codecs.decoder(name, "cdr")
            elif name.split("/")[1] == "srv":
                request, response = CodecRegistry.service_type_names(name)
                self._codecs.encoder(request, "cdr")
                self._codecs.decoder(response, "cdr")
        except SchemaError:
            pass  # said by whoever asks for the codec

    # -- answering ----------------------------------------------------------------------
    async def serve_descriptions(self) -> None:
        """Serve our node's ``get_type_description`` (once per connection;
        called when this client starts publishing). A failure to declare it
        is logged: publishing goes on."""
        if self._describing:
            return
        self._describing = True
        name = f"/{self._node_name}{_SERVICE_SUFFIX}"
        try:
            handler = _DescriptionServer(name, self.description_answer, self._log)
            await self._serving.advertise_service(
                name, DESCRIBE_SERVICE_TYPE, handler, confirm=False
            )
        except Exception as exc:
            self._log.warning("cannot serve %s: %s", name, truncate_for_log(str(exc)))

    def description_answer(self, type_name: Any, type_hash: Any) -> dict[str, Any]:
        """The GetTypeDescription response our node gives for (type, hash):
        the description of a type this client publishes, when the hash is
        ours (or not given); a failure naming the reason otherwise."""
        self.descriptions_served += 1
        name = type_name if isinstance(type_name, str) else ""
        published = next(
            (t for t in self._published().values() if name and same_type_name(t, name)), None
        )
        if published is None:
            return _refusal(f"this node does not publish {name!r}")
        try:
            ours = self._type_hash(published)
            if type_hash and type_hash != ours:
                return _refusal(f"{published} has the hash {ours} here, not {type_hash}")
            description = type_description(self._codecs, published)
        except SchemaError as exc:
            return _refusal(str(exc))
        return {
            "successful": True,
            "failure_reason": "",
            "type_description": description,
            "type_sources": [],
            "extra_information": [],
        }


class _DescriptionServer:
    """The handler of our node's ``get_type_description`` (see
    :class:`~._seam.ServiceHandler`)."""

    def __init__(
        self, name: str, answer: Callable[[Any, Any], dict[str, Any]], log: logging.Logger
    ) -> None:
        self.name = name
        self.answer = answer
        self.log = log

    async def on_service_request(self, host: ServiceHost, request_id: str, args: Any) -> None:
        response = self.answer(_field(args, "type_name"), _field(args, "type_hash"))
        await host.respond_service(self.name, request_id, response, True)

    def on_service_failed(self, error: Exception) -> None:
        self.log.warning("%s: %s", self.name, error)


def _node_of(service: str) -> str:
    """The node of its ``get_type_description`` service's name."""
    return service.removesuffix(_SERVICE_SUFFIX)


def _refusal(reason: str) -> dict[str, Any]:
    return {"successful": False, "failure_reason": reason}


def _field(value: Any, name: str) -> Any:
    getter: Callable[[str], Any] | None = getattr(value, "get", None)
    return getter(name) if getter is not None else getattr(value, name, None)
