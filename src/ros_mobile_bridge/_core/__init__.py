"""The client core: what one :class:`~ros_mobile_bridge.Client` is made of
and runs. Bottom first, as ``tests/test_exports.py`` orders them: the
services (``_outbound``: the outbox and control receipts; ``_serve``: serving
a service; ``_action``: an action goal's handle; ``_published_types``: the
publish type policy; ``_rejection_log``: rejections counted and logged at a
bounded rate), then ``_router`` (adapter events to subscriptions and
watchables), ``_connection`` (the connection's life: its tasks, reconnect,
the teardown with the zero Twist), ``_record`` (recording to MCAP) and
``_client`` (``Client``, the public front). It may import the base layer,
the parts (``wire``, ``codec``, ``flow``, ``transport``), the options and the
adapters, never what stands above it: ``_connect``, the sync layer
(``_sync``), the demo robot, the command line and the package face. This
face re-exports nothing; import the modules."""
