"""zenoh-ros2-sdk nodes: an rmw_zenoh implementation this project did not
write, as the peer of the Zenoh tests. One process runs one role:

    python tests/peers/zenoh_sdk_node.py --router tcp/127.0.0.1:7447 --domain 5 \\
        --definitions <ROS share dir> talker --topic /chatter --count 100

Roles: ``talker`` (``std_msgs/msg/String`` "hello N"), ``listener`` (one JSON
line ``{"msg": {...}}`` per message, any type), ``service``
(``std_srvs/srv/SetBool``: success = data, message "set to <data>"),
``add_two_ints`` (``example_interfaces/srv/AddTwoInts``: sum = a + b) and
``params`` (node ``/sdk_params``: its ``get_parameters``, ``set_parameters``
and ``list_parameters`` services over three parameters). Each prints
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
    parser.add_argument("role", choices=["talker", "listener", "service", "add_two_ints", "params"])
    parser.add_argument("--topic", default="/chatter")
    parser.add_argument("--type", default="std_msgs/msg/String")
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--count", type=int, default=0, help="0: until stopped")
    parser.add_argument("--name", default="/sdk_set_bool")
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
    elif args.role == "add_two_ints":
        adders: list[Any] = []

        def add(request: Any) -> Any:
            return adders[0].response_msg_class(sum=int(request.a) + int(request.b))

        adder = sdk.ROS2ServiceServer(
            args.name, "example_interfaces/srv/AddTwoInts", add, node_name="sdk_adder", **where
        )
        adders.append(adder)
        closers.append(adder)
        emit("HASH", "example_interfaces/srv/AddTwoInts", adder.type_hash)
        emit("READY")
    else:
        closers.extend(_params_node(sdk, where))
        emit("READY")
    stop.wait()
    for closer in closers:
        closer.close()
    return 0


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

    def messages(self) -> list[dict[str, Any]]:
        """Every message the listener has printed so far."""
        while True:
            try:
                line = self._lines.get_nowait()
            except queue.Empty:
                break
            if line and line.startswith("{"):
                self._received.append(json.loads(line)["msg"])
        return list(self._received)

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
