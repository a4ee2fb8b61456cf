"""Building frozen slotted dataclasses on hot paths.

A frozen dataclass's ``__init__`` sets each field through
``object.__setattr__``, about twice the cost of writing the slots directly.
Objects built once per received frame (``Message``, the Foxglove engine's
``MessageData``) are made with :func:`new_object` and each field's
:func:`slot_setter` instead: the same frozen object, with every field set,
for about half the cost. Only for classes whose ``__init__`` does nothing
but store its arguments (no ``__post_init__``, no validation)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

__all__ = ["new_object", "slot_setter"]

T = TypeVar("T")

new_object = object.__new__
"""``new_object(cls)``: an instance of ``cls`` with no slot set yet."""


def slot_setter(cls: type[T], name: str) -> Callable[[T, Any], None]:
    """The setter of slot ``name`` of ``cls`` (it ignores ``frozen``)."""
    descriptor: Any = cls.__dict__[name]
    return cast(Callable[[T, Any], None], descriptor.__set__)
