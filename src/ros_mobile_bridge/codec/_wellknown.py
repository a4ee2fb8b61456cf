"""rosbags' bundled ROS 2 Jazzy message definitions: the last fallback of a
:class:`CodecRegistry`, after the interfaces bundled with this package
(``codec/_bundled.py``), for the message packages rosbags knows and the
bundle does not hold. Parsed once, on first use, and shared read-only by
every registry (each builds its own rosbags typestore).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

from rosbags.typesys import Stores, get_typestore

from ._model import MsgDef, msgdef_from_rosbags

__all__ = ["builtin_definitions"]


@functools.cache
def builtin_definitions() -> Mapping[str, MsgDef]:
    """rosbags' ROS 2 Jazzy message definitions, by canonical name (rosbags
    keeps no ``.msg`` default values)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    return {
        name: msgdef_from_rosbags(name, consts, fields)
        for name, (consts, fields) in store.fielddefs.items()
    }
