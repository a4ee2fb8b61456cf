"""Interim: bundled classes only (replaced by the runtime class builder)."""

from __future__ import annotations

from collections.abc import Mapping

from .._errors import SchemaError
from ..interfaces._base import RosMessage, message_class
from ._bundled import bundled_definition
from ._model import MsgDef

__all__ = ["class_for"]


def class_for(key: str, defs: Mapping[str, MsgDef]) -> type[RosMessage]:
    if all(bundled_definition(k) == d for k, d in defs.items()):
        return message_class(key)
    raise SchemaError(f"no class for {key}")
