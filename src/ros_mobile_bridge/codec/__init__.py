"""Schemas and payloads -> Python objects, and back.

:class:`CodecRegistry` holds the schemas one server advertised and makes
decoders (CDR or JSON payload -> ``dict``) and encoders (``dict`` -> payload)
for them, falling back to the ROS 2 Jazzy message definitions bundled with
rosbags and a few standard service definitions. :func:`normalize_type_name`
and :func:`same_type_name` deal with the several spellings of a ROS type
name; :func:`type_hash` computes a type's ROS 2 (REP-2011, ``RIHS01_``) type
hash from a registry's definitions, :func:`description_hash` the hash of a
REP-2011 type description and :func:`describe` the definitions it gives
(:meth:`CodecRegistry.add_description` registers them).
"""

from __future__ import annotations

from ._description import DESCRIPTION_CACHE as DESCRIPTION_CACHE
from ._description import DescriptionCache as DescriptionCache
from ._description import HashMismatch as HashMismatch
from ._description import describe as describe
from ._description import description_hash as description_hash
from ._model import DescribedTypes as DescribedTypes
from ._model import FieldDef as FieldDef
from ._names import normalize_type_name as normalize_type_name
from ._names import same_type_name as same_type_name
from ._registry import CodecRegistry as CodecRegistry
from ._registry import SchemaTooLarge as SchemaTooLarge
from ._typehash import type_description as type_description
from ._typehash import type_hash as type_hash

__all__ = [
    "DESCRIPTION_CACHE",
    "CodecRegistry",
    "DescribedTypes",
    "DescriptionCache",
    "FieldDef",
    "HashMismatch",
    "SchemaTooLarge",
    "describe",
    "description_hash",
    "normalize_type_name",
    "same_type_name",
    "type_description",
    "type_hash",
]
