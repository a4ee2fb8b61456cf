"""Transport backends behind the one :class:`~ros_mobile_bridge.Client` API."""

from ._base import Advertisement as Advertisement
from ._base import Backend as Backend
from ._base import BackendEvents as BackendEvents
from ._base import GoalEvents as GoalEvents
from ._base import ServiceHandler as ServiceHandler
from ._base import SubscribeHints as SubscribeHints
from ._base import open_websocket as open_websocket
from ._foxglove import FoxgloveBackend as FoxgloveBackend
from ._foxglove import open_foxglove as open_foxglove
from ._foxglove import start_foxglove as start_foxglove
from ._rosbridge import RosbridgeBackend as RosbridgeBackend
from ._rosbridge import open_rosbridge as open_rosbridge
from ._rosbridge import start_rosbridge as start_rosbridge
