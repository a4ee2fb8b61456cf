"""Scenarios for the hostile server (``peers.hostile_server``), one module
each: ``PROTOCOL = "foxglove" | "rosbridge"`` (the default; ``--arg
protocol=...`` overrides it) and ``async def run(conn: Conn) -> None``, run
once per client connection. Returning closes the connection normally."""
