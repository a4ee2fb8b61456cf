"""The public surface and the layering rules, in the style of trio's
``_tests/test_exports.py``: what ``import ros_mobile_bridge`` offers is exactly
``__all__``, re-exported from private modules so type checkers see it, with
docstrings; and the layers import only what design.md allows them to."""

from __future__ import annotations

import ast
import importlib.resources
import inspect
import re
import subprocess
import sys
import types
from pathlib import Path

import pytest

import ros_mobile_bridge as rmb

PACKAGE = "ros_mobile_bridge"
PACKAGE_DIR = Path(rmb.__file__).parent
INIT_SOURCE = (PACKAGE_DIR / "__init__.py").read_text(encoding="utf-8")

PUBLIC_SUBMODULES = {"lag"}
"""Public modules re-exported by name (``rmb.lag``); their own names are
checked by ``test_lag_module_exports_its_readers``."""
PUBLIC_NAMES = sorted(set(rmb.__all__) - {"__version__"} - PUBLIC_SUBMODULES)
# What a user reaches as ``rmb.X``: __all__ plus any public attribute it misses.
API_NAMES = sorted(
    ({n for n, v in vars(rmb).items() if not isinstance(v, types.ModuleType)} | set(rmb.__all__))
    - {"__version__"}
    - PUBLIC_SUBMODULES
    - {n for n in vars(rmb) if n.startswith("_")}
)


def _is_private_path(dotted: str) -> bool:
    return any(part.startswith("_") for part in dotted.split("."))


def _init_imports() -> dict[str, tuple[str, str | None]]:
    """Name bound in ``__init__`` -> (absolute source module, ``as`` name)."""
    bound: dict[str, tuple[str, str | None]] = {}
    nodes: list[ast.stmt] = []
    for node in ast.parse(INIT_SOURCE).body:
        if isinstance(node, ast.If) and ast.unparse(node.test) == "_typing.TYPE_CHECKING":
            nodes.extend(node.body)  # the lazy names, as type checkers read them
        else:
            nodes.append(node)
    for node in nodes:
        if isinstance(node, ast.ImportFrom):
            assert node.level == 1, f"absolute import in __init__: {ast.unparse(node)}"
            module = f"{PACKAGE}.{node.module}" if node.module else PACKAGE
            for alias in node.names:
                bound[alias.asname or alias.name] = (module, alias.asname)
    return bound


# -- __all__ -------------------------------------------------------------------------
def test_all_has_no_duplicates() -> None:
    assert len(rmb.__all__) == len(set(rmb.__all__))


@pytest.mark.parametrize("name", rmb.__all__)
def test_every_name_in_all_exists(name: str) -> None:
    assert hasattr(rmb, name), name


def _public_attributes() -> set[str]:
    return {
        name
        for name, value in vars(rmb).items()
        if not name.startswith("_") and not isinstance(value, types.ModuleType)
    }


def test_every_public_attribute_is_in_all() -> None:
    assert _public_attributes() == set(PUBLIC_NAMES)


def test_lag_module_exports_its_readers() -> None:
    assert isinstance(rmb.lag, types.ModuleType)
    assert set(rmb.lag.__all__) == {
        "LagStats",
        "clear",
        "history_csv",
        "max_lag_ms",
        "recurring_lag_ms",
        "stats",
        "sustained_lag_ms",
    }
    for name in rmb.lag.__all__:
        assert getattr(rmb.lag, name).__doc__, name


@pytest.mark.parametrize("name", ["connect", "parse_target"])
def test_connect_and_parse_target_are_in_all(name: str) -> None:
    assert name in rmb.__all__


@pytest.mark.parametrize(
    ("name", "module"),
    [("cancel_on_signals", "_signals"), ("SignalScope", "_signals")],
)
def test_signal_helper_is_public(name: str, module: str) -> None:
    assert name in rmb.__all__
    assert getattr(rmb, name).__module__ == f"{PACKAGE}.{module}"


def test_register_type_and_check_velocity_are_public_api() -> None:
    assert rmb.Client.register_type.__doc__
    assert "check_velocity" in inspect.signature(rmb.Client.publish).parameters


def test_star_import_gives_exactly_all() -> None:
    namespace: dict[str, object] = {}
    exec(f"from {PACKAGE} import *", namespace)  # the point of the test
    namespace.pop("__builtins__")
    assert set(namespace) == set(rmb.__all__)


def test_lazy_table_matches_the_type_checking_imports() -> None:
    # what type checkers read (the TYPE_CHECKING block) is what loads at run time
    table = {
        name: (f"{PACKAGE}{module}" if module else PACKAGE, attr)
        for name, (module, attr) in rmb._LAZY.items()
    }
    bound = _init_imports()
    bound.pop("__version__")
    assert {name: module for name, (module, _) in table.items()} == {
        name: module for name, (module, _) in bound.items()
    }
    assert set(table) | {"__version__"} == set(rmb.__all__)


def test_import_loads_no_dependency() -> None:
    # ``import ros_mobile_bridge`` stays light (issue 11: it took 161 ms with
    # numpy loaded eagerly); each name loads its module on first use
    code = (
        "import sys, ros_mobile_bridge as rmb\n"
        "heavy = ('numpy', 'websockets', 'rosbags', 'cbor2', 'anyio', 'zenoh')\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & set(heavy)))\n"
        "rmb.ConnectError\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & set(heavy)))\n"
        "rmb.connect\n"
        "print('numpy' in sys.modules, 'websockets' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split("\n")
    assert out[:3] == ["[]", "[]", "True True"]


def test_unknown_attribute_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="no attribute 'nosuch'"):
        rmb.nosuch  # noqa: B018
    assert not hasattr(rmb, "_nosuch")


def test_version_is_a_string() -> None:
    assert isinstance(rmb.__version__, str)
    assert rmb.__version__


# -- re-exported from private modules --------------------------------------------------
@pytest.mark.parametrize("name", API_NAMES)
def test_public_names_use_the_explicit_reexport_form(name: str) -> None:
    # ``from ._x import Y as Y`` is what marks a re-export for type checkers.
    bound = _init_imports()
    assert name in bound, f"{name} is not imported in __init__.py"
    module, asname = bound[name]
    assert asname == name, f"write `from {module} import {name} as {name}`"
    source = importlib.import_module(module)
    assert getattr(source, name) is getattr(rmb, name)


@pytest.mark.parametrize("name", API_NAMES)
def test_public_names_are_defined_in_private_modules(name: str) -> None:
    obj = getattr(rmb, name)
    if inspect.isclass(obj) or inspect.isfunction(obj):
        home = obj.__module__
    else:  # type aliases and constants: where __init__ takes them from
        home = _init_imports()[name][0]
    assert home.startswith(f"{PACKAGE}."), home
    assert _is_private_path(home.removeprefix(f"{PACKAGE}.")), (
        f"{name} lives in the public module {home}; define it in a private one"
    )


def test_connect_and_parse_target_come_from_connect_module() -> None:
    assert rmb.connect.__module__ == f"{PACKAGE}._connect"
    assert rmb.parse_target.__module__ == f"{PACKAGE}._connect"


# -- docstrings -------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name",
    [
        n
        for n in API_NAMES
        if inspect.isclass(getattr(rmb, n)) or inspect.isfunction(getattr(rmb, n))
    ],
)
def test_public_classes_and_functions_have_docstrings(name: str) -> None:
    obj = getattr(rmb, name)
    if isinstance(obj, type):
        doc = obj.__dict__.get("__doc__")  # its own, not inherited
        # a dataclass without a docstring gets "Name(field: type, ...)"
        assert doc and not doc.startswith(f"{obj.__name__}("), f"{name} has no docstring"
    else:
        assert inspect.getdoc(obj), f"{name} has no docstring"


def test_package_has_a_docstring() -> None:
    assert rmb.__doc__
    assert rmb.__doc__.strip()


# -- packaging ---------------------------------------------------------------------------------
def test_py_typed_ships_in_the_package() -> None:
    marker = importlib.resources.files(PACKAGE).joinpath("py.typed")
    assert marker.is_file()
    assert (PACKAGE_DIR / "py.typed").is_file()


def test_the_wheel_packages_the_whole_package_dir() -> None:
    # hatchling ships every file under the listed package dir, py.typed included.
    pyproject = PACKAGE_DIR.parents[1] / "pyproject.toml"
    if not pyproject.is_file():
        pytest.skip("not running from a source checkout")
    text = pyproject.read_text(encoding="utf-8")
    assert re.search(r'packages\s*=\s*\[\s*"src/ros_mobile_bridge"\s*\]', text)
    assert "Typing :: Typed" in text


# -- layering ------------------------------------------------------------------------------------
def _modules_in(subpackage: str, *, nested: bool = False) -> list[Path]:
    folder = PACKAGE_DIR / subpackage
    files = sorted(folder.rglob("*.py") if nested else folder.glob("*.py"))
    assert files, f"no modules in {subpackage}/"
    return files


def _imports(path: Path) -> set[str]:
    """Every module ``path`` imports, as absolute dotted names (for
    ``from pkg import name`` both ``pkg`` and ``pkg.name``)."""
    # the package a module (or an __init__) belongs to: its folder
    package = list(path.relative_to(PACKAGE_DIR.parent).parent.parts)
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                module = ".".join([*base, *([node.module] if node.module else [])])
            else:
                module = node.module or ""
            found.add(module)
            found.update(f"{module}.{alias.name}" for alias in node.names)
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute | ast.Name)
            and (getattr(node.func, "attr", None) or getattr(node.func, "id", None))
            in ("import_module", "__import__")
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            found.add(node.args[0].value)
    return found


def _hits(imported: set[str], forbidden: tuple[str, ...]) -> list[str]:
    return sorted(
        name for name in imported for bad in forbidden if name == bad or name.startswith(bad + ".")
    )


def test_import_resolution_helper_sees_relative_imports() -> None:
    found = _imports(PACKAGE_DIR / "flow" / "_subscription.py")
    assert "anyio" in found
    assert f"{PACKAGE}._errors" in found
    assert f"{PACKAGE}.flow._frame" in found
    found = _imports(PACKAGE_DIR / "flow" / "__init__.py")
    assert f"{PACKAGE}.flow._subscription" in found
    # the rule checks can fire: the backends do use the wire engines
    backend_imports = set().union(*map(_imports, _modules_in("adapters")))
    assert _hits(backend_imports, (f"{PACKAGE}.wire",))


def test_units_are_the_longest_that_prefix_a_module() -> None:
    assert _unit(f"{PACKAGE}._core._router.Route") == "_core._router"
    assert _unit(f"{PACKAGE}._loop._wakeup.new_wakeup") == "_loop"
    assert _unit(f"{PACKAGE}.wire._limits") == "wire"
    assert _unit(f"{PACKAGE}._sync._client") == "_sync"
    assert _unit(PACKAGE) == "__init__"
    assert _unit_of_path(PACKAGE_DIR / "_core" / "_client.py") == "_core._client"
    assert _unit_of_path(PACKAGE_DIR / "_core" / "_unplaced.py") == "_core._unplaced"
    assert _unit_of_path(PACKAGE_DIR / "wire" / "_foxglove" / "_engine.py") == "wire"
    # the client core as a whole stands with its top: nothing below imports it
    assert _unit_of_path(PACKAGE_DIR / "_core" / "__init__.py") == "_core"
    assert RANK["_core"] == RANK["_core._client"] > RANK["_core._router"] > RANK["adapters"]


EVENT_LOOPS = ("anyio", "asyncio", "trio", "sniffio")


@pytest.mark.parametrize(
    "path",
    _modules_in("wire", nested=True),
    ids=lambda p: p.relative_to(PACKAGE_DIR / "wire").as_posix(),
)
def test_wire_engines_import_no_event_loop(path: Path) -> None:
    assert _hits(_imports(path), EVENT_LOOPS) == []
    # and no textual import hidden from the AST walk (e.g. in a string exec)
    source = path.read_text(encoding="utf-8")
    assert not re.search(r"^\s*(import|from)\s+(anyio|asyncio|trio)\b", source, re.MULTILINE)


@pytest.mark.parametrize(
    "path",
    _modules_in("wire", nested=True),
    ids=lambda p: p.relative_to(PACKAGE_DIR / "wire").as_posix(),
)
def test_wire_engines_do_no_io_and_know_no_other_layer(path: Path) -> None:
    forbidden = (
        "socket",
        "ssl",
        "selectors",
        "threading",
        "websockets",
        "zenoh",
        f"{PACKAGE}.flow",
        f"{PACKAGE}.transport",
        f"{PACKAGE}.adapters",
        f"{PACKAGE}._loop",
        f"{PACKAGE}._core",
        f"{PACKAGE}._connect",
        f"{PACKAGE}._sync",
    )
    assert _hits(_imports(path), forbidden) == []


@pytest.mark.parametrize("path", _modules_in("flow"), ids=lambda p: p.name)
def test_flow_knows_no_protocol(path: Path) -> None:
    forbidden = (
        f"{PACKAGE}.wire",
        f"{PACKAGE}.adapters",
        f"{PACKAGE}.transport",
        "websockets",
        "zenoh",
    )
    assert _hits(_imports(path), forbidden) == []


# -- the house: layers, each importing only what stands below it ------------------------

LAYERS: tuple[frozenset[str], ...] = (
    frozenset({"_errors", "_types", "_slots", "_version", "_checks", "_loop", "_zenoh_options"}),
    frozenset({"wire", "codec", "interfaces", "flow", "transport", "_signals"}),
    frozenset({"_options", "lag"}),
    frozenset({"adapters"}),
    frozenset(
        {
            "_core._serve",
            "_core._arguments",
            "_core._outbound",
            "_core._action",
            "_core._published_types",
            "_core._rejection_log",
        }
    ),
    frozenset({"_core._router"}),
    frozenset({"_core._connection"}),
    frozenset({"_core._record"}),
    frozenset({"_core._client"}),
    frozenset({"_connect"}),
    frozenset({"_sync", "demo"}),
    frozenset({"_cli", "cli", "__main__", "__init__"}),
)
"""The package's units, bottom first: a unit may import units of its own
layer or below, never above (see docs/architecture.md). A unit is a module
of the package root, a folder (``_loop``, ``wire``, ``_sync``...: everything
in it) or, for a folder whose modules stand in several layers (the client
core, ``_core``), one module of it, dotted (``_core._router``): a module
belongs to the longest unit its dotted name starts with. Such a folder
imported as a whole (its ``__init__``) ranks with its highest unit, so
nothing below the client core imports ``_core``; every module in it needs
a unit of its own."""


def _ranks() -> dict[str, int]:
    units = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}
    ranks = dict(units)
    for unit, i in units.items():
        parts = unit.split(".")
        for n in range(1, len(parts)):
            folder = ".".join(parts[:n])
            if folder not in units:
                ranks[folder] = max(ranks.get(folder, i), i)
    return ranks


RANK = _ranks()
"""Unit -> its layer's index, and each split folder -> its highest unit's."""
SPLIT_FOLDERS = frozenset(RANK) - set().union(*LAYERS)
"""Folders whose modules stand in several layers (``_core``)."""


def _unit(module: str) -> str:
    """The unit of an absolute dotted name (a module, or a name in one): the
    longest unit of ``LAYERS`` or split folder it starts with; ``__init__``
    for the package itself; else its top-level name (a unit ``LAYERS``
    misses)."""
    parts = module.split(".")[1:]
    if not parts:
        return "__init__"
    for n in range(len(parts), 0, -1):
        candidate = ".".join(parts[:n])
        if candidate in RANK:
            return candidate
    return parts[0]


def _unit_of_path(path: Path) -> str:
    parts = path.relative_to(PACKAGE_DIR).with_suffix("").parts
    if parts == ("__init__",):
        return "__init__"
    module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
    unit = _unit(f"{PACKAGE}.{module}")
    if unit in SPLIT_FOLDERS and unit != module:
        return module  # a module of a split folder: it needs a unit of its own
    return unit


def test_every_unit_has_a_layer() -> None:
    units = {_unit_of_path(p) for p in PACKAGE_DIR.rglob("*.py")}
    assert units - set(RANK) == set(), "add the new module to LAYERS"


@pytest.mark.parametrize(
    "path", sorted(PACKAGE_DIR.rglob("*.py")), ids=lambda p: str(p.relative_to(PACKAGE_DIR))
)
def test_nothing_imports_a_layer_above_it(path: Path) -> None:
    mine = _unit_of_path(path)
    if mine == "__init__":
        return  # the package face re-exports everything
    assert mine in RANK, f"add {mine} to LAYERS"
    above = sorted(
        name
        for name in _imports(path)
        if name.startswith(PACKAGE + ".") and RANK.get(_unit(name), -1) > RANK[mine]
    )
    assert above == []


def test_no_import_circles_between_modules() -> None:
    """Every import counts (lazy and TYPE_CHECKING ones too); package faces
    (``__init__`` re-exports) are not part of a circle."""
    modules = {
        ".".join(p.relative_to(PACKAGE_DIR.parent).with_suffix("").parts): p
        for p in PACKAGE_DIR.rglob("*.py")
        if p.name != "__init__.py"
    }
    graph = {
        name: {m for m in _imports(path) if m in modules and m != name}
        for name, path in modules.items()
    }
    done: set[str] = set()
    path_: list[str] = []

    def visit(node: str) -> None:
        if node in done:
            return
        assert node not in path_, "import circle: " + " -> ".join(
            [*path_[path_.index(node) :], node]
        )
        path_.append(node)
        for nxt in sorted(graph[node]):
            visit(nxt)
        path_.pop()
        done.add(node)

    for name in sorted(graph):
        visit(name)
