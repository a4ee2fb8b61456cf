"""ros-mobile-bridge: an async (asyncio and trio, via anyio) client for ROS 2
robots over Foxglove WebSocket or rosbridge v2, without installing ROS.

Start with :func:`connect`; everything else is reached from the
:class:`Client` it yields. See the README for the safety boundary: the
library sends a zero Twist on teardown while the socket is open, and cannot
stop a robot after the network is gone.

``import ros_mobile_bridge`` is light: each name below loads its module on
first use (PEP 562), so a program that only needs, say, the errors or the
options does not pay for numpy, websockets and the codec at start-up."""

import importlib as _importlib
import typing as _typing

from ._version import __version__ as __version__

if _typing.TYPE_CHECKING:  # what type checkers and documentation tools read
    from . import lag as lag
    from ._connect import Endpoint as Endpoint
    from ._connect import connect as connect
    from ._connect import parse_target as parse_target
    from ._core._action import ActionGoal as ActionGoal
    from ._core._client import Client as Client
    from ._core._record import Recording as Recording
    from ._core._record import RecordStats as RecordStats
    from ._core._serve import ServeStats as ServeStats
    from ._core._serve import ServiceRequest as ServiceRequest
    from ._core._serve import ServiceRequests as ServiceRequests
    from ._errors import ActionGoalError as ActionGoalError
    from ._errors import ActionGoalLost as ActionGoalLost
    from ._errors import AssetError as AssetError
    from ._errors import ConnectError as ConnectError
    from ._errors import DecodeError as DecodeError
    from ._errors import MessageError as MessageError
    from ._errors import NotConnected as NotConnected
    from ._errors import NotSupportedError as NotSupportedError
    from ._errors import ParameterError as ParameterError
    from ._errors import ProtocolMismatchError as ProtocolMismatchError
    from ._errors import RosBridgeError as RosBridgeError
    from ._errors import SchemaError as SchemaError
    from ._errors import ServiceError as ServiceError
    from ._errors import ServiceTimeout as ServiceTimeout
    from ._options import BreakerPolicy as BreakerPolicy
    from ._options import ClientOptions as ClientOptions
    from ._options import ReconnectPolicy as ReconnectPolicy
    from ._options import RosbridgeAuth as RosbridgeAuth
    from ._signals import SignalScope as SignalScope
    from ._signals import cancel_on_signals as cancel_on_signals
    from ._sync._background import ClientHandle as ClientHandle
    from ._sync._background import open_client as open_client
    from ._sync._blocks import SyncActionGoal as SyncActionGoal
    from ._sync._blocks import SyncSubscription as SyncSubscription
    from ._sync._client import SyncClient as SyncClient
    from ._sync._client import connect_sync as connect_sync
    from ._types import DEFAULT_PORTS as DEFAULT_PORTS
    from ._types import ActionOutcome as ActionOutcome
    from ._types import Compression as Compression
    from ._types import ConnectionStats as ConnectionStats
    from ._types import Dispatch as Dispatch
    from ._types import GoalState as GoalState
    from ._types import Message as Message
    from ._types import PlaybackRequest as PlaybackRequest
    from ._types import PlaybackState as PlaybackState
    from ._types import PlaybackStatus as PlaybackStatus
    from ._types import Priority as Priority
    from ._types import SaveBandwidth as SaveBandwidth
    from ._types import ServerInfo as ServerInfo
    from ._types import ServerStatus as ServerStatus
    from ._types import ServiceInfo as ServiceInfo
    from ._types import Status as Status
    from ._types import StatusLevel as StatusLevel
    from ._types import StatusRemoved as StatusRemoved
    from ._types import SubscriptionState as SubscriptionState
    from ._types import SubscriptionStats as SubscriptionStats
    from ._types import TopicEndpoints as TopicEndpoints
    from ._types import TopicInfo as TopicInfo
    from ._zenoh_options import ZenohSecurity as ZenohSecurity
    from .codec import FieldDef as FieldDef
    from .codec._jsonable import jsonable as jsonable
    from .flow import Batches as Batches
    from .flow import Subscription as Subscription
    from .flow._breaker import BreakerState as BreakerState
    from .flow._breaker import CircuitBreaker as CircuitBreaker
    from .flow._lag import LagStats as LagStats
    from .flow._throttle import DEFAULT_PRESETS as DEFAULT_PRESETS
    from .flow._throttle import Bucket as Bucket
    from .flow._throttle import ThrottleMode as ThrottleMode

_LAZY: "dict[str, tuple[str, str]]" = {
    "lag": ("", "lag"),
    "ActionGoal": ("._core._action", "ActionGoal"),
    "Client": ("._core._client", "Client"),
    "Endpoint": ("._connect", "Endpoint"),
    "connect": ("._connect", "connect"),
    "parse_target": ("._connect", "parse_target"),
    "ActionGoalError": ("._errors", "ActionGoalError"),
    "ActionGoalLost": ("._errors", "ActionGoalLost"),
    "AssetError": ("._errors", "AssetError"),
    "ConnectError": ("._errors", "ConnectError"),
    "DecodeError": ("._errors", "DecodeError"),
    "MessageError": ("._errors", "MessageError"),
    "NotConnected": ("._errors", "NotConnected"),
    "NotSupportedError": ("._errors", "NotSupportedError"),
    "ParameterError": ("._errors", "ParameterError"),
    "ProtocolMismatchError": ("._errors", "ProtocolMismatchError"),
    "RosBridgeError": ("._errors", "RosBridgeError"),
    "SchemaError": ("._errors", "SchemaError"),
    "ServiceError": ("._errors", "ServiceError"),
    "ServiceTimeout": ("._errors", "ServiceTimeout"),
    "BreakerPolicy": ("._options", "BreakerPolicy"),
    "ClientOptions": ("._options", "ClientOptions"),
    "ReconnectPolicy": ("._options", "ReconnectPolicy"),
    "ZenohSecurity": ("._zenoh_options", "ZenohSecurity"),
    "SignalScope": ("._signals", "SignalScope"),
    "cancel_on_signals": ("._signals", "cancel_on_signals"),
    "DEFAULT_PORTS": ("._types", "DEFAULT_PORTS"),
    "ActionOutcome": ("._types", "ActionOutcome"),
    "Compression": ("._types", "Compression"),
    "ConnectionStats": ("._types", "ConnectionStats"),
    "Dispatch": ("._types", "Dispatch"),
    "GoalState": ("._types", "GoalState"),
    "Message": ("._types", "Message"),
    "PlaybackRequest": ("._types", "PlaybackRequest"),
    "PlaybackState": ("._types", "PlaybackState"),
    "PlaybackStatus": ("._types", "PlaybackStatus"),
    "Priority": ("._types", "Priority"),
    "SaveBandwidth": ("._types", "SaveBandwidth"),
    "ServerInfo": ("._types", "ServerInfo"),
    "ServerStatus": ("._types", "ServerStatus"),
    "ServiceInfo": ("._types", "ServiceInfo"),
    "Status": ("._types", "Status"),
    "StatusLevel": ("._types", "StatusLevel"),
    "StatusRemoved": ("._types", "StatusRemoved"),
    "SubscriptionState": ("._types", "SubscriptionState"),
    "SubscriptionStats": ("._types", "SubscriptionStats"),
    "TopicEndpoints": ("._types", "TopicEndpoints"),
    "TopicInfo": ("._types", "TopicInfo"),
    "FieldDef": (".codec", "FieldDef"),
    "Batches": (".flow", "Batches"),
    "Subscription": (".flow", "Subscription"),
    "BreakerState": (".flow._breaker", "BreakerState"),
    "CircuitBreaker": (".flow._breaker", "CircuitBreaker"),
    "LagStats": (".flow._lag", "LagStats"),
    "DEFAULT_PRESETS": (".flow._throttle", "DEFAULT_PRESETS"),
    "Bucket": (".flow._throttle", "Bucket"),
    "ThrottleMode": (".flow._throttle", "ThrottleMode"),
    "ClientHandle": ("._sync._background", "ClientHandle"),
    "open_client": ("._sync._background", "open_client"),
    "SyncActionGoal": ("._sync._blocks", "SyncActionGoal"),
    "SyncClient": ("._sync._client", "SyncClient"),
    "SyncSubscription": ("._sync._blocks", "SyncSubscription"),
    "connect_sync": ("._sync._client", "connect_sync"),
    "Recording": ("._core._record", "Recording"),
    "RecordStats": ("._core._record", "RecordStats"),
    "ServeStats": ("._core._serve", "ServeStats"),
    "ServiceRequest": ("._core._serve", "ServiceRequest"),
    "ServiceRequests": ("._core._serve", "ServiceRequests"),
    "RosbridgeAuth": ("._options", "RosbridgeAuth"),
    "jsonable": (".codec._jsonable", "jsonable"),
}
"""Public name -> (private module relative to this package, its name there);
``("", name)`` is a public submodule. Kept equal to the ``TYPE_CHECKING``
imports above by ``tests/test_exports.py``."""


if not _typing.TYPE_CHECKING:  # hidden from type checkers: a misspelt name stays an error there

    def __getattr__(name: str) -> _typing.Any:
        try:
            module, attr = _LAZY[name]
        except KeyError:
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
        if module:
            value = getattr(_importlib.import_module(module, __name__), attr)
        else:
            value = _importlib.import_module(f".{attr}", __name__)
        globals()[name] = value  # loaded once: later lookups do not come here
        return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "DEFAULT_PORTS",
    "DEFAULT_PRESETS",
    "ActionGoal",
    "ActionGoalError",
    "ActionGoalLost",
    "ActionOutcome",
    "AssetError",
    "Batches",
    "BreakerPolicy",
    "BreakerState",
    "Bucket",
    "CircuitBreaker",
    "Client",
    "ClientHandle",
    "ClientOptions",
    "Compression",
    "ConnectError",
    "ConnectionStats",
    "DecodeError",
    "Dispatch",
    "Endpoint",
    "FieldDef",
    "GoalState",
    "LagStats",
    "Message",
    "MessageError",
    "NotConnected",
    "NotSupportedError",
    "ParameterError",
    "PlaybackRequest",
    "PlaybackState",
    "PlaybackStatus",
    "Priority",
    "ProtocolMismatchError",
    "ReconnectPolicy",
    "RecordStats",
    "Recording",
    "RosBridgeError",
    "RosbridgeAuth",
    "SaveBandwidth",
    "SchemaError",
    "ServeStats",
    "ServerInfo",
    "ServerStatus",
    "ServiceError",
    "ServiceInfo",
    "ServiceRequest",
    "ServiceRequests",
    "ServiceTimeout",
    "SignalScope",
    "Status",
    "StatusLevel",
    "StatusRemoved",
    "Subscription",
    "SubscriptionState",
    "SubscriptionStats",
    "SyncActionGoal",
    "SyncClient",
    "SyncSubscription",
    "ThrottleMode",
    "TopicEndpoints",
    "TopicInfo",
    "ZenohSecurity",
    "__version__",
    "cancel_on_signals",
    "connect",
    "connect_sync",
    "jsonable",
    "lag",
    "open_client",
    "parse_target",
]
