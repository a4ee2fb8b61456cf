"""A simulated differential-drive robot served by the official Foxglove SDK WebSocket server.

The robot is what ``rmb demo`` drives, and what ``rmb demo --serve`` exposes to other tools
(the Foxglove app, other clients). Everything runs in-process: :meth:`DemoRobot.start` starts a
Foxglove server on loopback (with its own :class:`foxglove.Context`, so it never mixes with other
users of the SDK's global context) plus one simulation thread, and :meth:`DemoRobot.stop` tears
both down again.

**Safety: the robot's own cmd_vel watchdog.** A velocity command is only obeyed for
:data:`CMD_VEL_TIMEOUT_S` (0.5 s) after it arrives. If no newer command arrives in time, the
robot stops by itself (``/status`` then reports ``mode == "watchdog_stop"``). This is how real
robot bases behave, and it is the safety point the library's documentation makes: a client that
crashes, loses its link or simply stops publishing must not leave a robot driving. Clients that
drive the robot therefore re-send their command periodically (for example at 10 Hz), and send a
zero Twist when they are done so that the robot stops *immediately* rather than after the
watchdog timeout.
"""

from __future__ import annotations

import collections
import errno
import json
import logging
import math
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np

try:
    import foxglove
    from foxglove import (
        Channel,
        Context,
        MessageSchema,
        Parameter,
        ParameterType,
        Schema,
        Service,
        ServiceRequest,
        ServiceSchema,
    )
    from foxglove.websocket import (
        Capability,
        ChannelView,
        Client,
        ClientChannel,
        PlaybackControlRequest,
        PlaybackState,
        WebSocketServer,
    )
except ImportError as exc:  # pragma: no cover - depends on the installed extras
    raise ImportError(
        "the demo robot needs the Foxglove SDK: pip install 'ros-mobile-bridge[demo]'"
    ) from exc

from rosbags.interfaces.typing import Typesdict
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore
from rosbags.typesys.stores import ros2_jazzy as _jazzy

from ._assets import connection_graph, serve_asset
from ._png import CameraRenderer

__all__ = [
    "CMD_VEL_TIMEOUT_S",
    "CMD_VEL_TOPICS",
    "SERVICES",
    "TOPICS",
    "CmdVel",
    "DemoRobot",
]

_log = logging.getLogger("ros_mobile_bridge.demo")

# Typed message classes of rosbags' bundled ROS 2 Jazzy store.
Time = _jazzy.builtin_interfaces__msg__Time
Point = _jazzy.geometry_msgs__msg__Point
Pose = _jazzy.geometry_msgs__msg__Pose
PoseStamped = _jazzy.geometry_msgs__msg__PoseStamped
PoseWithCovariance = _jazzy.geometry_msgs__msg__PoseWithCovariance
Quaternion = _jazzy.geometry_msgs__msg__Quaternion
Twist = _jazzy.geometry_msgs__msg__Twist
TwistStamped = _jazzy.geometry_msgs__msg__TwistStamped
TwistWithCovariance = _jazzy.geometry_msgs__msg__TwistWithCovariance
Vector3 = _jazzy.geometry_msgs__msg__Vector3
Odometry = _jazzy.nav_msgs__msg__Odometry
BatteryState = _jazzy.sensor_msgs__msg__BatteryState
CompressedImage = _jazzy.sensor_msgs__msg__CompressedImage
Header = _jazzy.std_msgs__msg__Header

CMD_VEL_TIMEOUT_S: Final = 0.5
"""The robot's own cmd_vel watchdog: a command older than this (seconds) is treated as zero."""

TOPICS: Final[dict[str, str]] = {
    "/odom": "nav_msgs/msg/Odometry",
    "/pose": "geometry_msgs/msg/PoseStamped",
    "/battery": "sensor_msgs/msg/BatteryState",
    "/camera/image/compressed": "sensor_msgs/msg/CompressedImage",
    "/status": "rmb_demo/Status",
}
"""Topics the robot publishes, and their schema names (``/status`` is JSON, the rest CDR)."""

SERVICES: Final[dict[str, str]] = {
    "/reset_odometry": "std_srvs/srv/Trigger",
    "/set_led": "std_srvs/srv/SetBool",
}
"""Services the robot offers (CDR requests and responses), and their service types."""

CMD_VEL_TOPICS: Final[dict[str, str]] = {
    "/cmd_vel": "geometry_msgs/msg/Twist",
    "/cmd_vel_stamped": "geometry_msgs/msg/TwistStamped",
}
"""Topics the robot accepts velocity commands on (client-published, ``cdr`` or ``json``)."""

_ODOM_FRAME: Final = "odom"
_BASE_FRAME: Final = "base_link"
_STATUS_HZ: Final = 2.0
_BATTERY_HZ: Final = 1.0
_BATTERY_IDLE_DRAIN_PER_S: Final = 0.0001
_BATTERY_MOTION_DRAIN_PER_M: Final = 0.0004
_BATTERY_FLOOR: Final = 0.05

_SRV_MSGDEFS: Final[dict[str, str]] = {
    # ROS 2 empty messages carry one dummy uint8 on the wire; the .srv text is empty, though.
    "std_srvs/srv/Trigger_Request": "",
    "std_srvs/srv/Trigger_Response": "bool success\nstring message\n",
    "std_srvs/srv/SetBool_Request": "bool data\n",
    "std_srvs/srv/SetBool_Response": "bool success\nstring message\n",
}

_STATUS_JSONSCHEMA: Final[dict[str, object]] = {
    "title": "rmb_demo/Status",
    "type": "object",
    "properties": {
        "mode": {
            "type": "string",
            "enum": ["idle", "driving", "watchdog_stop"],
            "description": "idle: no or zero command; driving: obeying a fresh command; "
            "watchdog_stop: the last command was non-zero but is older than the watchdog timeout",
        },
        "uptime_s": {"type": "number"},
        "speed": {"type": "number", "description": "applied |linear.x| in m/s"},
        "linear_x": {"type": "number"},
        "angular_z": {"type": "number"},
        "battery_percentage": {"type": "number", "minimum": 0, "maximum": 1},
        "led": {"type": "boolean"},
        "cmd_vel_count": {"type": "integer"},
        "watchdog_timeout_s": {"type": "number"},
    },
    "required": ["mode", "uptime_s", "speed"],
}


def _make_typestore() -> Typestore:
    """Jazzy typestore plus the two std_srvs service types the robot serves."""
    store = get_typestore(Stores.ROS2_JAZZY)
    extra: Typesdict = {}
    for name, text in _SRV_MSGDEFS.items():
        # ROS 2 serialises an empty message as a single dummy uint8.
        wire_text = text or "uint8 structure_needs_at_least_one_member\n"
        # get_types_from_msg wants a msg-style name; re-key the single result to the srv name.
        (fielddef,) = get_types_from_msg(wire_text, "rmb_demo/msg/Tmp").values()
        extra[name] = fielddef
    store.register(extra)
    return store


_TYPESTORE: Final = _make_typestore()


def _serialize(message: object, typename: str) -> bytes:
    return bytes(_TYPESTORE.serialize_cdr(message, typename, little_endian=True))


def _ros2msg_schema(typename: str) -> Schema:
    """``ros2msg`` schema: the type's .msg text followed by its dependencies' definitions."""
    text, _ = _TYPESTORE.generate_msgdef(typename, ros_version=2)
    return Schema(name=typename, encoding="ros2msg", data=text.encode())


def _srv_schema(service_type: str) -> ServiceSchema:
    def part(suffix: str) -> MessageSchema:
        name = f"{service_type}_{suffix}"
        schema = Schema(name=name, encoding="ros2msg", data=_SRV_MSGDEFS[name].encode())
        return MessageSchema(encoding="cdr", schema=schema)

    return ServiceSchema(name=service_type, request=part("Request"), response=part("Response"))


def _stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _quat_from_yaw(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def _wrap_angle(angle: float) -> float:
    """``angle`` in (-pi, pi]; returned unchanged (bit for bit) when already in range."""
    if -math.pi < angle <= math.pi:
        return angle
    wrapped = math.atan2(math.sin(angle), math.cos(angle))
    return math.pi if wrapped <= -math.pi else wrapped


def _diag6(value: float) -> np.ndarray[tuple[int], np.dtype[np.float64]]:
    cov = np.zeros(36, dtype=np.float64)
    cov[::7] = value
    return cov


def _to_parameter(name: str, value: object) -> Parameter:
    if isinstance(value, float):
        return Parameter(name, value=value, type=ParameterType.Float64)
    if isinstance(value, (bool, int, str)):
        return Parameter(name, value=value)
    return Parameter(name)


@dataclass(frozen=True)
class CmdVel:
    """One velocity command received by the robot.

    ``linear_x`` (m/s) and ``angular_z`` (rad/s) are the values as sent (before the robot's
    ``max_speed`` clamp). ``receive_time_ns`` is the robot's wall-clock time (``time.time_ns()``)
    at reception, ``encoding`` the client channel's message encoding (``"cdr"`` or ``"json"``).
    """

    linear_x: float
    angular_z: float
    receive_time_ns: int
    encoding: str


@dataclass(frozen=True)
class _ClientTopic:
    topic: str
    encoding: str
    schema_name: str


class DemoRobot:
    """A simulated differential-drive robot behind a Foxglove SDK WebSocket server.

    Published (``cdr`` with ``ros2msg`` schemas generated from rosbags' ROS 2 Jazzy typestore,
    except ``/status`` which is ``json`` with a ``jsonschema`` schema):

    * ``/odom`` ``nav_msgs/msg/Odometry`` at ``rate_hz``: pose integrated from the last velocity
      command with unicycle kinematics; twist is the applied velocity.
    * ``/pose`` ``geometry_msgs/msg/PoseStamped`` at ``rate_hz``.
    * ``/battery`` ``sensor_msgs/msg/BatteryState`` at 1 Hz, slowly draining (never below 5 %).
    * ``/camera/image/compressed`` ``sensor_msgs/msg/CompressedImage`` (160x120 PNG, top-down
      view with a dot at the robot's position) at ``camera_hz`` (capped at ``rate_hz``).
    * ``/status`` ``rmb_demo/Status`` (JSON) at 2 Hz: mode, uptime_s, speed, ...

    Accepted from clients (capability ``clientPublish``, encodings ``cdr`` and ``json``):
    ``/cmd_vel`` ``geometry_msgs/msg/Twist`` and ``/cmd_vel_stamped``
    ``geometry_msgs/msg/TwistStamped``. Each one is appended to :attr:`cmd_vel_log`. Commands
    are obeyed for :data:`CMD_VEL_TIMEOUT_S` only (the robot's own watchdog, see the module
    docstring); ``|linear_x|`` is clamped to the ``max_speed`` parameter.

    Services (``cdr``): ``/reset_odometry`` ``std_srvs/srv/Trigger`` (pose back to zero, answers
    ``success=True, message="odometry reset"``) and ``/set_led`` ``std_srvs/srv/SetBool``
    (answers ``success=True, message="led on"/"led off"``, updates the ``led`` parameter).

    Parameters: ``max_speed`` (float, m/s, default 1.0), ``robot_name`` (str, default ``name``),
    ``led`` (bool). Setting a known parameter to a value of the wrong type leaves it unchanged
    (the reply shows the kept value); unknown names are stored as given. Changes are published
    to clients subscribed to parameter updates.

    The server also broadcasts its time every tick (capability ``time``).

    All public methods and properties are thread-safe. Use as a context manager, or call
    :meth:`start` and :meth:`stop`; the robot can be restarted after a stop (its pose, log and
    parameters persist).
    """

    def __init__(
        self,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        rate_hz: float = 20.0,
        camera_hz: float = 5.0,
        name: str = "rmb-demo-robot",
        max_log: int = 100_000,
    ) -> None:
        """Configure the robot; nothing starts until :meth:`start`.

        ``port=0`` picks a free ephemeral port. ``max_log`` bounds :attr:`cmd_vel_log` (the
        oldest entries are dropped beyond it). Raises :class:`ValueError` for non-positive
        rates, a port outside 0..65535 or a non-positive ``max_log``.
        """
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be a positive number, got {rate_hz!r}")
        if not (math.isfinite(camera_hz) and camera_hz > 0):
            raise ValueError(f"camera_hz must be a positive number, got {camera_hz!r}")
        if not 0 <= port <= 65535:
            raise ValueError(f"port must be in 0..65535, got {port!r}")
        if max_log <= 0:
            raise ValueError(f"max_log must be positive, got {max_log!r}")
        self._host = host
        self._requested_port = port
        self._rate_hz = float(rate_hz)
        self._camera_hz = float(camera_hz)
        self._name = name

        # Lifecycle (start/stop) is serialised by its own lock; simulation state by _lock.
        self._lifecycle_lock = threading.Lock()
        self._lock = threading.Lock()
        self._stop_event = threading.Event()
        self._thread: threading.Thread | None = None
        self._server: WebSocketServer | None = None
        self._context: Context | None = None
        self._channels: dict[str, Channel] = {}
        self._port: int | None = None

        self._x = 0.0
        self._y = 0.0
        self._yaw = 0.0
        self._applied = (0.0, 0.0)
        self._battery = 1.0
        self._last_cmd: CmdVel | None = None
        self._last_cmd_mono = 0.0
        self._cmd_vel_log: collections.deque[CmdVel] = collections.deque(maxlen=max_log)
        self._cmd_vel_count = 0
        self._client_topics: dict[tuple[int, int], _ClientTopic] = {}
        self._parameters: dict[str, object] = {
            "max_speed": 1.0,
            "robot_name": name,
            "led": False,
        }
        self._start_mono = time.monotonic()

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> int:
        """Start the Foxglove server and the simulation thread; return the bound port.

        Raises :class:`RuntimeError` if the robot is already running, and whatever the SDK raises
        if the server cannot bind (nothing is left running in that case).
        """
        with self._lifecycle_lock:
            if self._server is not None:
                raise RuntimeError("DemoRobot is already running")
            context = Context()
            channels = {
                topic: Channel(
                    topic,
                    message_encoding="cdr",
                    schema=_ros2msg_schema(typename),
                    context=context,
                )
                for topic, typename in TOPICS.items()
                if topic != "/status"
            }
            channels["/status"] = Channel(
                "/status",
                message_encoding="json",
                schema=Schema(
                    name=TOPICS["/status"],
                    encoding="jsonschema",
                    data=json.dumps(_STATUS_JSONSCHEMA).encode(),
                ),
                context=context,
            )
            services = [
                Service(
                    "/reset_odometry",
                    schema=_srv_schema(SERVICES["/reset_odometry"]),
                    handler=self._handle_reset_odometry,
                ),
                Service(
                    "/set_led",
                    schema=_srv_schema(SERVICES["/set_led"]),
                    handler=self._handle_set_led,
                ),
            ]
            try:
                server = foxglove.start_server(
                    name=self._name,
                    host=self._host,
                    port=self._requested_port,
                    capabilities=[
                        Capability.ClientPublish,
                        Capability.Services,
                        Capability.Parameters,
                        Capability.Time,
                        Capability.ConnectionGraph,
                    ],
                    server_listener=_Listener(
                        advertise=self._on_client_advertise,
                        unadvertise=self._on_client_unadvertise,
                        message=self._on_message_data,
                        get_parameters=self._get_parameters,
                        set_parameters=self._set_parameters,
                    ),
                    supported_encodings=["json", "cdr"],
                    services=services,
                    asset_handler=serve_asset,
                    context=context,
                )
                server.publish_connection_graph(connection_graph(TOPICS, CMD_VEL_TOPICS, SERVICES))
            except BaseException:
                for channel in channels.values():
                    channel.close()
                raise
            # Keep the Context referenced: when its Python object is garbage-collected the SDK
            # closes every channel created on it, even though the server is still running.
            self._context = context
            self._server = server
            self._channels = channels
            self._port = server.port
            self._stop_event.clear()
            with self._lock:
                self._start_mono = time.monotonic()
            thread = threading.Thread(
                target=self._run, name=f"{self._name}-sim", args=(server, channels)
            )
            self._thread = thread
            thread.start()
            _log.info("demo robot %r serving on %s", self._name, self.url)
            return server.port

    def stop(self) -> None:
        """Stop the simulation thread (joined), close the channels and stop the server.

        When this returns, the port no longer accepts connections (waits up to 2 s for the
        SDK's asynchronous shutdown). Idempotent, and a no-op if the robot was never started.
        """
        with self._lifecycle_lock:
            self._stop_event.set()
            thread, self._thread = self._thread, None
            if thread is not None:
                thread.join()
            channels, self._channels = self._channels, {}
            for channel in channels.values():
                channel.close()
            server, self._server = self._server, None
            if server is not None and self._port is not None:
                server.stop()
                # WebSocketServer.stop() returns before the listening socket is closed (and
                # server.port reads 0 afterwards, hence self._port).
                _wait_port_released(self._host, self._port, timeout=2.0)
            self._context = None
            with self._lock:
                self._client_topics.clear()

    def __enter__(self) -> DemoRobot:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ public state

    @property
    def running(self) -> bool:
        """Whether the server and simulation thread are running."""
        return self._server is not None

    @property
    def port(self) -> int:
        """The bound TCP port (still readable after :meth:`stop`).

        Raises :class:`RuntimeError` if the robot was never started.
        """
        if self._port is None:
            raise RuntimeError("DemoRobot has not been started")
        return self._port

    @property
    def url(self) -> str:
        """``ws://HOST:PORT`` to connect to (``127.0.0.1`` if bound to all interfaces)."""
        host = self._host
        if host in ("", "0.0.0.0"):
            host = "127.0.0.1"
        elif host == "::":
            host = "::1"
        if ":" in host:
            host = f"[{host}]"
        return f"ws://{host}:{self.port}"

    @property
    def foxglove_app_url(self) -> str | None:
        """A Foxglove app link that opens this robot as a data source (None when not running)."""
        server = self._server
        return server.app_url() if server is not None else None

    @property
    def cmd_vel_log(self) -> list[CmdVel]:
        """A copy of the velocity commands received so far, oldest first."""
        return self.received_cmd_vel()

    def received_cmd_vel(self) -> list[CmdVel]:
        """A copy of the velocity commands received so far, oldest first."""
        with self._lock:
            return list(self._cmd_vel_log)

    @property
    def pose(self) -> tuple[float, float, float]:
        """Snapshot of ``(x, y, yaw)`` in the odom frame (metres, radians in (-pi, pi])."""
        with self._lock:
            return (self._x, self._y, self._yaw)

    @property
    def parameters(self) -> dict[str, object]:
        """A copy of the current parameters."""
        with self._lock:
            return dict(self._parameters)

    @property
    def battery(self) -> float:
        """Battery charge in [0, 1]."""
        with self._lock:
            return self._battery

    @property
    def led(self) -> bool:
        """The LED state (the ``led`` parameter)."""
        with self._lock:
            return bool(self._parameters.get("led", False))

    # ------------------------------------------------------------------ simulation

    def _run(self, server: WebSocketServer, channels: dict[str, Channel]) -> None:
        period = 1.0 / self._rate_hz
        camera_period = 1.0 / self._camera_hz
        renderer = CameraRenderer()
        now = time.monotonic()
        last = now
        next_tick = now
        next_camera = now
        next_battery = now
        next_status = now
        while not self._stop_event.is_set():
            now = time.monotonic()
            try:
                self._step(now - last, now)
                wall_ns = time.time_ns()
                server.broadcast_time(wall_ns)
                self._publish_motion(channels, wall_ns)
                if now >= next_battery:
                    next_battery = now + 1.0 / _BATTERY_HZ
                    self._publish_battery(channels, wall_ns)
                if now >= next_status:
                    next_status = now + 1.0 / _STATUS_HZ
                    self._publish_status(channels, wall_ns, now)
                if now >= next_camera:
                    next_camera = now + camera_period
                    self._publish_camera(channels, wall_ns, renderer)
            except Exception:
                _log.exception("demo robot simulation step failed")
            last = now
            next_tick += period
            if next_tick < now:  # fell behind (e.g. a paused process): do not try to catch up
                next_tick = now + period
            self._stop_event.wait(max(0.0, next_tick - time.monotonic()))

    def _command(self, now_mono: float) -> tuple[float, float, str]:
        """Applied (linear_x, angular_z) and mode, honouring the watchdog; caller holds _lock."""
        cmd = self._last_cmd
        if cmd is None:
            return 0.0, 0.0, "idle"
        if now_mono - self._last_cmd_mono > CMD_VEL_TIMEOUT_S:
            moving = cmd.linear_x != 0.0 or cmd.angular_z != 0.0
            return 0.0, 0.0, "watchdog_stop" if moving else "idle"
        max_speed = self._parameters.get("max_speed", 1.0)
        limit = float(max_speed) if isinstance(max_speed, (int, float)) else 1.0
        linear = min(max(cmd.linear_x, -limit), limit)
        mode = "driving" if (linear != 0.0 or cmd.angular_z != 0.0) else "idle"
        return linear, cmd.angular_z, mode

    def _step(self, dt: float, now_mono: float) -> None:
        with self._lock:
            v, w, _ = self._command(now_mono)
            self._applied = (v, w)
            if dt > 0:
                mid_yaw = self._yaw + 0.5 * w * dt
                self._x += v * math.cos(mid_yaw) * dt
                self._y += v * math.sin(mid_yaw) * dt
                self._yaw = _wrap_angle(self._yaw + w * dt)
                drain = _BATTERY_IDLE_DRAIN_PER_S * dt + _BATTERY_MOTION_DRAIN_PER_M * abs(v) * dt
                self._battery = max(_BATTERY_FLOOR, self._battery - drain)

    def _publish_motion(self, channels: dict[str, Channel], wall_ns: int) -> None:
        with self._lock:
            x, y, yaw = self._x, self._y, self._yaw
            v, w = self._applied
        header = Header(stamp=_stamp(wall_ns), frame_id=_ODOM_FRAME)
        pose = Pose(position=Point(x=x, y=y, z=0.0), orientation=_quat_from_yaw(yaw))
        odom = Odometry(
            header=header,
            child_frame_id=_BASE_FRAME,
            pose=PoseWithCovariance(pose=pose, covariance=_diag6(0.01)),
            twist=TwistWithCovariance(
                twist=Twist(linear=Vector3(x=v, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=w)),
                covariance=_diag6(0.001),
            ),
        )
        channels["/odom"].log(_serialize(odom, TOPICS["/odom"]), log_time=wall_ns)
        stamped = PoseStamped(header=header, pose=pose)
        channels["/pose"].log(_serialize(stamped, TOPICS["/pose"]), log_time=wall_ns)

    def _publish_battery(self, channels: dict[str, Channel], wall_ns: int) -> None:
        with self._lock:
            charge = self._battery
        msg = BatteryState(
            header=Header(stamp=_stamp(wall_ns), frame_id=_BASE_FRAME),
            voltage=10.5 + 2.1 * charge,  # 3S LiPo
            temperature=25.0,
            current=-1.2,
            charge=5.0 * charge,
            capacity=5.0,
            design_capacity=5.0,
            percentage=charge,
            power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
            power_supply_health=BatteryState.POWER_SUPPLY_HEALTH_GOOD,
            power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO,
            present=True,
            cell_voltage=np.full(3, (10.5 + 2.1 * charge) / 3, dtype=np.float32),
            cell_temperature=np.full(3, 25.0, dtype=np.float32),
            location="base",
            serial_number="RMB-DEMO-0001",
        )
        channels["/battery"].log(_serialize(msg, TOPICS["/battery"]), log_time=wall_ns)

    def _publish_status(self, channels: dict[str, Channel], wall_ns: int, now: float) -> None:
        with self._lock:
            v, w, mode = self._command(now)
            status = {
                "mode": mode,
                "uptime_s": round(now - self._start_mono, 3),
                "speed": abs(v),
                "linear_x": v,
                "angular_z": w,
                "battery_percentage": round(self._battery, 4),
                "led": bool(self._parameters.get("led", False)),
                "cmd_vel_count": self._cmd_vel_count,
                "watchdog_timeout_s": CMD_VEL_TIMEOUT_S,
            }
        channels["/status"].log(json.dumps(status).encode(), log_time=wall_ns)

    def _publish_camera(
        self, channels: dict[str, Channel], wall_ns: int, renderer: CameraRenderer
    ) -> None:
        with self._lock:
            x, y, yaw = self._x, self._y, self._yaw
            led = bool(self._parameters.get("led", False))
        png = renderer.render(x, y, yaw, led=led)
        msg = CompressedImage(
            header=Header(stamp=_stamp(wall_ns), frame_id="camera"),
            format="png",
            data=np.frombuffer(png, dtype=np.uint8),
        )
        channels["/camera/image/compressed"].log(
            _serialize(msg, TOPICS["/camera/image/compressed"]), log_time=wall_ns
        )

    # ------------------------------------------------------------------ services

    def _handle_reset_odometry(self, request: ServiceRequest) -> bytes:
        with self._lock:
            self._x = self._y = self._yaw = 0.0
        response_type = "std_srvs/srv/Trigger_Response"
        response = _TYPESTORE.types[response_type](success=True, message="odometry reset")
        return _serialize(response, response_type)

    def _handle_set_led(self, request: ServiceRequest) -> bytes:
        if request.encoding != "cdr":
            raise ValueError(f"unsupported request encoding {request.encoding!r}")
        data = _TYPESTORE.deserialize_cdr(request.payload, "std_srvs/srv/SetBool_Request")
        state = bool(getattr(data, "data"))  # noqa: B009 - rosbags types are dynamic
        with self._lock:
            self._parameters["led"] = state
        server = self._server
        if server is not None:
            server.publish_parameter_values([_to_parameter("led", state)])
        response_type = "std_srvs/srv/SetBool_Response"
        response = _TYPESTORE.types[response_type](
            success=True, message="led on" if state else "led off"
        )
        return _serialize(response, response_type)

    # ------------------------------------------------------------------ client data

    def _on_client_advertise(self, client_id: int, channel: ClientChannel) -> None:
        with self._lock:
            self._client_topics[(client_id, channel.id)] = _ClientTopic(
                topic=channel.topic, encoding=channel.encoding, schema_name=channel.schema_name
            )

    def _on_client_unadvertise(self, client_id: int, channel_id: int) -> None:
        with self._lock:
            self._client_topics.pop((client_id, channel_id), None)

    def _on_message_data(self, client_id: int, channel_id: int, data: bytes) -> None:
        with self._lock:
            info = self._client_topics.get((client_id, channel_id))
        if info is None:
            _log.warning(
                "message on unknown client channel %d from client %d", channel_id, client_id
            )
            return
        if info.topic not in CMD_VEL_TOPICS:
            _log.debug("ignoring client message on %s", info.topic)
            return
        if info.schema_name:
            stamped = info.schema_name.rsplit("/", 1)[-1] == "TwistStamped"
        else:
            stamped = info.topic == "/cmd_vel_stamped"
        try:
            linear_x, angular_z = _decode_twist(data, info.encoding, stamped=stamped)
        except (ValueError, TypeError, KeyError) as exc:
            _log.warning("dropping undecodable %s message (%s): %s", info.topic, info.encoding, exc)
            return
        cmd = CmdVel(
            linear_x=linear_x,
            angular_z=angular_z,
            receive_time_ns=time.time_ns(),
            encoding=info.encoding,
        )
        with self._lock:
            self._last_cmd = cmd
            self._last_cmd_mono = time.monotonic()
            self._cmd_vel_log.append(cmd)
            self._cmd_vel_count += 1

    # ------------------------------------------------------------------ parameters

    def _get_parameters(self, names: Sequence[str]) -> list[Parameter]:
        with self._lock:
            wanted = names if names else list(self._parameters)
            return [_to_parameter(n, self._parameters[n]) for n in wanted if n in self._parameters]

    def _set_parameters(self, parameters: Sequence[Parameter]) -> list[Parameter]:
        result: list[Parameter] = []
        with self._lock:
            for param in parameters:
                name = param.name
                value = _coerce_parameter(name, param.get_value(), self._parameters.get(name))
                if value is None:
                    self._parameters.pop(name, None)
                    result.append(Parameter(name))
                else:
                    self._parameters[name] = value
                    result.append(_to_parameter(name, value))
        # The SDK itself publishes the returned values to subscribed clients.
        return result


def _wait_port_released(host: str, port: int, *, timeout: float) -> None:
    """Wait until nothing listens on ``(host, port)`` any more (best effort).

    Probes by binding with ``SO_REUSEADDR``, which on Linux, macOS and Windows fails only while a
    listening socket still holds the address; it never connects to the server.
    """
    try:
        infos = socket.getaddrinfo(
            host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )
    except OSError:
        return
    deadline = time.monotonic() + timeout
    for family, kind, proto, _, address in infos:
        while True:
            with socket.socket(family, kind, proto) as probe:
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    probe.bind(address)
                    break
                except OSError as exc:
                    if exc.errno != errno.EADDRINUSE:
                        break
            if time.monotonic() > deadline:
                _log.debug("port %d still in use %.1f s after server stop", port, timeout)
                return
            time.sleep(0.01)


def _coerce_parameter(name: str, value: object, current: object) -> object:
    """The value to store for ``name`` (``None``: delete), keeping ``current`` if invalid."""
    if name == "max_speed":
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            speed = float(value)
            if math.isfinite(speed) and speed >= 0:
                return speed
        return current
    if name == "robot_name":
        return value if isinstance(value, str) else current
    if name == "led":
        return value if isinstance(value, bool) else current
    return value


def _finite(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"expected a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"non-finite velocity {number!r}")
    return number


def _decode_twist(data: bytes, encoding: str, *, stamped: bool) -> tuple[float, float]:
    """``(linear.x, angular.z)`` of a Twist / TwistStamped in ``cdr`` or ``json``."""
    if encoding == "cdr":
        typename = "geometry_msgs/msg/TwistStamped" if stamped else "geometry_msgs/msg/Twist"
        try:
            msg = _TYPESTORE.deserialize_cdr(data, typename)
        except Exception as exc:  # rosbags raises SerdeError, which is not exported stably
            raise ValueError(str(exc)) from exc
        twist = msg.twist if isinstance(msg, TwistStamped) else msg
        if not isinstance(twist, Twist):
            raise TypeError(f"unexpected message {msg!r}")
        return _finite(twist.linear.x), _finite(twist.angular.z)
    if encoding == "json":
        obj = json.loads(data)
        if not isinstance(obj, dict):
            raise TypeError("expected a JSON object")
        if "twist" in obj:
            obj = obj["twist"]
        if not isinstance(obj, dict):
            raise TypeError("expected a JSON object")
        linear = obj.get("linear", {})
        angular = obj.get("angular", {})
        if not isinstance(linear, dict) or not isinstance(angular, dict):
            raise TypeError("linear/angular must be objects")
        return _finite(linear.get("x", 0.0)), _finite(angular.get("z", 0.0))
    raise ValueError(f"unsupported encoding {encoding!r}")


class _Listener:
    """Foxglove ServerListener forwarding to the robot's handlers, which the
    robot hands it. Called from the SDK's threads."""

    def __init__(
        self,
        *,
        advertise: Callable[[int, ClientChannel], None],
        unadvertise: Callable[[int, int], None],
        message: Callable[[int, int, bytes], None],
        get_parameters: Callable[[Sequence[str]], list[Parameter]],
        set_parameters: Callable[[Sequence[Parameter]], list[Parameter]],
    ) -> None:
        self._advertise = advertise
        self._unadvertise = unadvertise
        self._message = message
        self._get_parameters = get_parameters
        self._set_parameters = set_parameters

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        _log.debug("client %d subscribed to %s", client.id, channel.topic)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        _log.debug("client %d unsubscribed from %s", client.id, channel.topic)

    def on_client_advertise(self, client: Client, channel: ClientChannel) -> None:
        self._advertise(client.id, channel)

    def on_client_unadvertise(self, client: Client, client_channel_id: int) -> None:
        self._unadvertise(client.id, client_channel_id)

    def on_message_data(self, client: Client, client_channel_id: int, data: bytes) -> None:
        self._message(client.id, client_channel_id, data)

    def on_get_parameters(
        self, client: Client, param_names: list[str], request_id: str | None = None
    ) -> list[Parameter]:
        return self._get_parameters(param_names)

    def on_set_parameters(
        self, client: Client, parameters: list[Parameter], request_id: str | None = None
    ) -> list[Parameter]:
        return self._set_parameters(parameters)

    def on_parameters_subscribe(self, param_names: list[str]) -> None:
        _log.debug("parameters subscribed: %s", param_names)

    def on_parameters_unsubscribe(self, param_names: list[str]) -> None:
        _log.debug("parameters unsubscribed: %s", param_names)

    def on_connection_graph_subscribe(self) -> None:
        return None

    def on_connection_graph_unsubscribe(self) -> None:
        return None

    def on_playback_control_request(
        self, playback_control_request: PlaybackControlRequest
    ) -> PlaybackState | None:
        return None
