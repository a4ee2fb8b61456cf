"""ros-mobile-bridge: an async (asyncio and trio, via anyio) client for ROS 2
robots over Foxglove WebSocket or rosbridge v2, without installing ROS.

Start with :func:`connect`; everything else is reached from the
:class:`Client` it yields. See the README for the safety boundary: the
library sends a zero Twist on teardown while the socket is open, and cannot
stop a robot after the network is gone."""

from . import lag as lag
from ._action import ActionGoal as ActionGoal
from ._client import Client as Client
from ._connect import Endpoint as Endpoint
from ._connect import connect as connect
from ._connect import parse_target as parse_target
from ._errors import ActionGoalError as ActionGoalError
from ._errors import ConnectError as ConnectError
from ._errors import DecodeError as DecodeError
from ._errors import NotConnected as NotConnected
from ._errors import NotSupportedError as NotSupportedError
from ._errors import ProtocolMismatchError as ProtocolMismatchError
from ._errors import RosBridgeError as RosBridgeError
from ._errors import SchemaError as SchemaError
from ._errors import ServiceError as ServiceError
from ._errors import ServiceTimeout as ServiceTimeout
from ._options import BreakerPolicy as BreakerPolicy
from ._options import ClientOptions as ClientOptions
from ._options import ReconnectPolicy as ReconnectPolicy
from ._record import Recording as Recording
from ._record import RecordStats as RecordStats
from ._serve import ServeStats as ServeStats
from ._serve import ServiceRequest as ServiceRequest
from ._serve import ServiceRequests as ServiceRequests
from ._signals import SignalScope as SignalScope
from ._signals import cancel_on_signals as cancel_on_signals
from ._types import DEFAULT_PORTS as DEFAULT_PORTS
from ._types import ActionOutcome as ActionOutcome
from ._types import Compression as Compression
from ._types import Dispatch as Dispatch
from ._types import GoalState as GoalState
from ._types import Message as Message
from ._types import Priority as Priority
from ._types import ServerInfo as ServerInfo
from ._types import ServiceInfo as ServiceInfo
from ._types import Status as Status
from ._types import SubscriptionState as SubscriptionState
from ._types import SubscriptionStats as SubscriptionStats
from ._types import TopicInfo as TopicInfo
from ._version import __version__ as __version__
from .codec import FieldDef as FieldDef
from .flow import Batches as Batches
from .flow import Subscription as Subscription
from .flow._breaker import BreakerState as BreakerState
from .flow._breaker import CircuitBreaker as CircuitBreaker
from .flow._lag import LagStats as LagStats
from .flow._throttle import DEFAULT_PRESETS as DEFAULT_PRESETS
from .flow._throttle import Bucket as Bucket
from .flow._throttle import ThrottleMode as ThrottleMode

__all__ = [
    "DEFAULT_PORTS",
    "DEFAULT_PRESETS",
    "ActionGoal",
    "ActionGoalError",
    "ActionOutcome",
    "Batches",
    "BreakerPolicy",
    "BreakerState",
    "Bucket",
    "CircuitBreaker",
    "Client",
    "ClientOptions",
    "Compression",
    "ConnectError",
    "DecodeError",
    "Dispatch",
    "Endpoint",
    "FieldDef",
    "GoalState",
    "LagStats",
    "Message",
    "NotConnected",
    "NotSupportedError",
    "Priority",
    "ProtocolMismatchError",
    "ReconnectPolicy",
    "RecordStats",
    "Recording",
    "RosBridgeError",
    "SchemaError",
    "ServeStats",
    "ServerInfo",
    "ServiceError",
    "ServiceInfo",
    "ServiceRequest",
    "ServiceRequests",
    "ServiceTimeout",
    "SignalScope",
    "Status",
    "Subscription",
    "SubscriptionState",
    "SubscriptionStats",
    "ThrottleMode",
    "TopicInfo",
    "__version__",
    "cancel_on_signals",
    "connect",
    "lag",
    "parse_target",
]
