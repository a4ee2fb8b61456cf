"""scripts/gen_message_classes.py as a module, for the tests of the message
classes (tests/test_message_classes*.py)."""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "gen_message_classes.py"


def generator() -> types.ModuleType:
    """The generator script, imported once."""
    name = "_rmb_gen_message_classes"
    module = sys.modules.get(name)
    if module is None:
        spec = importlib.util.spec_from_file_location(name, SCRIPT)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # its dataclasses look their module up
        spec.loader.exec_module(module)
    return module
