"""zenoh-ros2-sdk nodes: an rmw_zenoh implementation this project did not
write, as the peer of the Zenoh tests. One process runs one role:

    python tests/peers/zenoh_sdk_node.py --router tcp/127.0.0.1:7447 --domain 5 \\
        --definitions <ROS share dir> talker --topic /chatter --count 100

Roles: ``talker`` (``std_msgs/msg/String`` "hello N", or any ``--type``
with the field values ``--values`` gives as JSON, the rest zero),
``listener`` (one JSON line ``{"msg": {...}}`` per message, any type),
``service`` (``std_srvs/srv/SetBool``: success = data, message "set to
<data>"; any other ``--type`` answers each request with the response fields
of the same name copied from it), ``params`` (node ``/sdk_params``: its
``get_parameters``, ``set_parameters`` and ``list_parameters`` services over
three parameters), ``client`` (a
``ROS2ServiceClient`` of ``--name`` / ``--type`` that waits until the sdk's
discovery shows a server, then calls it once per request of ``--requests``,
a JSON list, printing one JSON line per call: ``{"response": {...}}``, or
``{"error": "<text>"}`` for an error reply, or ``{"error": null}`` for no
reply in time; then ``DONE``) and ``discover`` (one JSON line
``{"servers": N, "types": [...]}`` whenever the sdk's
``get_service_info(--name)`` changes). Each prints
``HASH <type> <RIHS01 hash>`` for the hash the sdk computed, then ``READY``,
and runs until stdin closes.

With ``--describe`` the talker and service nodes also serve REP-2011's
``/<node>/get_type_description``
(``type_description_interfaces/srv/GetTypeDescription``), answering from the
official ``share/<pkg>/<kind>/<Name>.json`` (its ``type_description_msg``)
with the ``.msg``/``.srv`` texts as ``type_sources``, and print ``DESCRIBED
<type>`` per answer. ``--describe-wrong`` answers with the main type's first
field renamed (so the hash disagrees); ``--describe-silent`` declares the
service and never answers.

The sdk looks up ``.msg`` / ``.srv`` files in a directory laid out as
``<pkg>/<msg|srv>/<Name>.<ext>`` and, when one is missing, clones the
interface's git repository from the internet. The tests point it at the
ROS 2 Jazzy wheels' ``share/`` directory (the official files) and this
script makes any download attempt fail loudly instead.
"""

from __future__ import annotations

import argparse
import json
import logging
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import TracebackType
from typing import Any


def _offline() -> None:
    """Make the sdk's git fallback raise instead of touching the network."""
    from zenoh_ros2_sdk import _cache, message_registry

    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError(f"zenoh-ros2-sdk tried to download definitions: {args!r}")

    _cache.clone_to_cache = refuse  # type: ignore[assignment]
    message_registry.clone_to_cache = refuse  # type: ignore[attr-defined]
    message_registry.get_message_file_path = refuse  # type: ignore[attr-defined]


def plain(value: Any) -> Any:
    """A rosbags message object as JSON-able data."""
    if hasattr(value, "__dataclass_fields__"):
        fields = (n for n in value.__dataclass_fields__ if n != "__msgtype__")
        return {name: plain(getattr(value, name)) for name in fields}
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return value


def emit(*parts: Any) -> None:
    print(*parts, flush=True)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--router", required=True)
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--definitions", required=True, help="directory <pkg>/<msg|srv>/*")
    parser.add_argument(
        "role", choices=["talker", "listener", "service", "params", "client", "discover"]
    )
    parser.add_argument("--topic", default="/chatter")
    parser.add_argument("--type", default="std_msgs/msg/String")
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--count", type=int, default=0, help="0: until stopped")
    parser.add_argument("--name", default="/sdk_set_bool")
    parser.add_argument("--values", default="", help="talker: JSON field values")
    parser.add_argument("--node", default="", help="node name (default per role)")
    describe = parser.add_mutually_exclusive_group()
    describe.add_argument("--describe", action="store_true")
    describe.add_argument("--describe-wrong", action="store_true")
    describe.add_argument("--describe-silent", action="store_true")
    parser.add_argument("--requests", default="[]", help="client: a JSON list of requests")
    parser.add_argument("--timeout", type=float, default=10.0, help="client: per call")
    args = parser.parse_args(argv)
    describing = args.describe or args.describe_wrong or args.describe_silent

    host, port = args.router.removeprefix("tcp/").rsplit(":", 1)
    from zenoh_ros2_sdk import message_registry

    message_registry.get_registry(args.definitions)  # the first call fixes the directory
    _offline()
    import zenoh_ros2_sdk as sdk

    where = {"domain_id": args.domain, "router_ip": host, "router_port": int(port)}
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    closers: list[Any] = []

    if args.role == "talker":
        node = args.node or "sdk_talker"
        pub = sdk.ROS2Publisher(
            args.topic, args.type, node_name=node, type_hash=official_hash(args), **where
        )
        closers.append(pub)
        if describing:
            closers.append(_describer(sdk, where, node, args))
        emit("HASH", args.type, pub.type_hash)
        emit("READY")
        sent = 0
        store = sdk.ZenohSession.get_instance(where["router_ip"], where["router_port"]).store
        values = json.loads(args.values) if args.values else None
        while not stop.is_set() and (args.count == 0 or sent < args.count):
            if values is None:
                pub.publish(data=f"hello {sent}")
            else:
                message = build(store, args.type, values)
                fields = store.fielddefs[args.type][1]
                pub.publish(**{n: getattr(message, n) for n, _ in fields})
            sent += 1
            time.sleep(1.0 / args.rate)
        emit("SENT", sent)
    elif args.role == "listener":
        lock = threading.Lock()

        def on_message(msg: Any) -> None:
            with lock:
                emit(json.dumps({"msg": plain(msg)}))

        sub = sdk.ROS2Subscriber(
            args.topic, args.type, on_message, node_name="sdk_listener", **where
        )
        closers.append(sub)
        emit("HASH", args.type, sub.type_hash)
        emit("READY")
    elif args.role == "service":
        holder: list[Any] = []
        srv_type = "std_srvs/srv/SetBool" if args.type == "std_msgs/msg/String" else args.type
        node = args.node or "sdk_service"

        def set_bool(request: Any) -> Any:
            server = holder[0]
            return server.response_msg_class(
                success=bool(request.data), message=f"set to {bool(request.data)}"
            )

        def echo(request: Any) -> Any:
            server = holder[0]
            fields = server.response_msg_class.__dataclass_fields__
            return server.response_msg_class(
                **{n: getattr(request, n) for n in fields if n != "__msgtype__"}
            )

        handler = set_bool if srv_type == "std_srvs/srv/SetBool" else echo
        server = sdk.ROS2ServiceServer(
            args.name,
            srv_type,
            handler,
            node_name=node,
            type_hash=official_hash(args, srv_type),
            **where,
        )
        holder.append(server)
        closers.append(server)
        store = sdk.ZenohSession.get_instance(where["router_ip"], where["router_port"]).store
        alias_nested_types(store, srv_type.split("/")[0])
        if describing:
            closers.append(_describer(sdk, where, node, args))
        emit("HASH", srv_type, server.type_hash)
        emit("READY")
    elif args.role == "client":
        closers.append(_client(sdk, where, args, stop))
    elif args.role == "discover":
        emit("READY")
        _discover(sdk, where, args.name, stop)
    else:
        closers.extend(_params_node(sdk, where))
        emit("READY")
    stop.wait()
    for closer in closers:
        closer.close()
    return 0


class _ErrorReplies(logging.Handler):
    """The text of each error reply the sdk's client logs ("Service call
    failed: <text>"): its ``call`` returns None for an error and a timeout
    alike."""

    def __init__(self) -> None:
        super().__init__()
        self.texts: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        if message.startswith("Service call failed: "):
            self.texts.append(message.removeprefix("Service call failed: "))


def _server_count(sdk: Any, where: dict[str, Any], name: str) -> tuple[int, list[str]]:
    info = sdk.get_service_info(name, **where)
    if info is None:
        return 0, []
    return int(info.server_count), sorted(info.service_types)


def _client(sdk: Any, where: dict[str, Any], args: argparse.Namespace, stop: Any) -> Any:
    """Wait for a server of ``args.name``, call it with each request, print
    each answer as a JSON line, then ``DONE``."""
    errors = _ErrorReplies()
    logging.getLogger("zenoh_ros2_sdk.service_client").addHandler(errors)
    if args.type == "type_description_interfaces/srv/GetTypeDescription":
        session = sdk.ZenohSession.get_instance(where["router_ip"], where["router_port"])
        _register_description_types(session.store, Path(args.definitions))
    client = sdk.ROS2ServiceClient(
        args.name, args.type, node_name="sdk_client", timeout=args.timeout, **where
    )
    store = sdk.ZenohSession.get_instance(where["router_ip"], where["router_port"]).store
    alias_nested_types(store, args.type.split("/")[0])
    emit("HASH", args.type, client.type_hash)
    deadline = time.monotonic() + 30
    while _server_count(sdk, where, args.name)[0] == 0:
        if time.monotonic() > deadline or stop.is_set():
            emit(json.dumps({"no_server": args.name}))
            break
        time.sleep(0.1)
    emit("READY")
    for request in json.loads(args.requests):
        seen = len(errors.texts)
        response = client.call(**request)
        if response is not None:
            emit(json.dumps({"response": plain(response)}))
        else:
            text = errors.texts[seen] if len(errors.texts) > seen else None
            emit(json.dumps({"error": text}))
    emit("DONE")
    return client


def _discover(sdk: Any, where: dict[str, Any], name: str, stop: Any) -> None:
    """Print the sdk's view of ``name``'s servers whenever it changes."""
    last: tuple[int, list[str]] | None = None
    while not stop.is_set():
        now = _server_count(sdk, where, name)
        if now != last:
            last = now
            emit(json.dumps({"servers": now[0], "types": now[1]}))
        time.sleep(0.1)


def _params_node(sdk: Any, where: dict[str, Any]) -> list[Any]:
    """``/sdk_params``: three parameters behind the rcl_interfaces services."""
    import numpy as np

    values: dict[str, Any] = {"speed": 0.5, "name": "robot", "enabled": True}
    lock = threading.Lock()
    servers: list[Any] = []
    store = sdk.ZenohSession.get_instance(where["router_ip"], where["router_port"]).store

    def value_msg(value: Any) -> Any:
        cls = store.types["rcl_interfaces/msg/ParameterValue"]
        fields: dict[str, Any] = {
            "type": 0,
            "bool_value": False,
            "integer_value": 0,
            "double_value": 0.0,
            "string_value": "",
            "byte_array_value": np.zeros(0, np.uint8),
            "bool_array_value": np.zeros(0, np.bool_),
            "integer_array_value": np.zeros(0, np.int64),
            "double_array_value": np.zeros(0, np.float64),
            "string_array_value": [],
        }
        if isinstance(value, bool):
            fields.update(type=1, bool_value=value)
        elif isinstance(value, int):
            fields.update(type=2, integer_value=value)
        elif isinstance(value, float):
            fields.update(type=3, double_value=value)
        elif isinstance(value, str):
            fields.update(type=4, string_value=value)
        return cls(**fields)

    def from_msg(msg: Any) -> Any:
        return {
            1: msg.bool_value,
            2: msg.integer_value,
            3: msg.double_value,
            4: msg.string_value,
        }.get(int(msg.type))

    def get(request: Any) -> Any:
        with lock:
            found = [
                value_msg(values[n]) if n in values else value_msg(None) for n in request.names
            ]
        return servers[0].response_msg_class(values=found)

    def list_(request: Any) -> Any:
        result_cls = store.types["rcl_interfaces/msg/ListParametersResult"]
        with lock:
            names = sorted(values)
        return servers[1].response_msg_class(result=result_cls(names=names, prefixes=[]))

    def set_(request: Any) -> Any:
        result_cls = store.types["rcl_interfaces/msg/SetParametersResult"]
        results = []
        with lock:
            for param in request.parameters:
                if param.name == "readonly":
                    results.append(result_cls(successful=False, reason="read-only"))
                    continue
                values[param.name] = from_msg(param.value)
                results.append(result_cls(successful=True, reason=""))
        return servers[2].response_msg_class(results=results)

    for service, srv_type, handler in (
        ("get_parameters", "GetParameters", get),
        ("list_parameters", "ListParameters", list_),
        ("set_parameters", "SetParameters", set_),
    ):
        servers.append(
            sdk.ROS2ServiceServer(
                f"/sdk_params/{service}",
                f"rcl_interfaces/srv/{srv_type}",
                handler,
                node_name="sdk_params",
                **where,
            )
        )
    alias_nested_types(store, "rcl_interfaces")
    return servers


def alias_nested_types(store: Any, package: str) -> None:
    """The sdk (0.1.8) serializes a service's nested types of its own
    package as ``<pkg>/srv/msg/<T>`` without registering that name."""
    for name, fields in list(store.fielddefs.items()):
        if name.startswith(f"{package}/msg/"):
            alias = name.replace("/msg/", "/srv/msg/", 1)
            if alias not in store.fielddefs:
                store.register({alias: fields})


_DTYPES = {
    "bool": "bool",
    "byte": "uint8",
    "char": "uint8",
    "int8": "int8",
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "int32": "int32",
    "uint32": "uint32",
    "int64": "int64",
    "uint64": "uint64",
    "float32": "float32",
    "float64": "float64",
}


def _value(store: Any, desc: Any, value: Any) -> Any:
    """One field's value for the sdk's rosbags classes, from JSON."""
    import numpy as np
    from rosbags.interfaces import Nodetype

    node, arg = desc
    if node == Nodetype.BASE:
        base = arg[0]
        if value is not None:
            return value
        return (
            "" if base == "string" else False if base == "bool" else 0.0 if "float" in base else 0
        )
    if node == Nodetype.NAME:
        return build(store, arg, value or {})
    inner, size = arg
    items = value if value is not None else ([None] * size if node == Nodetype.ARRAY else [])
    if inner[0] == Nodetype.BASE and inner[1][0] in _DTYPES:
        zero = _value(store, inner, None)
        return np.array([zero if v is None else v for v in items], _DTYPES[inner[1][0]])
    return [_value(store, inner, v) for v in items]


def build(store: Any, type_name: str, values: dict[str, Any]) -> Any:
    """A message of ``type_name`` from the sdk's store with ``values`` (JSON
    data; missing fields zero)."""
    _consts, fields = store.fielddefs[type_name]
    return store.types[type_name](**{n: _value(store, d, values.get(n)) for n, d in fields})


def official_hash(args: Any, type_name: str | None = None) -> str | None:
    """The official hash of a type outside the packages the tests use as is
    (std_msgs, geometry_msgs, ...: None, the sdk's own): from its
    share/*.json, as an rclcpp node would announce it (the sdk 0.1.8
    computes another one for some test_msgs types)."""
    name = type_name or args.type
    if not name.startswith("test_msgs/"):
        return None
    path = Path(args.definitions) / f"{name}.json"
    return str(json.loads(path.read_text())["type_hashes"][0]["hash_string"])


def _register_description_types(store: Any, share: Path) -> None:
    """type_description_interfaces' messages, parsed by rosbags (the sdk
    0.1.8 cannot resolve their bounded strings by itself)."""
    from rosbags.typesys import get_types_from_msg

    for name in ("FieldType", "Field", "IndividualTypeDescription", "TypeDescription"):
        full = f"type_description_interfaces/msg/{name}"
        if full not in store.fielddefs:
            text = (share / f"{full}.msg").read_text()
            store.register(get_types_from_msg(text, full))


def _describer(sdk: Any, where: dict[str, Any], node: str, args: Any) -> Any:
    """``/<node>/get_type_description``, answered from the official files
    (see the module docstring)."""
    share = Path(args.definitions)
    store = sdk.ZenohSession.get_instance(where["router_ip"], where["router_port"]).store
    _register_description_types(store, share)
    td = "type_description_interfaces/msg/"
    holder: list[Any] = []

    def individual(raw: dict[str, Any]) -> Any:
        fields = [
            store.types[td + "Field"](
                name=f["name"],
                type=store.types[td + "FieldType"](**f["type"]),
                default_value=f.get("default_value", ""),
            )
            for f in raw["fields"]
        ]
        return store.types[td + "IndividualTypeDescription"](
            type_name=raw["type_name"], fields=fields
        )

    def answer(request: Any) -> Any:
        response = holder[0].response_msg_class
        path = share / f"{request.type_name}.json"
        if not path.is_file():
            return _failure(response, store, f"unknown type {request.type_name}")
        document = json.loads(path.read_text())
        description = document["type_description_msg"]
        if args.describe_wrong:
            description["type_description"]["fields"][0]["name"] += "_altered"
        sources = []
        if request.include_type_sources:
            names = [description["type_description"]["type_name"]] + [
                r["type_name"] for r in description["referenced_type_descriptions"]
            ]
            for name in names:
                kind = name.split("/")[1]
                text_path = share / f"{name}.{kind}"
                if text_path.is_file():
                    sources.append(
                        store.types[td + "TypeSource"](
                            type_name=name, encoding=kind, raw_file_contents=text_path.read_text()
                        )
                    )
        emit("DESCRIBED", request.type_name)
        return response(
            successful=True,
            failure_reason="",
            type_description=store.types[td + "TypeDescription"](
                type_description=individual(description["type_description"]),
                referenced_type_descriptions=[
                    individual(r) for r in description["referenced_type_descriptions"]
                ],
            ),
            type_sources=sources,
            extra_information=[],
        )

    server = sdk.ROS2ServiceServer(
        f"/{node}/get_type_description",
        "type_description_interfaces/srv/GetTypeDescription",
        answer,
        node_name=node,
        mode="queue" if args.describe_silent else "callback",
        **where,
    )
    holder.append(server)
    alias_nested_types(store, "type_description_interfaces")
    return server


def _failure(response: Any, store: Any, reason: str) -> Any:
    return response(
        successful=False,
        failure_reason=reason,
        type_description=build(store, "type_description_interfaces/msg/TypeDescription", {}),
        type_sources=[],
        extra_information=[],
    )


class SdkNode:
    """One role in its own process (a context manager): ``.hashes`` (type ->
    hash the sdk computed), ``.messages(timeout)`` (the listener's messages
    so far, as dicts), ``.stop()`` (stdin closed, then terminate, then kill)."""

    def __init__(self, router: str, domain: int, definitions: Path, role: str, *args: str) -> None:
        from peers.rosbridge import _die_with_parent

        self.hashes: dict[str, str] = {}
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._received: list[dict[str, Any]] = []
        self._described: list[str] = []
        self._done = False
        self._errors: list[str] = []
        self._proc = subprocess.Popen(
            [
                sys.executable,
                __file__,
                "--router",
                router,
                "--domain",
                str(domain),
                "--definitions",
                str(definitions),
                role,
                *args,
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=_die_with_parent,
        )
        self._readers = [
            threading.Thread(target=self._read, daemon=True),
            threading.Thread(target=self._read_errors, daemon=True),
        ]
        for reader in self._readers:
            reader.start()
        deadline = time.monotonic() + 30
        while True:
            line = self._next(deadline)
            if line == "READY":
                break
            if line.startswith("HASH "):
                _, type_name, hash_ = line.split()
                self.hashes[type_name] = hash_

    def _read(self) -> None:
        assert self._proc.stdout is not None
        for line in self._proc.stdout:
            self._lines.put(line.rstrip("\n"))
        self._lines.put(None)

    def _read_errors(self) -> None:
        assert self._proc.stderr is not None
        for line in self._proc.stderr:
            self._errors.append(line)
            del self._errors[:-200]

    def _next(self, deadline: float) -> str:
        try:
            line = self._lines.get(timeout=max(deadline - time.monotonic(), 0.0))
        except queue.Empty:
            raise RuntimeError(f"sdk node: no output in time; stderr: {self.stderr()}") from None
        if line is None:
            raise RuntimeError(f"sdk node exited ({self._proc.poll()}); stderr: {self.stderr()}")
        return line

    def stderr(self) -> str:
        return "".join(self._errors)[-3000:]

    def _drain(self) -> None:
        while True:
            try:
                line = self._lines.get_nowait()
            except queue.Empty:
                break
            if line is None:
                continue
            if line.startswith("{"):
                self._received.append(json.loads(line))
            elif line == "DONE":
                self._done = True
            elif line.startswith("DESCRIBED "):
                self._described.append(line.split(" ", 1)[1])

    def messages(self) -> list[dict[str, Any]]:
        """Every message the listener has printed so far."""
        self._drain()
        return [r["msg"] for r in self._received if "msg" in r]

    def records(self) -> list[dict[str, Any]]:
        """Every other JSON line printed so far (a client's answers, the
        discoverer's views), in order."""
        self._drain()
        return [r for r in self._received if "msg" not in r]

    @property
    def done(self) -> bool:
        """Whether a client printed ``DONE`` (every call answered or timed out)."""
        self._drain()
        return self._done

    def described(self) -> list[str]:
        """The types the node's get_type_description answered so far."""
        self.messages()
        return list(self._described)

    def stop(self) -> int | None:
        from peers._process import end_process  # this file also runs as a script

        return end_process(self._proc, grace=10, readers=self._readers)

    def __enter__(self) -> SdkNode:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
