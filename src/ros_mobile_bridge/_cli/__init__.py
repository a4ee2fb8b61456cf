"""The ``rmb`` command line, in private modules: ``_app`` (entry point,
options, exit codes), ``_table`` (the index of every verb: words, help line,
module; what ``--help`` and ``--version`` read without loading a verb),
``_topic`` (topic verbs), ``_lookup`` (``topic|service type|find``),
``_ros`` (services, parameters, actions), ``_interface``, ``_generate``
(``interface generate``), ``_record``,
``_demo``, ``_format`` (YAML, CSV and JSON in and out), ``_common`` (the
robot, graph names, type checks), ``_verb`` (the ``Verb`` record the verb
modules list their commands in; they import it from there, never from
``_app``). Loaded by ``ros_mobile_bridge.cli`` only."""

from ._app import main as main

__all__ = ["main"]
