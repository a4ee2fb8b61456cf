"""The event-loop timing machinery: one consumer's wait for its producer at the
loop's own cost (``_wakeup``, and its trio side ``_trio_wakeup``), trio's one
shared timer of timed waits per loop (``_trio_timers``), and the relay that
hands a per-loop worker between the clients on that loop (``_relay``). It is
part of the base layer: it imports anyio, sniffio and trio, nothing else of
ours. ``flow``, ``transport``, ``adapters`` and the client core stand above it
and wait through it. This face re-exports nothing; import the modules."""
