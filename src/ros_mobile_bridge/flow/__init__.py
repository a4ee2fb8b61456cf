"""Flow control between the socket and the user: the subscription pipeline,
the publish outbox and the pending-request registry. Knows no wire protocol."""

from ._breaker import BreakerState as BreakerState
from ._breaker import CircuitBreaker as CircuitBreaker
from ._feed import Feed as Feed
from ._feed import FeedWatcher as FeedWatcher
from ._frame import Decoder as Decoder
from ._frame import RawFrame as RawFrame
from ._lag import LagMonitor as LagMonitor
from ._lag import LagStats as LagStats
from ._lag import current_monitor as current_monitor
from ._lag import participate as participate
from ._outbox import Outbox as Outbox
from ._outbox import TopicMessage as TopicMessage
from ._outbox import WireMessage as WireMessage
from ._pending import PendingRequests as PendingRequests
from ._subscription import Batches as Batches
from ._subscription import FrameQueue as FrameQueue
from ._subscription import Subscription as Subscription
from ._throttle import DEFAULT_PRESETS as DEFAULT_PRESETS
from ._throttle import AdaptiveThrottle as AdaptiveThrottle
from ._throttle import Bucket as Bucket
from ._throttle import ThrottleMode as ThrottleMode
from ._throttle import resolve_presets as resolve_presets
from ._watch import Present as Present
from ._watch import Watchable as Watchable
from ._watch import Watcher as Watcher
