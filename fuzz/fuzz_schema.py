"""Fuzz harness for schema texts (``CodecRegistry.add_schema``) and what is built on them.

Each example registers one to three schemas in a fresh :class:`CodecRegistry`
(the same name may come twice: a redefinition). A schema is ``ros2msg``,
``ros2idl`` or ``jsonschema`` text: a valid seed (concatenated ``.msg``
definitions with ``=====``/``MSG:`` separators, ``.srv`` and ``.action``
texts, defaults and constants; IDL modules with several ``IDL:`` blocks,
annotations, bounded sequences and strings; JSON Schema objects with
``$ref``, ``allOf``, fixed-size arrays, defaults), the seed mutated (characters
and tokens of the language inserted, deleted or replaced, lines dropped,
duplicated or swapped, the text cut short, two seeds spliced, JSON values
replaced), or random text. Names are mostly valid type names (including a
bundled one, so a server definition overrides it), sometimes random.

The contract checked:

* ``add_schema`` registers the text or raises :class:`SchemaError` (an
  invalid *name* may raise ``ValueError``, the documented argument error);
  never another exception, within :data:`DEADLINE_S`;
* for what registered: ``decoder``/``encoder`` (``cdr`` and ``json``),
  ``template`` and ``definition`` return or raise :class:`SchemaError`, never
  another exception;
* when both CDR codecs build, ``encoder({})`` encodes (the template with the
  declared defaults) and decoding it gives back ``template()``.

Run it directly::

    python fuzz/fuzz_schema.py --examples 20000 [--seed 1]

or import it and call :func:`run` (``tests/test_fuzz_parsers_smoke.py`` does).
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st

from ros_mobile_bridge.interfaces._base import RosMessage

try:
    from ros_mobile_bridge import DecodeError, SchemaError
    from ros_mobile_bridge.codec import CodecRegistry
except ImportError:  # a checkout that is not installed: use its src/
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    from ros_mobile_bridge import DecodeError, SchemaError
    from ros_mobile_bridge.codec import CodecRegistry

try:
    from _harness import cli_main, run_sessions
except ImportError:  # loaded by its path (the smoke tests): the harness is beside it
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _harness import cli_main, run_sessions

__all__ = ["IDL_SEEDS", "JSONSCHEMA_SEEDS", "MSG_SEEDS", "STATS", "run", "run_session"]

DEADLINE_S = 5.0
"""The most CPU time one registration plus its codec builds may take (this
thread's: a busy machine slows the wall clock, not this)."""

_SEP = "=" * 80

MSG_SEEDS: tuple[tuple[str, str], ...] = (
    ("fuzz_msgs/msg/Text", "string data\n"),
    (
        "fuzz_msgs/msg/Twist",
        "Vector3 linear\nVector3 angular\n"
        f"{_SEP}\nMSG: fuzz_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
    ),
    (
        "fuzz_msgs/msg/Defaults",
        "# constants and defaults\n"
        "int32 MAX=7\nstring GREETING='hi'\nfloat64 PI=3.14\n"
        "int8 a 3\nuint8[2] pair [1, 2]\nfloat64[] values [1.0, -2.5]\n"
        'string<=5 name "abc"\nbool flag true\nstring[] words ["x", "y"]\n'
        "float32 ratio 0.1\nchar c 65\nbyte b 200\n",
    ),
    (
        "fuzz_msgs/msg/Nested",
        "std_msgs/Header header\nInner[] items\nInner[<=2] few\nInner[3] three\n"
        "string<=4[<=3] tags\nbuiltin_interfaces/Time stamp\n"
        f"{_SEP}\nMSG: fuzz_msgs/Inner\nint64 id\nLeaf[] leaves\nuint8[4] raw\n"
        f"{_SEP}\nMSG: fuzz_msgs/Leaf\nstring text\nfloat32[2] xy\n",
    ),
    ("fuzz_msgs/srv/SetFlag", "bool data\n---\nbool success\nstring message\n"),
    ("fuzz_msgs/action/Count", "int32 order\n---\nint32[] sequence\n---\nint32[] partial\n"),
    ("fuzz_msgs/msg/Empty", ""),
    ("std_msgs/msg/String", "string data\nuint32 extra\n"),  # overrides the bundled one
)

IDL_SEEDS: tuple[tuple[str, str], ...] = (
    (
        "fuzz_msgs/msg/Point",
        "#ifndef FUZZ__POINT_IDL\n#define FUZZ__POINT_IDL\n"
        '#include "fuzz_msgs/msg/Leaf.idl"\n'
        "module fuzz_msgs {\n  module msg {\n"
        "    module Point_Constants {\n      const int32 MAX = 5;\n"
        '      const string NAME = "p";\n    };\n'
        '    @verbatim (language="comment", text="A point.")\n'
        "    struct Point {\n      double x;\n"
        "      @default (value=1.5)\n      float y;\n"
        "      sequence<int32, 5> ids;\n      string<8> name;\n"
        "      int8 arr[3];\n      sequence<fuzz_msgs::msg::Leaf> leaves;\n"
        "      boolean flag;\n      octet raw;\n      uint64 big;\n    };\n  };\n};\n"
        "#endif\n"
        f"{_SEP}\nIDL: fuzz_msgs/msg/Leaf\n"
        "module fuzz_msgs {\n  module msg {\n    struct Leaf {\n"
        "      string text;\n      sequence<double> values;\n    };\n  };\n};\n",
    ),
    (
        "fuzz_msgs/msg/Simple",
        "module fuzz_msgs {\n  module msg {\n    struct Simple {\n"
        "      int32 a;\n      string b;\n      double c[2];\n    };\n  };\n};\n",
    ),
    (
        "fuzz_msgs/msg/Typedefs",
        "module fuzz_msgs {\n  module msg {\n    typedef double double__9[9];\n"
        "    struct Typedefs {\n      double__9 k;\n"
        "      builtin_interfaces::msg::Time stamp;\n    };\n  };\n};\n",
    ),
)

JSONSCHEMA_SEEDS: tuple[tuple[str, str], ...] = (
    ("fuzz_msgs/msg/JText", '{"type":"object","properties":{"data":{"type":"string"}}}'),
    (
        "fuzz_msgs/msg/JNested",
        json.dumps(
            {
                "title": "JNested",
                "type": "object",
                "$defs": {"Vec": {"type": "object", "properties": {"x": {"type": "number"}}}},
                "properties": {
                    "v": {"$ref": "#/$defs/Vec"},
                    "fixed": {"type": "array", "items": {"type": "integer"}, "minItems": 3}
                    | {"maxItems": 3},
                    "tuple": {"type": "array", "prefixItems": [{"type": "string"}]}
                    | {"minItems": 2, "maxItems": 2, "items": {"type": "boolean"}},
                    "mode": {"enum": ["a", "b"]},
                    "k": {"const": 4},
                    "d": {"type": "number", "default": 1.5},
                    "both": {"allOf": [{"$ref": "#/$defs/Vec"}, {"properties": {"y": {}}}]},
                    "either": {"anyOf": [{"type": "null"}, {"type": "string"}]},
                    "types": {"type": ["null", "integer"]},
                },
            }
        ),
    ),
    ("fuzz_msgs/msg/JTrue", "true"),
    ("fuzz_msgs/msg/JLoop", '{"$ref":"#","properties":{"self":{"$ref":"#"}}}'),
)

_MSG_TOKENS = (
    "int32", "uint8", "byte", "char", "bool", "string", "wstring", "float32", "float64",
    "int64", "uint64", "time", "duration", "Header", "std_msgs/Header", "fuzz_msgs/Leaf",
    "Inner", "Missing", "[", "]", "[<=", "<=", "[]", "[3]", "[0]", "[<=0]", "<=0", "=", " ",
    "#", "'", '"', ",", "---", "\n", "\n---\n", f"\n{_SEP}\n", "MSG: ", "MSG: fuzz_msgs/Leaf",
    "IDL: ", "-1", "0", "65536", "4294967296", "1e309", "nan", "-0x1", "true", "[1, 2]",
    "__", "_x", "9x", "Ünï", "\t", "\x00",
)  # fmt: skip
_IDL_TOKENS = (
    "module", "struct", "typedef", "const", "sequence<", "sequence<int32, 0>", ">", "<",
    "string<", "wstring", "double", "float", "long", "long double", "unsigned", "short",
    "octet", "boolean", "char", "wchar", "int8", "uint64", "::", ";", "{", "}", "[", "]",
    "[0]", "[99999]", "@default (value=", "@key", "@verbatim (", ")", "(", "=", ",", '"',
    "#include", "#define X", "\n", " ", "enum E { A, B };", "union", "fuzz_msgs::msg::Leaf",
    "builtin_interfaces::msg::Time", f"\n{_SEP}\nIDL: fuzz_msgs/msg/X\n", "0x10", "-1", "1.5e3",
)  # fmt: skip
_JSON_TOKENS = (
    "{", "}", "[", "]", ":", ",", '"', "null", "true", "false", "0", "-1", "1e999", "NaN",
    '"type"', '"object"', '"array"', '"$ref"', '"#/"', '"properties"', '"items"',
    '"minItems"', '"maxItems"', '"allOf"', '"default"', '"enum"', "\\u0000", "\\ud800",
)  # fmt: skip

_NAMES = (
    "fuzz_msgs/msg/T",
    "fuzz_msgs/T",
    "fuzz_msgs/srv/T",
    "fuzz_msgs/action/T",
    "fuzz_msgs/msg/Leaf",
    "std_msgs/msg/String",
    "geometry_msgs/Vector3",
)

STATS: Counter[str] = Counter()
"""What the run reached (printed by ``main``)."""


# --------------------------------------------------------------------------
# Texts


def _mutate_text(text: str, tokens: tuple[str, ...], data: st.DataObject) -> str:
    for _ in range(data.draw(st.integers(1, 4))):
        op = data.draw(st.integers(0, 6))
        pos = data.draw(st.integers(0, len(text)))
        if op == 0:
            text = text[:pos] + data.draw(st.sampled_from(tokens)) + text[pos:]
        elif op == 1:
            end = data.draw(st.integers(pos, min(len(text), pos + 12)))
            text = text[:pos] + text[end:]
        elif op == 2:
            text = text[:pos] + data.draw(st.text(max_size=3)) + text[pos + 1 :]
        elif op in (3, 4):
            lines = text.split("\n")
            i = data.draw(st.integers(0, len(lines) - 1))
            j = data.draw(st.integers(0, len(lines) - 1))
            if op == 3:
                lines.insert(j, lines[i])  # a duplicated line (a duplicate field)
            else:
                lines[i], lines[j] = lines[j], lines[i]
            text = "\n".join(lines)
        elif op == 5:
            lines = text.split("\n")
            del lines[data.draw(st.integers(0, len(lines) - 1))]
            text = "\n".join(lines)
        else:
            text = text[:pos]
    return text


_json_values = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-3, 5),
        st.integers(-(2**70), 2**70),
        st.floats(),
        st.text(max_size=6),
        st.sampled_from(("object", "array", "string", "number", "integer", "#", "#/$defs/Vec")),
    ),
    lambda inner: st.one_of(
        st.lists(inner, max_size=3),
        st.dictionaries(
            st.one_of(
                st.sampled_from(
                    (
                        "type",
                        "properties",
                        "items",
                        "prefixItems",
                        "minItems",
                        "maxItems",
                        "$ref",
                        "allOf",
                        "anyOf",
                        "oneOf",
                        "default",
                        "const",
                        "enum",
                        "title",
                    )
                ),
                st.text(max_size=4),
            ),
            inner,
            max_size=4,
        ),
    ),
    max_leaves=15,
)


def _mutate_json(value: Any, data: st.DataObject, depth: int = 0) -> Any:
    choice = data.draw(st.integers(0, 4 if depth else 2))
    if choice == 0:
        return data.draw(_json_values)
    if isinstance(value, dict) and value:
        key = data.draw(st.sampled_from(sorted(value)))
        out = dict(value)
        if choice == 1:
            del out[key]
        else:
            out[key] = _mutate_json(value[key], data, depth + 1)
        return out
    if isinstance(value, list) and value:
        index = data.draw(st.integers(0, len(value) - 1))
        out_list = list(value)
        out_list[index] = _mutate_json(value[index], data, depth + 1)
        return out_list
    return data.draw(_json_values) if choice < 3 else value


def _deep(encoding: str, data: st.DataObject) -> tuple[str, str]:
    """A schema nested ``depth`` levels: a chain of message types, IDL
    modules, or JSON Schema objects (through properties, items, allOf,
    ``$ref``-free defaults and consts)."""
    depth = data.draw(st.sampled_from((8, 40, 70, 130, 300, 600, 2000)), label="depth")
    if encoding == "ros2msg":
        depth = min(depth, 120)  # a long chain is a slow (schema-size) case, not a deep one
        blocks = ["T1 next\n"]
        blocks += [f"{_SEP}\nMSG: fuzz_msgs/T{i}\nT{i + 1} next\n" for i in range(1, depth)]
        blocks.append(f"{_SEP}\nMSG: fuzz_msgs/T{depth}\nint32 leaf\n")
        return "fuzz_msgs/msg/T0", "".join(blocks)
    if encoding == "ros2idl":
        opened = "".join(f"module m{i} {{ " for i in range(depth))
        return "m0/msg/T", opened + "struct T { int32 a; }; " + "}; " * depth
    where = data.draw(st.sampled_from(("default", "const", "enum", "properties", "items", "allOf")))
    if where in ("default", "const", "enum"):
        inner = "[" * depth + "]" * depth
        value = f"[{inner}]" if where == "enum" else inner
        return "fuzz_msgs/msg/JDeep", f'{{"properties":{{"a":{{"{where}":{value}}}}}}}'
    opening, closing = {
        "properties": ('{"type":"object","properties":{"a":', "}}"),
        "items": ('{"type":"array","minItems":1,"maxItems":1,"items":', "}"),
        "allOf": ('{"allOf":[', "]}"),
    }[where]
    return "fuzz_msgs/msg/JDeep", opening * depth + '{"type":"string"}' + closing * depth


def _schema(data: st.DataObject) -> tuple[str, str, str | bytes, str]:
    """(name, encoding, text, how it was made)."""
    encoding = data.draw(st.sampled_from(("ros2msg", "ros2msg", "ros2idl", "jsonschema")))
    seeds, tokens = {
        "ros2msg": (MSG_SEEDS, _MSG_TOKENS),
        "ros2idl": (IDL_SEEDS, _IDL_TOKENS),
        "jsonschema": (JSONSCHEMA_SEEDS, _JSON_TOKENS),
    }[encoding]
    name, text = data.draw(st.sampled_from(seeds))
    kind = data.draw(st.integers(0, 7), label="schema kind")
    how = "seed"
    if kind == 7:
        name, text = _deep(encoding, data)
        how = "deep"
    elif kind in (1, 2, 3):
        text, how = _mutate_text(text, tokens, data), "mutated"
    elif kind == 4:
        _, other = data.draw(st.sampled_from(seeds))
        text = (
            text[: data.draw(st.integers(0, len(text)))]
            + other[data.draw(st.integers(0, len(other))) :]
        )
        how = "spliced"
    elif kind == 5 and encoding == "jsonschema":
        text, how = json.dumps(_mutate_json(json.loads(text), data)), "mutated json"
    elif kind == 5:
        text = "".join(data.draw(st.lists(st.sampled_from(tokens), max_size=20)))
        how = "tokens"
    elif kind == 6:
        text, how = data.draw(st.text(max_size=80)), "random"
    naming = data.draw(st.integers(0, 9))
    if naming == 0:
        name = data.draw(st.sampled_from(_NAMES))
    elif naming == 1:
        name = data.draw(st.text(max_size=20))
    raw: str | bytes = text
    if data.draw(st.integers(0, 9)) == 0:
        raw = text.encode("utf-8", "surrogatepass")
        if raw and data.draw(st.booleans()):
            raw = raw[:-1] + b"\xff"  # not UTF-8
    return name, encoding, raw, f"{encoding} {how}"


# --------------------------------------------------------------------------
# Checks


def _plain(value: Any) -> Any:
    if isinstance(value, RosMessage):
        return _plain(value.to_dict())
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _close(got: Any, want: Any) -> bool:
    """Equal, floats up to float32 rounding (a ``float32`` default of 0.1
    decodes as 0.10000000149...)."""
    if isinstance(want, float | int) and isinstance(got, float | int):
        if isinstance(want, bool) or isinstance(got, bool):
            return got == want
        return got == want or math.isclose(got, want, rel_tol=1e-6) or (got != got and want != want)
    if isinstance(want, dict):
        return (
            isinstance(got, dict)
            and got.keys() == want.keys()
            and all(_close(got[k], want[k]) for k in want)
        )
    if isinstance(want, list):
        return (
            isinstance(got, list)
            and len(got) == len(want)
            and all(_close(g, w) for g, w in zip(got, want, strict=True))
        )
    return bool(got == want)


def _attempt(what: str, call: Any) -> Any:
    """``call()``; ``None`` after a :class:`SchemaError` (counted)."""
    try:
        out = call()
    except SchemaError:
        STATS[f"{what}: SchemaError"] += 1
        return None
    STATS[f"{what}: ok"] += 1
    return out


def _use(registry: CodecRegistry, name: str, encoding: str) -> None:
    """Everything built on a registered schema raises SchemaError or works."""
    names = [name]
    if encoding != "jsonschema":
        names += [f"{name}{s}" for s in ("_Request", "_Response", "_Goal", "_Result", "_Feedback")]
    for typ in names:
        template = _attempt("template", lambda typ=typ: registry.template(typ))
        _attempt("definition", lambda typ=typ: registry.definition(typ))
        json_encode = _attempt("json encoder", lambda typ=typ: registry.encoder(typ, "json"))
        if json_encode is not None and template is not None:
            try:
                json_encode(template)
                STATS["json encode template: ok"] += 1
            except DecodeError:
                STATS["json encode template: DecodeError"] += 1
        if encoding == "jsonschema":
            continue
        decode = _attempt("cdr decoder", lambda typ=typ: registry.decoder(typ, "cdr"))
        encode = _attempt("cdr encoder", lambda typ=typ: registry.encoder(typ, "cdr"))
        if decode is None or encode is None:
            continue
        if template is None:  # a chain deeper than the template's limit (64), see the report
            STATS["codecs but no template"] += 1
            continue
        payload = encode({})
        value = decode(memoryview(payload))
        assert _close(_plain(value), _plain(template)), (typ, value, template)
        STATS["template round trips"] += 1


def run_session(data: st.DataObject) -> None:
    """One example: one to three schemas into one fresh registry, then use them."""
    registry = CodecRegistry()
    for _ in range(data.draw(st.integers(1, 3), label="schemas")):
        name, encoding, text, how = _schema(data)
        start = time.thread_time()
        try:
            registry.add_schema(name, encoding, text)
            outcome = "registered"
        except SchemaError:
            outcome = "SchemaError"
        except ValueError:
            # The documented argument error: only for a name that is not one.
            assert not any(name == n for n, _ in (*MSG_SEEDS, *IDL_SEEDS)), name
            assert name not in _NAMES, name
            outcome = "ValueError (bad name)"
        STATS[f"{how}: {outcome}"] += 1
        if outcome == "registered":
            _use(registry, name, encoding)
        elapsed = time.thread_time() - start
        assert elapsed < DEADLINE_S, f"{how} {name!r} took {elapsed:.2f} s: {text!r}"


def run(max_examples: int = 1000, seed: int | None = None) -> None:
    """Run ``max_examples`` examples; raises on the first contract breach.
    A ``seed`` makes the run reproducible."""
    run_sessions(run_session, max_examples, seed)


def main(argv: list[str] | None = None) -> int:
    return cli_main(__doc__, run, STATS, argv)


if __name__ == "__main__":
    sys.exit(main())
