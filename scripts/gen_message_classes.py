#!/usr/bin/env python3
"""Generate the interface classes: src/ros_mobile_bridge/interfaces/<package>/.

    .venv/bin/python scripts/gen_message_classes.py [--check]

Reads the bundled interfaces (``codec/_interfaces.json.gz``, written by
``scripts/gen-interfaces``) through the library's own parser, and writes, for
each bundled package, ``<package>/__init__.py`` and a package per kind it has
(``msg/``, ``srv/``, ``action/``), laid out as rclpy's: one module per
interface, named as rosidl names it (``msg/_twist_with_covariance.py``),
holding its one class (a message; a service with its ``Request`` and
``Response`` nested; an action with its ``Goal``, ``Result``, ``Feedback``,
``SendGoal``, ``GetResult`` and ``FeedbackMessage`` nested), and the kind's
``__init__.py``, its public face, importing each class's module on first
use. Each class carries its type name and RIHS01 hash from the bundle, and
the ``.msg`` text's comments as its docstring. The writing is the library's
(``ros_mobile_bridge.interfaces._generate`` and ``._emit``, which ``rmb
interface generate`` and the classes made at run time share); this script
reads the bundle and writes the files.

The output is deterministic and already in the shape ``ruff format`` gives;
``--check`` compares instead of writing (exit 1 on a difference), as
``tests/test_message_classes_current.py`` does in memory. Run it after the
bundle changes (see CONTRIBUTING.md).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "src" / "ros_mobile_bridge" / "interfaces"
HAND_WRITTEN = frozenset({"__init__.py", "_base.py", "_emit.py", "_generate.py", "_runtime.py"})
"""The files of OUT that this script does not write."""
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

from ros_mobile_bridge._errors import SchemaError  # noqa: E402
from ros_mobile_bridge.interfaces._emit import module_stem  # noqa: E402
from ros_mobile_bridge.interfaces._generate import BUNDLED_HEADER, Layout  # noqa: E402
from ros_mobile_bridge.interfaces._generate import generate_from as _generate_from  # noqa: E402

HEADER = BUNDLED_HEADER
__all__ = ["HEADER", "differences", "existing", "generate", "generate_from", "module_stem"]


def generate() -> dict[str, str]:
    """Every generated file's text by its path relative to the interfaces
    package (``"geometry_msgs/msg/_twist.py"``), from the bundle."""
    from ros_mobile_bridge.codec._bundled import (
        bundled_hash,
        bundled_interface,
        bundled_interface_names,
        bundled_packages,
    )

    texts: dict[str, str] = {}
    for name in bundled_interface_names():
        interface = bundled_interface(name)
        assert interface is not None
        texts[name] = interface.text
    return generate_from(texts, bundled_packages(), bundled_hash)


def generate_from(
    interfaces: Mapping[str, str],
    packages: Mapping[str, str],
    hashes: Callable[[str], str | None],
) -> dict[str, str]:
    """The files for ``interfaces`` (name -> text), with each package's
    version from ``packages`` and each type's hash from ``hashes``; exits
    with the reason when the classes cannot express a definition."""
    supplement = frozenset(p for p, version in packages.items() if version == "supplement")
    try:
        return _generate_from(interfaces, Layout(HEADER, packages), hashes, supplement)
    except SchemaError as exc:
        raise SystemExit(str(exc)) from None


def existing(root: Path = OUT) -> dict[str, str]:
    """The generated files on disk, by the same relative paths."""
    out: dict[str, str] = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel in HAND_WRITTEN:
            continue
        out[rel] = path.read_text(encoding="utf-8")
    return out


def differences(wanted: dict[str, str], have: dict[str, str]) -> Iterator[str]:
    for rel in sorted(set(wanted) | set(have)):
        if rel not in have:
            yield f"missing: {rel}"
        elif rel not in wanted:
            yield f"not generated (stale): {rel}"
        elif wanted[rel] != have[rel]:
            yield f"differs: {rel}"


def write(files: dict[str, str], root: Path = OUT) -> None:
    """Write ``files`` under ``root``; remove the generated files it no longer has."""
    for rel in existing(root):
        if rel not in files:
            (root / rel).unlink()
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.is_file() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")


def _stats(files: Iterable[tuple[str, str]]) -> str:
    lines = [text.count("\n") for _, text in files]
    return f"{len(lines)} files, {sum(lines)} lines"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write")
    args = parser.parse_args(argv)
    files = generate()
    if args.check:
        problems = list(differences(files, existing()))
        for problem in problems:
            print(problem)
        print(f"{OUT}: {'DIFFERS' if problems else 'up to date'} ({_stats(files.items())})")
        return 1 if problems else 0
    write(files)
    print(f"wrote {OUT} ({_stats(files.items())})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
