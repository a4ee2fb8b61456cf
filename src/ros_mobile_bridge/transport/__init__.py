"""Byte transports: a WebSocket client over anyio streams (and, later, a Zenoh session)."""

from ._websocket import ConnectionLost as ConnectionLost
from ._websocket import WebSocket as WebSocket
from ._ws_connect import HandshakeRejected as HandshakeRejected
from ._ws_connect import connect_websocket as connect_websocket
