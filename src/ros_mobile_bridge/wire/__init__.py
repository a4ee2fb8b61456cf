"""Sans-IO protocol engines: bytes and text in, events out; no sockets, no event loop.

Each module here implements one wire protocol as a pure state machine in the
style of ``h11`` / ``wsproto``. The transports own the I/O and feed these
engines; nothing in this package imports ``anyio`` or ``asyncio``.
"""
