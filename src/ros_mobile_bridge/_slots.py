"""Building frozen slotted dataclasses on hot paths.

A frozen dataclass's ``__init__`` sets each field through
``object.__setattr__``, several times the cost of a plain slotted
class's. Objects built once per received frame (``Message``) are made as an
instance of the class's :func:`unfrozen_twin` instead, their fields written as
plain attributes, and then turned into the frozen class by assigning
``__class__``: the same frozen object, with every field set, for about half
the cost of writing each slot through its descriptor's ``__set__``
(:func:`slot_setter`, as ``MessageData`` is still built), and a quarter of
``__init__``'s. Only for classes whose ``__init__`` does
nothing but store its arguments (no ``__post_init__``, no validation)."""

from __future__ import annotations

import types
from collections.abc import Callable
from typing import Any, Generic, TypeVar, cast

__all__ = ["new_object", "slot_setter", "unfrozen_twin"]

T = TypeVar("T")

new_object = object.__new__
"""``new_object(cls)``: an instance of ``cls`` with no slot set yet."""


def slot_setter(cls: type[T], name: str) -> Callable[[T, Any], None]:
    """The setter of slot ``name`` of ``cls`` (it ignores ``frozen``)."""
    descriptor: Any = cls.__dict__[name]
    return cast(Callable[[T, Any], None], descriptor.__set__)


def unfrozen_twin(cls: type) -> type:
    """A class with exactly the slots of ``cls`` (a slotted class deriving
    from ``object`` alone, or from ``Generic[...]`` alone) and the ordinary attribute setter. Build with
    ``obj = new_object(twin)``, write every field (``obj.name = value``: on
    CPython 3.11+ a direct slot store), then ``obj.__class__ = cls``: the
    layouts are the same, so the assignment is allowed and ``obj`` is from
    then on an ordinary ``cls`` (frozen again). Raises ``TypeError`` for a
    class whose layout a twin cannot share."""
    slots = cls.__dict__.get("__slots__")
    generic = cls.__bases__ == (Generic,)
    if (
        cls.__bases__ not in ((object,), (Generic,))
        or not isinstance(slots, tuple)
        or "__dict__" in slots
    ):
        raise TypeError(f"{cls.__qualname__} is not a slotted class deriving from object alone")
    namespace = {"__slots__": slots, "__module__": cls.__module__}
    # a generic class's twin derives from the same Generic[...], so that the
    # two share their base (the layouts must, for the __class__ assignment)
    bases = cls.__dict__["__orig_bases__"] if generic else ()
    twin = types.new_class(f"_Unfrozen{cls.__name__}", bases, {}, lambda ns: ns.update(namespace))
    probe: Any = new_object(twin)
    probe.__class__ = cls  # raises TypeError now if the layouts differ
    return twin
