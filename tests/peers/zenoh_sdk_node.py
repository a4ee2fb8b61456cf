"""zenoh-ros2-sdk nodes: an rmw_zenoh implementation this project did not
write, as the peer of the Zenoh tests. One process runs one role:

    python tests/peers/zenoh_sdk_node.py --router tcp/127.0.0.1:7447 --domain 5 \\
        --definitions <ROS share dir> talker --topic /chatter --count 100

Roles: ``talker`` (``std_msgs/msg/String`` "hello N"), ``listener`` (one JSON
line ``{"msg": {...}}`` per message, any type), ``service``
(``std_srvs/srv/SetBool``: success = data, message "set to <data>") and
``params`` (node ``/sdk_params``: its ``get_parameters``, ``set_parameters``
and ``list_parameters`` services over three parameters), ``client`` (a
``ROS2ServiceClient`` of ``--name`` / ``--type`` that waits until the sdk's
discovery shows a server, then calls it once per request of ``--requests``,
a JSON list, printing one JSON line per call: ``{"response": {...}}``, or
``{"error": "<text>"}`` for an error reply, or ``{"error": null}`` for no
reply in time; then ``DONE``) and ``discover`` (one JSON line
``{"servers": N, "types": [...]}`` whenever the sdk's
``get_service_info(--name)`` changes). Each prints
``HASH <type> <RIHS01 hash>`` for the hash the sdk computed, then ``READY``,
and runs until stdin closes.

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
    parser.add_argument("--requests", default="[]", help="client: a JSON list of requests")
    parser.add_argument("--timeout", type=float, default=10.0, help="client: per call")
    args = parser.parse_args(argv)

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
        pub = sdk.ROS2Publisher(args.topic, args.type, node_name="sdk_talker", **where)
        closers.append(pub)
        emit("HASH", args.type, pub.type_hash)
        emit("READY")
        sent = 0
        while not stop.is_set() and (args.count == 0 or sent < args.count):
            pub.publish(data=f"hello {sent}")
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

        def set_bool(request: Any) -> Any:
            server = holder[0]
            return server.response_msg_class(
                success=bool(request.data), message=f"set to {bool(request.data)}"
            )

        server = sdk.ROS2ServiceServer(
            args.name, "std_srvs/srv/SetBool", set_bool, node_name="sdk_service", **where
        )
        holder.append(server)
        closers.append(server)
        emit("HASH", "std_srvs/srv/SetBool", server.type_hash)
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
    client = sdk.ROS2ServiceClient(
        args.name, args.type, node_name="sdk_client", timeout=args.timeout, **where
    )
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

    def alias_nested_types() -> None:
        # the sdk (0.1.8) serializes a service's nested types of its own
        # package as "<pkg>/srv/msg/<T>" without registering that name
        for name, fields in list(store.fielddefs.items()):
            if name.startswith("rcl_interfaces/msg/"):
                alias = name.replace("/msg/", "/srv/msg/", 1)
                if alias not in store.fielddefs:
                    store.register({alias: fields})

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
    alias_nested_types()
    return servers


class SdkNode:
    """One role in its own process (a context manager): ``.hashes`` (type ->
    hash the sdk computed), ``.messages(timeout)`` (the listener's messages
    so far, as dicts), ``.stop()`` (stdin closed, then terminate, then kill)."""

    def __init__(self, router: str, domain: int, definitions: Path, role: str, *args: str) -> None:
        from peers.rosbridge import _die_with_parent

        self.hashes: dict[str, str] = {}
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._received: list[dict[str, Any]] = []
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
