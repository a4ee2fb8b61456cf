"""Byte transports: a WebSocket client over anyio streams (and, later, a Zenoh session)."""

from ._websocket import ConnectionLost as ConnectionLost
from ._websocket import HandshakeRejected as HandshakeRejected
from ._websocket import WebSocket as WebSocket
from ._websocket import connect_websocket as connect_websocket
