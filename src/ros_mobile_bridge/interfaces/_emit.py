"""The Python source of one interface class, from its parsed definitions: the
one emitter behind the bundled classes (``scripts/gen_message_classes.py``),
the classes ``rmb interface generate`` writes for a user's packages, and the
classes made at run time for types learnt from a robot
(:mod:`ros_mobile_bridge.interfaces._runtime`).

:class:`ClassWriter` writes a class statement (a message; a service's or an
action's namespace with its nested classes) in the shape ``ruff format``
gives; how it names the classes of nested fields is its subclasses' concern
(:meth:`ClassWriter.ref`): a generated module imports them, a class made at
run time finds them in the namespace its source runs in. What a written
class needs at run time is :mod:`._base`'s ``RosMessage`` (``RosService``,
``RosAction``) and the constructor helpers the writer lists in
:attr:`ClassWriter.helpers`. A definition the classes cannot express (a
field named like a method or a keyword, a constant named like a field, a
primitive with no Python type) raises :class:`~ros_mobile_bridge.SchemaError`.
"""

from __future__ import annotations

import keyword
import re
from collections.abc import Callable
from dataclasses import dataclass, field

from .._errors import SchemaError
from ..codec._model import ARRAY, SCALAR, FieldSpec, MsgDef
from ._base import _DTYPES

__all__ = [
    "LINE",
    "ClassWriter",
    "Message",
    "Namespace",
    "docstring",
    "field_type",
    "literal",
    "location",
    "module_stem",
    "natural",
    "wrap_call",
]

LINE = 100
"""ruff's line length (pyproject.toml): the written source fits it."""

_INT_TYPES = frozenset(
    {"byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}
)
_FLOAT_TYPES = frozenset({"float32", "float64"})
_STR_TYPES = frozenset({"string", "wstring", "wchar"})
_RESERVED = frozenset(
    {"replace", "to_dict", "from_dict", "get_fields_and_field_types", "self", "cls"}
)
"""Field names a class cannot have (RosMessage's own names)."""


def _dtype_name(base: str) -> str | None:
    """The numpy scalar type's name for a primitive array of ``base`` (the
    dtypes the classes build, ``interfaces._base``; ``bool`` is ``bool_``
    in an annotation), or None for a type with no numpy array."""
    dtype = _DTYPES.get(base)
    return "bool_" if dtype == "bool" else dtype


def module_stem(name: str) -> str:
    """The module of the interface ``name`` as rosidl names it
    (``convert_camel_case_to_lower_case_underscore``, with the leading
    underscore rclpy adds): ``TwistWithCovariance`` -> ``_twist_with_covariance``,
    ``PointCloud2`` -> ``_point_cloud2``, ``MultiDOFJointTrajectory`` ->
    ``_multi_dof_joint_trajectory``."""
    value = re.sub("(.)([A-Z][a-z]+)", r"\1_\2", name)
    value = re.sub("([a-z0-9])([A-Z])", r"\1_\2", value)
    return "_" + value.lower()


def natural(text: str) -> list[tuple[int, int | str]]:
    """The sort key of ruff's natural sort (RUF022, RUF023)."""
    return [
        (0, int(part)) if part.isdigit() else (1, part) for part in re.split(r"(\d+)", text) if part
    ]


def _py_str(text: str) -> str:
    """``text`` as a double-quoted Python literal."""
    out = []
    for char in text:
        if char in '\\"':
            out.append("\\" + char)
        elif char.isprintable():
            out.append(char)
        else:
            out.append(repr(char)[1:-1])
    return '"' + "".join(out) + '"'


def literal(value: object) -> str:
    """``value`` (a default or a constant: a str, an int, a float, a tuple
    of them) as a Python literal (``float("nan")`` for the non-finite)."""
    if isinstance(value, str):
        return _py_str(value)
    if isinstance(value, int):
        return repr(value)
    if isinstance(value, float):
        if value != value or value in (float("inf"), float("-inf")):
            return f'float("{value}")'
        return repr(value)
    if isinstance(value, tuple | list):
        items = [literal(v) for v in value]
        return f"({items[0]},)" if len(items) == 1 else f"({', '.join(items)})"
    raise SchemaError(f"cannot write the default {value!r}")


def _escape(line: str) -> str:
    return line.replace("\\", "\\\\").replace('"""', '\\"\\"\\"')


def docstring(summary: str, body: list[str], indent: str) -> list[str]:
    """The lines of a docstring: ``summary``, then ``body`` after a blank line."""
    if not body:
        return [f'{indent}"""{_escape(summary)}"""']
    lines = [f'{indent}"""{_escape(summary)}', ""]
    lines += [f"{indent}{_escape(x)}" if x else "" for x in body]
    lines.append(f'{indent}"""')
    return lines


def wrap_call(indent: str, head: str, args: list[str], end: str = "") -> list[str]:
    """``head(args)`` (a tuple when ``head`` is empty) followed by ``end``,
    the way ruff format lays it out."""
    one = f"{indent}{head}({', '.join(args)}){end}"
    if len(one) <= LINE:
        return [one]
    inner = f"{indent}    {', '.join(args)}"
    if head and len(inner) <= LINE:
        return [f"{indent}{head}(", inner, f"{indent}){end}"]
    return [f"{indent}{head}(", *(f"{indent}    {a}," for a in args), f"{indent}){end}"]


def field_type(spec: FieldSpec) -> str:
    """The ``.msg`` spelling of a field's type (``__ros_fields__``)."""
    element = spec.ref if spec.ref is not None else str(spec.base)
    if spec.base in ("string", "wstring") and spec.string_bound:
        element += f"<={spec.string_bound}"
    if spec.cardinality == SCALAR:
        return element
    if spec.cardinality == ARRAY:
        return f"{element}[{spec.size}]"
    return f"{element}[<={spec.size}]" if spec.size else f"{element}[]"


def location(type_name: str) -> tuple[str, str, str]:
    """``(package, kind, qualname)`` of the class of ``type_name``
    (``pkg/srv/X_Request`` -> ``("pkg", "srv", "X.Request")``)."""
    pkg, kind, short = type_name.split("/")
    return pkg, kind, ".".join(short.split("_"))


# -- what to write ---------------------------------------------------------------------------


@dataclass
class Message:
    """One message class to write: its type name, its qualified name
    (``"Twist"``, ``"AddTwoInts.Request"``), its docstring's summary and
    body lines, its definition."""

    type_name: str
    qualname: str
    summary: str
    doc: list[str]
    msgdef: MsgDef
    base: str = "RosMessage"
    """The base class expression: ``RosMessage``, or for a service's
    request ``RosRequest["AddTwoInts.Response"]`` and for an action's goal
    ``RosGoal["Fibonacci.Result", "Fibonacci.Feedback"]`` (what type
    checkers learn a call or a goal gives)."""


@dataclass
class Namespace:
    """A service or an action class: a type name and hash, nested classes."""

    type_name: str
    qualname: str
    base: str
    summary: str
    members: list[Message | Namespace] = field(default_factory=list)


_Statement = Callable[[str], list[str]]


class ClassWriter:
    """Writes class statements. ``hashes`` gives each type's ``RIHS01_``
    hash (None: unknown, an error). What the written classes use is
    collected as they are written: :attr:`helpers` (the constructor helpers
    of ``_base``), :attr:`typing` (``typing`` names needed at run time) and
    :attr:`checking` (names only annotations use). With
    ``check_shadowing``, a field named like a name its class's annotations
    use is refused (for source that a type checker reads)."""

    def __init__(
        self, hashes: Callable[[str], str | None], *, check_shadowing: bool = True
    ) -> None:
        self.hashes = hashes
        self.check_shadowing = check_shadowing
        self.helpers: set[str] = set()
        self.typing: set[str] = set()
        self.checking: set[str] = set()  # "numpy", "NDArray", "Sequence"

    def ref(self, type_name: str) -> tuple[str, str]:
        """``(annotation, run-time expression)`` of the class of ``type_name``."""
        raise NotImplementedError

    def message(self, cls: Message, indent: str) -> list[str]:
        """The lines of the class statement of ``cls``, at ``indent``."""
        msgdef = cls.msgdef
        fields = msgdef.visible_fields
        inner = indent + "    "
        lines = [f"{indent}class {cls.qualname.rpartition('.')[2]}({cls.base}):"]
        if cls.base != "RosMessage":
            self.helpers.add(cls.base.partition("[")[0])
        lines += docstring(cls.summary, cls.doc, inner)
        lines.append("")
        names = [f.name for f in fields]
        for name in names:
            if (
                name in _RESERVED
                or name.startswith("_")
                or not name.isidentifier()
                or keyword.iskeyword(name)
            ):
                raise SchemaError(f"{cls.type_name}: cannot name a field {name!r}")
        slots = sorted(names, key=natural)
        if len(slots) == 1:
            lines.append(f'{inner}__slots__ = ("{slots[0]}",)')
        elif not slots:
            lines.append(f"{inner}__slots__ = ()")
        else:
            lines.append(f"{inner}__slots__ = (")
            lines += [f'{inner}    "{s}",' for s in slots]
            lines.append(f"{inner})")
        lines.append(f'{inner}__ros_type__ = "{cls.type_name}"')
        lines.append(f'{inner}__ros_hash__ = "{self.hash_of(cls.type_name)}"')
        pairs = [(f'"{f.name}"', f'"{field_type(f)}"') for f in fields]
        if not pairs:
            lines.append(f"{inner}__ros_fields__ = ()")
        elif len(pairs) == 1 and len(f"{inner}__ros_fields__ = (({', '.join(pairs[0])}),)") <= LINE:
            lines.append(f"{inner}__ros_fields__ = (({', '.join(pairs[0])}),)")
        else:
            lines.append(f"{inner}__ros_fields__ = (")
            for pair in pairs:
                lines += wrap_call(inner + "    ", "", list(pair), ",")
            lines.append(f"{inner})")
        if msgdef.constants:
            lines.append("")
            self.typing.add("ClassVar")
            for cname, ctype, value in msgdef.constants:
                if cname in names or not cname.isidentifier() or keyword.iskeyword(cname):
                    raise SchemaError(f"{cls.type_name}: cannot name a constant {cname!r}")
                lines.append(f"{inner}{cname}: ClassVar[{_scalar(ctype)}] = {literal(value)}")
        if not fields:
            return lines
        params: list[str] = []
        body: list[str] = []
        annotations: list[str] = []
        used: set[str] = set()
        for spec in fields:
            attr, param, statement = self._field(spec, used)
            annotations.append(f"{inner}{spec.name}: {attr}")
            params.append(f"{spec.name}: {param}")
            body += statement(inner + "    ")
        clash = used & set(names)
        if clash and self.check_shadowing:
            raise SchemaError(f"{cls.type_name}: field names {sorted(clash)} shadow type names")
        lines.append("")
        lines += annotations
        lines.append("")
        lines.append(f"{inner}def __init__(")
        lines.append(f"{inner}    self,")
        lines.append(f"{inner}    *,")
        lines += [f"{inner}    {p}," for p in params]
        lines.append(f"{inner}) -> None:")
        lines += body
        return lines

    def _field(self, spec: FieldSpec, used: set[str]) -> tuple[str, str, _Statement]:
        """``(attribute annotation, parameter, statements(indent))`` of a field."""
        name = spec.name
        default = spec.default
        call: tuple[str, list[str]] | None
        if spec.ref is not None:
            annotation, runtime = self.ref(spec.ref)
            used.add(annotation.partition(".")[0])
            if spec.cardinality == SCALAR:
                self.helpers.add("_nested")
                call = ("_nested", [f'"{name}"', name, runtime])
                attr, param = annotation, f"{annotation} | None = None"
            else:
                self.helpers.add("_messages")
                self.checking.add("Sequence")
                used.update({"list", "Sequence"})
                call = ("_messages", [f'"{name}"', name, runtime])
                attr, param = f"list[{annotation}]", f"Sequence[{annotation}] | None = None"
        elif spec.cardinality == SCALAR:
            scalar = _scalar(str(spec.base))
            used.add(scalar)
            if default is None:
                default = {"int": 0, "float": 0.0, "bool": False, "str": ""}[scalar]
            attr, param = scalar, f"{scalar} = {literal(default)}"
            if spec.base in ("string", "wstring") and spec.string_bound:
                self.helpers.add("_bounded")
                call = ("_bounded", [f'"{name}"', name])
            else:
                call = None
        elif spec.base in ("string", "wstring"):
            self.helpers.add("_strings")
            self.checking.add("Sequence")
            used.update({"list", "str", "Sequence"})
            args = [f'"{name}"', name] + ([literal(default)] if default else [])
            call = ("_strings", args)
            attr, param = "list[str]", "Sequence[str] | None = None"
        else:
            dtype = _dtype_name(str(spec.base))
            if dtype is None:
                raise SchemaError(f"unsupported array element type {spec.base!r}")
            self.helpers.add("_array")
            self.checking.update({"numpy", "NDArray", "Sequence"})
            element = _scalar(str(spec.base)) if spec.base != "bool" else "bool"
            used.update({"numpy", "NDArray", "Sequence", element})
            args = [f'"{name}"', name] + ([literal(default)] if default else [])
            call = ("_array", args)
            attr = f"NDArray[numpy.{dtype}]"
            param = f"{attr} | Sequence[{element}] | None = None"

        def statement(indent: str) -> list[str]:
            if call is None:
                return [f"{indent}self.{name} = {name}"]
            head, args = call
            return wrap_call(indent, f"self.{name} = {head}", ["self", *args])

        return attr, param, statement

    def hash_of(self, type_name: str) -> str:
        found = self.hashes(type_name)
        if found is None:
            raise SchemaError(f"no hash for {type_name}")
        return found

    def namespace(self, ns: Namespace, indent: str) -> list[str]:
        """The lines of the class statement of a service or an action."""
        inner = indent + "    "
        name = ns.qualname.rpartition(".")[2]
        lines = [f"{indent}class {name}({ns.base}):"]
        if len(lines[0]) > LINE:  # as the formatter splits it
            lines = [f"{indent}class {name}(", f"{inner}{ns.base}", f"{indent}):"]
        lines += docstring(ns.summary, [], inner)
        lines.append("")
        lines.append(f"{inner}__slots__ = ()")
        lines.append(f'{inner}__ros_type__ = "{ns.type_name}"')
        lines.append(f'{inner}__ros_hash__ = "{self.hash_of(ns.type_name)}"')
        for member in ns.members:
            lines.append("")
            lines += self.one(member, inner)
        return lines

    def one(self, cls: Message | Namespace, indent: str) -> list[str]:
        """The lines of the class statement of ``cls``, at ``indent``."""
        if isinstance(cls, Namespace):
            return self.namespace(cls, indent)
        return self.message(cls, indent)


def _scalar(base: str) -> str:
    """The Python type of a primitive."""
    if base in _INT_TYPES:
        return "int"
    if base in _FLOAT_TYPES:
        return "float"
    if base == "bool":
        return "bool"
    if base in _STR_TYPES:
        return "str"
    raise SchemaError(f"unsupported primitive type {base!r}")
