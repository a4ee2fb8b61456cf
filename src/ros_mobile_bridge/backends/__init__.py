"""Transport backends behind the one :class:`~ros_mobile_bridge.Client` API."""

from ._base import Backend as Backend
from ._base import BackendEvents as BackendEvents
from ._base import SubscribeHints as SubscribeHints
from ._foxglove import FoxgloveBackend as FoxgloveBackend
from ._foxglove import open_foxglove as open_foxglove
