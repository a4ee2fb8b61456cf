"""Flow control between the socket and the user: the subscription pipeline,
the publish outbox and the pending-request registry. Knows no wire protocol."""

from ._frame import Decoder as Decoder
from ._frame import RawFrame as RawFrame
from ._outbox import Outbox as Outbox
from ._outbox import WireMessage as WireMessage
from ._pending import PendingRequests as PendingRequests
from ._subscription import FrameQueue as FrameQueue
from ._subscription import Subscription as Subscription
from ._watch import Watchable as Watchable
from ._watch import Watcher as Watcher
