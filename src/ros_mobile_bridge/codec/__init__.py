"""Schemas and payloads -> Python objects, and back.

:class:`CodecRegistry` holds the schemas one server advertised and makes
decoders (CDR or JSON payload -> an instance of the type's message class,
:mod:`ros_mobile_bridge.interfaces`; ``dict_decoder`` for a ``dict``) and
encoders (an instance or a ``dict`` -> payload) for them, falling back to local interface files (:class:`InterfacePaths`),
then to the standard ROS 2 Jazzy interfaces bundled with the package
(:func:`bundled_interface`, :func:`bundled_hash`), then to rosbags' Jazzy
messages. :func:`find_interface` and :func:`interface_names` look interfaces
up the same way for tools. :func:`normalize_type_name` and
:func:`same_type_name` deal with the several spellings of a ROS type name;
:func:`type_hash` computes a type's ROS 2 (REP-2011, ``RIHS01_``) type hash
from a registry's definitions.
REP-2011 type descriptions: :func:`description_hash` hashes one,
:func:`describe` gives its definitions (:meth:`CodecRegistry.add_description`
registers them) and :func:`type_description` makes one from a registry.
"""

from __future__ import annotations

from ._bundled import bundled_hash as bundled_hash
from ._bundled import bundled_interface as bundled_interface
from ._bundled import bundled_interface_names as bundled_interface_names
from ._description import DESCRIPTION_CACHE as DESCRIPTION_CACHE
from ._description import DescriptionCache as DescriptionCache
from ._description import HashMismatch as HashMismatch
from ._description import describe as describe
from ._description import description_hash as description_hash
from ._interface import Interface as Interface
from ._model import DescribedTypes as DescribedTypes
from ._model import FieldDef as FieldDef
from ._names import normalize_type_name as normalize_type_name
from ._names import same_type_name as same_type_name
from ._registry import CodecRegistry as CodecRegistry
from ._registry import SchemaTooLarge as SchemaTooLarge
from ._typehash import type_description as type_description
from ._typehash import type_hash as type_hash
from ._workspace import InterfacePaths as InterfacePaths
from ._workspace import find_interface as find_interface
from ._workspace import interface_names as interface_names
from ._workspace import interface_paths_for as interface_paths_for

__all__ = [
    "DESCRIPTION_CACHE",
    "CodecRegistry",
    "DescribedTypes",
    "DescriptionCache",
    "FieldDef",
    "HashMismatch",
    "Interface",
    "InterfacePaths",
    "SchemaTooLarge",
    "bundled_hash",
    "bundled_interface",
    "bundled_interface_names",
    "describe",
    "description_hash",
    "find_interface",
    "interface_names",
    "interface_paths_for",
    "normalize_type_name",
    "same_type_name",
    "type_description",
    "type_hash",
]
