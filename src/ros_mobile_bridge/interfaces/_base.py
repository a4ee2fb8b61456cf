"""The base classes of the generated interface classes, and the helpers their
constructors call.

Every generated message class derives from :class:`RosMessage` and declares,
as class attributes, its ROS type name (``__ros_type__``), its RIHS01 hash
(``__ros_hash__``) and its fields with their ``.msg`` types
(``__ros_fields__``); everything generic (equality, ``repr``, copies,
``replace``, ``to_dict``/``from_dict``, pickling) is written once here and
reads those. numpy is imported on first use (a default array, an array
argument), never at import: importing a package's messages stays cheap.

The generated constructors check only what a caller gets wrong and costs
little to check: the length of a fixed-size array, the bound of a bounded
sequence or string, and the class of a nested message; they raise
:class:`~ros_mobile_bridge.MessageError` naming the field. A decoder builds
instances without them: ``cls.__new__(cls)``, then every slot assigned
(:meth:`RosMessage._make` does that for any class).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Final, Generic, TypeVar

from .._errors import MessageError, SchemaError

if TYPE_CHECKING:
    import numpy
    from numpy.typing import NDArray

__all__ = [
    "RosAction",
    "RosGoal",
    "RosMessage",
    "RosRequest",
    "RosService",
    "lazy_kinds",
    "lazy_types",
    "message_class",
]

_M = TypeVar("_M", bound="RosMessage")
_Request = TypeVar("_Request", bound="RosMessage")
_Response = TypeVar("_Response", bound="RosMessage")
_Result = TypeVar("_Result", bound="RosMessage")
_Feedback = TypeVar("_Feedback", bound="RosMessage")

# What a field holds (FieldInfo.kind).
SCALAR: Final = 0
"""A primitive: ``int``, ``float``, ``bool`` or ``str``."""
ARRAY: Final = 1
"""An array or sequence of numbers or bools: a one-dimensional numpy array."""
STRINGS: Final = 2
"""An array or sequence of strings: a ``list[str]``."""
MESSAGE: Final = 3
"""A nested message: an instance of its class."""
MESSAGES: Final = 4
"""An array or sequence of nested messages: a ``list`` of instances."""

_DTYPES: Final = {
    "bool": "bool",
    "byte": "uint8",  # the ROS 2 octet, 0..255, as the CDR decoder gives it
    "char": "uint8",
    "int8": "int8",
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "int32": "int32",
    "uint32": "uint32",
    "int64": "int64",
    "uint64": "uint64",
    "float32": "float32",
    "float64": "float64",
}
"""A primitive array's element type -> the dtype of its numpy array."""
_STRING_TYPES: Final = frozenset({"string", "wstring"})
_PACKAGE: Final = __name__.rpartition(".")[0]


class FieldInfo:
    """One field of a class, read from its ``.msg`` type (``"float64[36]"``,
    ``"string<=256"``, ``"geometry_msgs/msg/Point[]"``, ``"int32[<=5]"``).
    (A plain class: a ``NamedTuple`` would compile its annotations at import.)"""

    __slots__ = ("element", "fixed", "kind", "msg_type", "name", "size", "string_bound")

    def __init__(
        self,
        name: str,
        msg_type: str,
        kind: int,
        element: str,
        fixed: bool,
        size: int,
        string_bound: int,
    ) -> None:
        self.name = name
        self.msg_type = msg_type
        """The type as ``__ros_fields__`` spells it."""
        self.kind = kind
        """:data:`SCALAR`, :data:`ARRAY`, :data:`STRINGS`, :data:`MESSAGE` or :data:`MESSAGES`."""
        self.element = element
        """The element type without its string bound (``"float64"``,
        ``"string"``, ``"geometry_msgs/msg/Point"``)."""
        self.fixed = fixed
        """A fixed-size array (``T[N]``): ``size`` is its length."""
        self.size = size
        """The length of a fixed-size array, the bound of a bounded sequence, else 0."""
        self.string_bound = string_bound
        """The bound of a bounded string (the field's, or its elements'), else 0."""


def parse_field(name: str, type_: str) -> FieldInfo:
    """The :class:`FieldInfo` of field ``name`` of the ``.msg`` type ``type_``."""
    element, fixed, size, array = type_, False, 0, False
    if type_.endswith("]"):
        array = True
        element, _, spec = type_[:-1].rpartition("[")
        if spec.startswith("<="):
            size = int(spec[2:])
        elif spec:
            fixed, size = True, int(spec)
    element, _, bound = element.partition("<=")
    string_bound = int(bound) if bound else 0
    if "/" in element:
        kind = MESSAGES if array else MESSAGE
    elif not array:
        kind = SCALAR
    else:
        kind = STRINGS if element in _STRING_TYPES else ARRAY
    return FieldInfo(name, type_, kind, element, fixed, size, string_bound)


class _Plan:
    """What the generic methods need of one class, computed on first use."""

    __slots__ = ("classes", "fields", "kinds", "maker", "names", "path")

    def __init__(self, infos: list[FieldInfo], path: str) -> None:
        self.names = tuple(i.name for i in infos)
        self.kinds = tuple(i.kind for i in infos)
        self.fields = {i.name: i for i in infos}
        self.path = path
        """The class as ``repr`` names it (as rclpy's does): ``geometry_msgs.msg.Twist``."""
        self.classes: dict[str, type[RosMessage]] = {}
        """The nested message fields' classes, by field name, found on first use."""
        self.maker: Callable[..., Any] | None = None
        """``maker(cls, *values)``: an instance without the constructor
        (:meth:`RosMessage._make`), made on first use."""

    def make_maker(self) -> Callable[..., Any]:
        """A function assigning every slot in one run, as a generated
        decoder does: a loop over ``setattr`` costs three times as much."""
        args = "".join(f", {name}" for name in self.names)
        body = "".join(f"\n    obj.{name} = {name}" for name in self.names)
        source = f"def make(cls{args}):\n    obj = cls.__new__(cls){body}\n    return obj\n"
        namespace: dict[str, Any] = {}
        exec(compile(source, f"<maker of {self.path}>", "exec"), namespace)
        self.maker = namespace["make"]
        return self.maker

    def nested_class(self, name: str) -> type[RosMessage]:
        cls = self.classes.get(name)
        if cls is None:
            element = self.fields[name].element
            try:
                cls = message_class(element)
            except SchemaError:
                cls = generated_class(element)
            self.classes[name] = cls
        return cls


_PLANS: dict[type, _Plan] = {}


def _plan(cls: type[RosMessage]) -> _Plan:
    plan = _PLANS.get(cls)
    if plan is None:
        own = cls.__dict__.get(_OWN_PLAN)
        if own is not None:  # a class made at run time keeps its own (see own_plan)
            return own  # type: ignore[no-any-return]
        infos = [parse_field(name, type_) for name, type_ in cls.__ros_fields__]
        # the path rclpy's repr gives: the kind's face, not the class's own
        # module (geometry_msgs.msg._twist)
        module = cls.__module__
        if module.startswith(_PACKAGE + "."):
            module = module[len(_PACKAGE) + 1 :]
        face, _, own = module.rpartition(".")
        if face and own.startswith("_"):
            module = face
        plan = _Plan(infos, f"{module}.{cls.__qualname__}")
        _PLANS[cls] = plan
    return plan


_OWN_PLAN: Final = "_ros_plan_"


def own_plan(cls: type[RosMessage], path: str, nested: Mapping[str, type[RosMessage]]) -> None:
    """Give ``cls``, a class made at run time, its plan: ``path`` is what its
    ``repr`` names it (``"my_msgs.msg.Status"``), ``nested`` its nested
    message fields' classes by field name (they are not found by
    :func:`message_class`). The plan is kept on the class, not in this
    module's table, so that the class can be freed when nothing uses it."""
    plan = _Plan([parse_field(name, type_) for name, type_ in cls.__ros_fields__], path)
    plan.classes.update(nested)
    setattr(cls, _OWN_PLAN, plan)


def message_class(type_name: str) -> type[RosMessage]:
    """The class of the ROS message type ``type_name``: ``"pkg/msg/Name"``,
    or a type a service or an action derives (``"pkg/srv/Name_Request"`` is
    ``Name.Request``, ``"pkg/action/Name_SendGoal_Request"`` is
    ``Name.SendGoal.Request``). Imports its module. Raises
    :class:`~ros_mobile_bridge.SchemaError` when there is none."""
    found = _class_at(type_name, f"{_PACKAGE}.")
    if found is None:
        raise SchemaError(f"no message class for {type_name!r}")
    return found


def generated_class(type_name: str) -> type[RosMessage]:
    """The class of ``type_name`` in a package ``rmb interface generate``
    wrote (importable as ``<package>.<kind>``, beside the bundled ones).
    Raises :class:`~ros_mobile_bridge.SchemaError` when there is none, or
    when what that path holds is not the class of that type."""
    found = _class_at(type_name, "")
    if found is None or found.__ros_type__ != type_name:
        raise SchemaError(f"no message class for {type_name!r}")
    return found


def _class_at(type_name: str, root: str) -> type[RosMessage] | None:
    """The message class ``<root><pkg>.<kind>`` holds for ``type_name``
    (importing it), or None."""
    parts = type_name.split("/")
    found: object = None
    if len(parts) == 3 and parts[1] in ("msg", "srv", "action") and parts[0].isidentifier():
        pkg, kind, name = parts
        try:
            found = importlib.import_module(f"{root}{pkg}.{kind}")
        except ImportError:
            found = None
        for part in name.split("_"):
            found = getattr(found, part, None)
    return found if isinstance(found, type) and issubclass(found, RosMessage) else None


class RosMessage:
    """The base of every message class (and of a service's ``Request`` and
    ``Response``, an action's ``Goal``, ``Result`` and ``Feedback``).

    A message class is built with keyword arguments, each defaulting to the
    ``.msg`` file's default (zero, ``""``, ``False``, a fresh zero message,
    an empty or zero-filled array); its instances are mutable, compare equal
    when their classes and all fields are equal (numpy arrays by value), and
    are not hashable, as rclpy's. Class attributes: ``__ros_type__`` (the
    ROS type name, ``"geometry_msgs/msg/Twist"``), ``__ros_hash__`` (its
    ``RIHS01_`` type hash) and ``__ros_fields__`` (``(name, .msg type)``
    pairs in wire order); the ``.msg`` constants."""

    __slots__ = ()

    __ros_type__: ClassVar[str]
    """The ROS type name: ``"geometry_msgs/msg/Twist"``."""
    __ros_hash__: ClassVar[str]
    """The ROS 2 type hash (REP-2011): ``"RIHS01_..."``."""
    __ros_fields__: ClassVar[tuple[tuple[str, str], ...]] = ()
    """Every field's name and ``.msg`` type, in wire order:
    ``(("x", "float64"), ("covariance", "float64[36]"), ...)``."""

    @classmethod
    def get_fields_and_field_types(cls) -> dict[str, str]:
        """Every field's name and ``.msg`` type, in wire order (rclpy's
        method of that name, with ``.msg`` spellings: ``"float64[36]"``)."""
        return dict(cls.__ros_fields__)

    @classmethod
    def _make(cls: type[_M], *values: Any) -> _M:
        """An instance with these field values, in wire order, taken as
        they are: no defaults, no checks (for decoders)."""
        plan = _plan(cls)
        maker = plan.maker or plan.make_maker()
        return maker(cls, *values)  # type: ignore[no-any-return]

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        plan = _plan(type(self))
        for name, kind in zip(plan.names, plan.kinds, strict=True):
            mine = getattr(self, name)
            theirs = getattr(other, name)
            if mine is theirs:
                continue
            if kind == ARRAY:
                if not _arrays_equal(mine, theirs):
                    return False
            elif mine != theirs:
                return False
        return True

    # defining __eq__ sets __hash__ to None (messages are mutable, not hashable);
    # the annotation tells type checkers, as typeshed does for list
    __hash__: ClassVar[None]  # type: ignore[assignment]

    def __repr__(self) -> str:
        plan = _plan(type(self))
        args = ", ".join(f"{name}={getattr(self, name)!r}" for name in plan.names)
        return f"{plan.path}({args})"

    def __copy__(self: _M) -> _M:
        """A shallow copy: the fields' values (nested messages, arrays,
        lists) are shared, as ``copy.copy`` does for any object."""
        cls = type(self)
        obj = cls.__new__(cls)
        for name in _plan(cls).names:
            setattr(obj, name, getattr(self, name))
        return obj

    def __deepcopy__(self: _M, memo: dict[int, Any]) -> _M:
        """A deep copy: nested messages, lists and arrays are copied (an
        array copy is writable, even of a read-only received array)."""
        from copy import deepcopy

        cls = type(self)
        obj = cls.__new__(cls)
        memo[id(self)] = obj
        for name in _plan(cls).names:
            setattr(obj, name, deepcopy(getattr(self, name), memo))
        return obj

    def replace(self: _M, /, **changes: Any) -> _M:
        """A new instance with the fields in ``changes`` replaced, the others
        shared with this one (as ``dataclasses.replace``): the constructor
        runs, so its checks apply; an unknown name is a ``TypeError``."""
        values = {name: getattr(self, name) for name in _plan(type(self)).names}
        values.update(changes)
        return type(self)(**values)

    def __replace__(self: _M, /, **changes: Any) -> _M:
        """``copy.replace(message, **changes)`` (Python 3.13): :meth:`replace`."""
        return self.replace(**changes)

    def to_dict(self) -> dict[str, Any]:
        """This message as the dict the library's decoders give: nested
        messages as dicts, arrays of messages and of strings as lists,
        numeric and bool arrays as the numpy arrays they are (the same
        objects, not copies; ``ros_mobile_bridge.jsonable`` turns the
        result into JSON-safe data). Constants are not included."""
        plan = _plan(type(self))
        out: dict[str, Any] = {}
        for name, kind in zip(plan.names, plan.kinds, strict=True):
            value = getattr(self, name)
            if kind == MESSAGE:
                value = value.to_dict()
            elif kind == MESSAGES:
                value = [item.to_dict() for item in value]
            elif kind == STRINGS:
                value = list(value)
            out[name] = value
        return out

    @classmethod
    def from_dict(cls: type[_M], data: Mapping[str, Any]) -> _M:
        """An instance from a (partial) mapping such as :meth:`to_dict`
        gives: nested messages as mappings (or instances), lists of them
        for arrays of messages; a missing field takes its default. Raises
        :class:`~ros_mobile_bridge.MessageError` naming the field (its dotted
        path, ``"pose.pose.position"``) for an unknown field, a value that
        is not a mapping where a message is expected, and what the
        constructor refuses."""
        type_name = cls.__ros_type__
        if not isinstance(data, Mapping):
            raise MessageError(type_name, f"expected a mapping, got {type(data).__name__}")
        plan = _plan(cls)
        values: dict[str, Any] = {}
        for key, value in data.items():
            info = plan.fields.get(key) if isinstance(key, str) else None
            if info is None:
                names = ", ".join(plan.names) or "none"
                raise MessageError(type_name, f"unknown field ({type_name} has: {names})", str(key))
            if info.kind == MESSAGE:
                value = _nested_from(type_name, key, value, plan.nested_class(key))
            elif info.kind == MESSAGES and value is not None:
                sub = plan.nested_class(key)
                if isinstance(value, str | bytes) or not isinstance(value, Iterable):
                    raise MessageError(
                        type_name,
                        f"expected a list of {sub.__ros_type__}, got {type(value).__name__}",
                        key,
                    )
                value = [
                    _nested_from(type_name, f"{key}[{index}]", item, sub)
                    for index, item in enumerate(value)
                ]
            values[key] = value
        return cls(**values)


def _nested_from(type_name: str, path: str, value: Any, sub: type[RosMessage]) -> Any:
    """``value`` for a nested field of class ``sub``: a mapping converted;
    an instance (or None) as it is (the constructor checks it)."""
    if not isinstance(value, Mapping):
        return value
    try:
        return sub.from_dict(value)
    except MessageError as exc:
        field = f"{path}.{exc.field}" if exc.field else path
        raise MessageError(type_name, exc.reason, field) from None


class RosRequest(RosMessage, Generic[_Response]):
    """The base of a service's ``Request`` class: ``RosRequest[Response]``
    tells type checkers which class answers it, so
    ``call_service(name, AddTwoInts.Request(a=1, b=2))`` is known to return
    an ``AddTwoInts.Response``. Otherwise a :class:`RosMessage`."""

    __slots__ = ()


class RosGoal(RosMessage, Generic[_Result, _Feedback]):
    """The base of an action's ``Goal`` class: ``RosGoal[Result, Feedback]``
    tells type checkers what a goal's result and feedback are, so a goal
    sent as ``Fibonacci.Goal(order=5)`` has a ``Fibonacci.Result`` and
    ``Fibonacci.Feedback``. Otherwise a :class:`RosMessage`."""

    __slots__ = ()


class RosService(Generic[_Request, _Response]):
    """The base of every service class: a namespace holding the service's
    ``Request`` and ``Response`` classes, its ROS type name
    (``__ros_type__``, ``"std_srvs/srv/SetBool"``) and its ``RIHS01_`` hash
    (``__ros_hash__``). It has no instances. ``RosService[Request,
    Response]`` tells type checkers the two classes, so a service served as
    ``serve(name, AddTwoInts)`` hands out ``AddTwoInts.Request`` instances
    and takes ``AddTwoInts.Response`` replies."""

    __slots__ = ()

    __ros_type__: ClassVar[str]
    __ros_hash__: ClassVar[str]

    def __init__(self) -> None:
        name = type(self).__qualname__
        raise TypeError(f"{name} is a service type: its messages are {name}.Request and .Response")


class RosAction:
    """The base of every action class: a namespace holding the action's
    ``Goal``, ``Result`` and ``Feedback`` classes, the services and the
    message rcl carries them in (``SendGoal``, ``GetResult``,
    ``FeedbackMessage``), its ROS type name (``__ros_type__``) and its
    ``RIHS01_`` hash (``__ros_hash__``). It has no instances."""

    __slots__ = ()

    __ros_type__: ClassVar[str]
    __ros_hash__: ClassVar[str]

    def __init__(self) -> None:
        name = type(self).__qualname__
        raise TypeError(f"{name} is an action type: its goal is a {name}.Goal")


def lazy_kinds(package: str, kinds: tuple[str, ...]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of a generated package: ``pkg.msg`` (and
    ``srv``, ``action``) import on first use, so a module can refer to
    another package's classes without importing it."""

    def __getattr__(name: str) -> Any:
        if name in kinds:
            __import__(f"{package}.{name}")  # -X importtime shows it, as importlib's does not
            return sys.modules[f"{package}.{name}"]
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


def lazy_types(package: str, modules: Mapping[str, str]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of a generated kind (``pkg.msg``): each
    class (a key of ``modules``) imports its own module (the value,
    ``"_twist"``) on first use, and is then an attribute of the kind, so
    taking one class loads only the modules of the types it refers to."""

    def __getattr__(name: str) -> Any:
        stem = modules.get(name)
        if stem is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        __import__(f"{package}.{stem}")
        value = getattr(sys.modules[f"{package}.{stem}"], name)
        setattr(sys.modules[package], name, value)
        return value

    return __getattr__


# -- the constructors' helpers -------------------------------------------------------------


def _error(owner: RosMessage, field: str, reason: str) -> MessageError:
    return MessageError(type(owner).__ros_type__, reason, field)


def _info(owner: RosMessage, name: str) -> FieldInfo:
    return _plan(type(owner)).fields[name]


def _length(owner: RosMessage, name: str, info: FieldInfo, count: int) -> None:
    if info.fixed:
        if count != info.size:
            raise _error(owner, name, f"expected exactly {info.size} elements, got {count}")
    elif info.size and count > info.size:
        raise _error(owner, name, f"expected at most {info.size} elements, got {count}")


def _nested(owner: RosMessage, name: str, value: object, cls: type[_M]) -> _M:
    """A nested message field: ``value``, or a fresh zero message for None."""
    if value is None:
        return cls()
    if not isinstance(value, cls):
        reason = f"expected {cls.__ros_type__}, got {type(value).__name__}"
        if isinstance(value, Mapping):
            reason += f" (a dict converts with {cls.__qualname__}.from_dict)"
        raise _error(owner, name, reason)
    return value


def _messages(owner: RosMessage, name: str, value: object, cls: type[_M]) -> list[_M]:
    """An array of nested messages: a new list of ``value``'s items (each an
    instance of ``cls``), or the default (empty, or as many zero messages as
    a fixed-size array has)."""
    info = _info(owner, name)
    if value is None:
        return [cls() for _ in range(info.size)] if info.fixed else []
    if isinstance(value, str | bytes | Mapping) or not isinstance(value, Iterable):
        raise _error(
            owner, name, f"expected a list of {cls.__ros_type__}, got {type(value).__name__}"
        )
    items = list(value)
    _length(owner, name, info, len(items))
    for index, item in enumerate(items):
        if not isinstance(item, cls):
            reason = f"expected {cls.__ros_type__}, got {type(item).__name__}"
            raise _error(owner, f"{name}[{index}]", reason)
    return items


def _bounded(owner: RosMessage, name: str, value: str) -> str:
    """A bounded string field: ``value``, checked against its bound."""
    bound = _info(owner, name).string_bound
    if isinstance(value, str) and len(value) > bound:
        reason = f"string longer than its bound {bound} ({len(value)} characters)"
        raise _error(owner, name, reason)
    return value


def _strings(
    owner: RosMessage, name: str, value: Iterable[str] | None, default: tuple[str, ...] = ()
) -> list[str]:
    """An array of strings: a new list of ``value``'s items, or the default
    (the declared one, or empty, or as many ``""`` as a fixed-size array has)."""
    info = _info(owner, name)
    if value is None:
        if default:
            return list(default)
        return [""] * info.size if info.fixed else []
    if isinstance(value, str | bytes) or not isinstance(value, Iterable):
        raise _error(owner, name, f"expected a list of str, got {type(value).__name__}")
    items = list(value)
    _length(owner, name, info, len(items))
    if info.string_bound:
        for index, item in enumerate(items):
            if isinstance(item, str) and len(item) > info.string_bound:
                reason = (
                    f"string longer than its bound {info.string_bound} ({len(item)} characters)"
                )
                raise _error(owner, f"{name}[{index}]", reason)
    return items


def _array(
    owner: RosMessage, name: str, value: object, default: tuple[Any, ...] = ()
) -> NDArray[Any]:
    """A numeric or bool array field as a one-dimensional numpy array of the
    field's dtype: ``value`` as it is when it is one already (no copy: a
    read-only array stays read-only), else converted (a list, a tuple,
    ``bytes`` for an 8-bit integer array; a multi-dimensional array is
    flattened); None is the default (the declared one, or zeros)."""
    import numpy

    info = _info(owner, name)
    dtype = numpy.dtype(_DTYPES[info.element])
    if value is None:
        if default:
            return numpy.array(default, dtype)
        return numpy.zeros(info.size if info.fixed else 0, dtype)
    if isinstance(value, numpy.ndarray) and value.dtype == dtype:
        array: NDArray[Any] = value
    else:
        array = converted_array(owner, name, value, dtype, info.element)
    if array.ndim != 1:
        array = array.reshape(-1)
    _length(owner, name, info, array.shape[0])
    return array


def converted_array(
    owner: RosMessage, name: str, value: object, dtype: numpy.dtype[Any], element: str
) -> NDArray[Any]:
    import numpy

    if isinstance(value, bytes | bytearray | memoryview):
        if dtype.itemsize != 1 or dtype.kind == "b":
            reason = f"bytes are only accepted for 8-bit integer arrays, not {element}[]"
            raise _error(owner, name, reason)
        return numpy.frombuffer(value, numpy.uint8).view(dtype)
    if isinstance(value, str) or not isinstance(value, numpy.ndarray | Iterable):
        raise _error(owner, name, f"expected an array of {element}, got {type(value).__name__}")
    try:
        array = numpy.asarray(value)
    except (ValueError, TypeError, OverflowError) as exc:
        raise _error(owner, name, f"not an array of {element}: {exc}") from None
    if array.size == 0:
        return numpy.zeros(array.shape, dtype)
    have, want = array.dtype.kind, dtype.kind
    if want == "b":
        if have != "b" and (have not in "iu" or not numpy.isin(array, (0, 1)).all()):
            raise _error(owner, name, f"expected bools, got an array of {array.dtype}")
    elif want in "iu":
        if have in "iu":
            limits = numpy.iinfo(dtype)
            if int(array.min()) < limits.min or int(array.max()) > limits.max:
                raise _error(owner, name, f"array values out of range for {element}")
        elif have != "b":
            reason = f"expected integers ({element}), got an array of {array.dtype}"
            raise _error(owner, name, reason)
    elif have not in "biuf":
        reason = f"expected numbers ({element}), got an array of {array.dtype}"
        raise _error(owner, name, reason)
    elif dtype.itemsize == 4 and have == "f":
        finite = array[numpy.isfinite(array)]
        if finite.size and float(numpy.abs(finite).max()) > float(numpy.finfo(numpy.float32).max):
            raise _error(owner, name, "array values out of range for float32")
    return array.astype(dtype)


def _arrays_equal(a: object, b: object) -> bool:
    import numpy

    return bool(numpy.array_equal(a, b))  # type: ignore[arg-type]
