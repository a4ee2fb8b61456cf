"""The sync layer: clients for code that does not run an event loop of its
own. ``_client`` is ``connect_sync()`` and the blocking ``SyncClient`` over
``_worker`` (one thread running the event loop and the blocks it holds);
``_background`` is ``open_client()``, a client that outlives the task that
opened it (Jupyter). It may import everything below it: ``_connect``, the
client core and the layers under them. Only the command line and the
package face stand above it. This face re-exports nothing; import the
modules."""
