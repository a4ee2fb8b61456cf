"""Transport adapters: one per protocol, each a wire engine over a transport,
behind the one :class:`~.Adapter` seam the connection drives."""

from ._foxglove import FoxgloveAdapter as FoxgloveAdapter
from ._foxglove import open_foxglove as open_foxglove
from ._foxglove import start_foxglove as start_foxglove
from ._rosbridge import RosbridgeAdapter as RosbridgeAdapter
from ._rosbridge import open_rosbridge as open_rosbridge
from ._rosbridge import start_rosbridge as start_rosbridge
from ._seam import ActionClient as ActionClient
from ._seam import Adapter as Adapter
from ._seam import AssetFetcher as AssetFetcher
from ._seam import Event as Event
from ._seam import EventSink as EventSink
from ._seam import GoalEvents as GoalEvents
from ._seam import GraphChanged as GraphChanged
from ._seam import NodeLister as NodeLister
from ._seam import ParameterAccess as ParameterAccess
from ._seam import ParameterValues as ParameterValues
from ._seam import PlaybackControl as PlaybackControl
from ._seam import Rejected as Rejected
from ._seam import Replayed as Replayed
from ._seam import ServerClock as ServerClock
from ._seam import ServiceHandler as ServiceHandler
from ._seam import ServiceHost as ServiceHost
from ._seam import SubscribeHints as SubscribeHints
from ._seam import TopicState as TopicState
from ._seam import TypeDescriber as TypeDescriber
from ._seam import require as require
from ._shared import open_websocket as open_websocket
