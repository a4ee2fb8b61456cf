"""The ``rmb`` command line, in private modules: ``_app`` (entry point,
options, exit codes), ``_topic`` (topic verbs), ``_ros`` (services,
parameters, interfaces, actions), ``_demo``, ``_format`` (YAML and JSON in
and out), ``_common``, ``_verb`` (the ``Verb`` record the verb modules list
their commands in; they import it from there, never from ``_app``).
Loaded by ``ros_mobile_bridge.cli`` only."""

from ._app import main as main

__all__ = ["main"]
