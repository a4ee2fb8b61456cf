"""The ``rmb`` command line, in the shape of ``ros2 topic|service|param|
interface|action``: ``rmb demo`` (the embedded demo robot, driven), ``topics``,
``echo``, ``hz``, ``bw``, ``info``, ``pub``, ``topic type|find``,
``services``, ``call``, ``service type|find``, ``param get|set|list|dump``,
``interface``, ``action send``, ``record``; ``rmb GROUP --help`` lists a
group's verbs. docs/cli.md describes every verb, its ros2 and hu
equivalents, ``--json``'s fields, the exit codes and ``$RMB_URL``. The code lives in the private
``_cli`` package; this module is the entry point (``rmb =
"ros_mobile_bridge.cli:main"``)."""

from __future__ import annotations

from ._cli import main as main

__all__ = ["main"]
