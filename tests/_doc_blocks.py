"""The code blocks of README.md and docs/**/*.md, read as tests/test_doc_blocks.py runs them.

The conventions (CONTRIBUTING.md, "Code blocks in the docs"):

- Every fenced block names its language. ``text``, ``yaml``, ``json`` and
  ``toml`` blocks (output, configuration) and ``mermaid`` diagrams are exempt. Output lines of a
  ``console`` block (those without a ``$ `` prompt) are exempt too.
- An unmarked ``python`` block runs against the demo robot. An unmarked
  ``bash``/``console`` block's commands (``rmb ...``, ``python examples/...``,
  ``export RMB_URL=...``) run against the demo robot with ``$RMB_URL`` set.
- A block that cannot run against the demo robot is marked by an HTML comment
  on the line before it (blank lines between allowed), and the prose right
  before it says the same in words: ``<!-- needs: rosbridge -->``,
  ``<!-- needs: zenoh -->`` (another transport; run by the ``ros`` tests
  against the peers of tests/peers/), ``<!-- needs: roslibpy -->`` (that
  library and a rosbridge server), ``<!-- needs: robot -->``
  (a real robot, its network or files on it), ``<!-- needs: checkout -->``
  (a command run from a clone of the repository: its scripts, the test suite,
  benches, fuzzers), ``<!-- needs: install -->`` (a command that installs
  something), ``<!-- needs: recording -->`` (a shell block reading a recording
  named ``run.mcap``: the harness records one from the demo robot first, then
  runs the block). Marked python blocks are at least compiled; marked shell
  blocks are not run, except ``needs: recording`` and those the peer tests run.
- ``<!-- block: continues -->``: the block is the continuation of the page's
  previous python block; the two are run as one.
- ``<!-- block: until-stopped -->``: the block (or a command of it) runs until
  stopped. The harness stops it after a few seconds (a cancel for python,
  SIGINT for a command, which must then exit 130); what ends by itself must
  succeed.
- A ``--8<-- "examples/..."`` block includes an example: tests/test_examples*.py
  run it.

The robot's documented address (``robot.local``, ``localhost``,
``127.0.0.1``, with or without ``ws://`` or ``tcp/`` and ``:8765``, ``:9090`` or
``:7447``) is replaced by the demo robot's (or the peer's). A python block with no ``import`` is a fragment: it gets ``anyio``,
``rmb`` and ``url`` (the robot's URL), and ``robot`` when it uses that name
without binding it (the async client inside ``async with rmb.connect(url)``
when the block awaits, else the blocking client of ``rmb.connect_sync(url)``).
A block that defines ``main`` without running it is run with ``anyio.run(main)``.
"""

from __future__ import annotations

import ast
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGES = (ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")))

EXEMPT = frozenset({"text", "yaml", "json", "toml", "mermaid"})
PYTHON = frozenset({"python"})
SHELL = frozenset({"bash", "console"})
NEEDS = {
    # what a marked block needs -> words one of which the prose before it must say
    "rosbridge": ("rosbridge",),
    "zenoh": ("zenoh",),
    "roslibpy": ("roslibpy",),
    "robot": ("robot",),
    "checkout": ("checkout", "clone", "repository", ".venv"),
    "install": ("install", "extra"),
    "recording": ("recording", "recorder", ".mcap"),
}
RECORDING = "run.mcap"
"""What a ``needs: recording`` block reads: the harness records it from the demo robot first."""
FLAGS = frozenset({"continues", "until-stopped"})

_FENCE = re.compile(r"^(?P<indent>\s*)(?P<fence>`{3,}|~{3,})\s*(?P<lang>[^\s`]*)(?P<rest>.*)$")
_MARKER = re.compile(r"^\s*<!--\s*(?P<key>[a-z]+):\s*(?P<value>[a-z-]+)\s*-->\s*$")
_INCLUDE = re.compile(r'^--8<--\s+"(?P<path>[^"]+)"\s*$')
_ADDRESS = re.compile(
    r"(?P<scheme>ws://|tcp/)?(?:robot\.local|localhost|127\.0\.0\.1)"
    r"(?::(?:8765|9090|7447))?(?![\w.:])"
)


@dataclass(frozen=True)
class Block:
    """One fenced block of a page."""

    page: str  # relative to the checkout
    line: int  # the opening fence, 1-based
    lang: str
    code: str  # without the page's indentation
    prose: str  # the few lines of text before the block (markers left out)
    needs: str | None = None
    flags: frozenset[str] = frozenset()

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}"

    @property
    def include(self) -> str | None:
        """The file a ``--8<--`` block includes, else None."""
        m = _INCLUDE.match(self.code.strip())
        return m["path"] if m else None


@dataclass(frozen=True)
class Command:
    """One command line of a shell block."""

    argv: tuple[str, ...]
    background: bool  # ended by ``&``


def read_page(path: Path) -> tuple[list[Block], list[str]]:
    """The page's blocks, and what is wrong with its markers."""
    rel = path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else path.name
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    problems: list[str] = []
    pending: list[tuple[int, str, str]] = []  # (line, key, value) waiting for their block
    text_lines: list[str] = []  # the page's text so far, without blocks and markers
    i = 0
    while i < len(lines):
        line = lines[i]
        marker = _MARKER.match(line)
        fence = _FENCE.match(line)
        if marker:
            pending.append((i + 1, marker["key"], marker["value"]))
        elif fence:
            indent, char, width = len(fence["indent"]), fence["fence"][0], len(fence["fence"])
            j = i + 1
            close = re.compile(rf"^\s{{0,{indent}}}{re.escape(char)}{{{width},}}\s*$")
            while j < len(lines) and not close.match(lines[j]):
                j += 1
            body = "\n".join(text[indent:] for text in lines[i + 1 : j]) + "\n"
            needs: str | None = None
            flags: set[str] = set()
            for at, key, value in pending:
                if key == "needs" and value in NEEDS and needs is None:
                    needs = value
                elif key == "block" and value in FLAGS:
                    flags.add(value)
                else:
                    problems.append(f"{rel}:{at}: unknown or repeated marker {key}: {value}")
            pending = []
            prose = "\n".join(text_lines[-8:])
            blocks.append(Block(rel, i + 1, fence["lang"], body, prose, needs, frozenset(flags)))
            i = j
        else:
            text_lines.append(line)
            if line.strip() and pending:
                problems.extend(
                    f"{rel}:{at}: marker not followed by a block" for at, _, _ in pending
                )
                pending = []
        i += 1
    problems.extend(f"{rel}:{at}: marker not followed by a block" for at, _, _ in pending)
    return blocks, problems


def all_blocks() -> tuple[list[Block], list[str]]:
    blocks: list[Block] = []
    problems: list[str] = []
    for page in PAGES:
        found, wrong = read_page(page)
        blocks.extend(found)
        problems.extend(wrong)
    return blocks, problems


def commands(block: Block) -> list[Command]:
    """The commands of a shell block: every line of a ``bash`` block, the ``$ `` lines of a
    ``console`` block; comments and blank lines left out."""
    lines = block.code.splitlines()
    if block.lang == "console":
        lines = [t[2:] for t in lines if t.startswith("$ ")]
    found: list[Command] = []
    for text in lines:
        argv = shlex.split(text, comments=True)
        if not argv:
            continue
        background = argv[-1] == "&"
        found.append(Command(tuple(argv[:-1] if background else argv), background))
    return found


def runnable_command(command: Command) -> bool:
    """A command the harness runs: ``rmb ...``, ``python examples/X.py ...``, or the
    ``export RMB_URL=...`` it replaces with its own."""
    argv = command.argv
    if argv[0] == "rmb":
        return True
    if argv[0] == "python" and len(argv) > 1 and argv[1].startswith("examples/"):
        return True
    return argv[0] == "export" and len(argv) == 2 and argv[1].startswith("RMB_URL=")


def problem(block: Block) -> str | None:
    """Why the block is neither runnable nor marked (None when it is one of them)."""
    if not block.lang:
        return f"{block.id}: a block without a language (name one; `text` for output)"
    if block.lang in EXEMPT:
        return None
    if block.lang not in PYTHON | SHELL:
        return f"{block.id}: language {block.lang!r} is neither run nor exempt"
    if block.needs is not None:
        words = NEEDS[block.needs]
        if not any(word in block.prose.lower() for word in words):
            return (
                f"{block.id}: marked `needs: {block.needs}` but the text before it does not say"
                f" so (one of {', '.join(words)})"
            )
        return None
    if block.include is not None:
        path = ROOT / block.include
        if not path.is_file():
            return f"{block.id}: includes {block.include}, which does not exist"
        return None
    if block.lang in SHELL:
        found = commands(block)
        if not found:
            return f"{block.id}: a {block.lang} block with no command"
        for command in found:
            if not runnable_command(command):
                return (
                    f"{block.id}: `{shlex.join(command.argv)}` is not an rmb or examples/"
                    " command; mark the block with what it needs"
                )
    return None


def localise(text: str, url: str) -> str:
    """The text with the docs' robot address replaced by ``url`` (``ws://host:port``, or a
    zenoh router's ``tcp/host:port``)."""
    hostport = url.removeprefix("ws://").removeprefix("tcp/")
    return _ADDRESS.sub(lambda m: url if m["scheme"] else hostport, text)


def python_source(block: Block, blocks: list[Block]) -> str:
    """The block's code, after the page's previous python block when it continues it."""
    if "continues" not in block.flags:
        return block.code
    before = [
        b for b in blocks if b.page == block.page and b.lang in PYTHON and b.line < block.line
    ]
    if not before:
        raise AssertionError(f"{block.id}: marked `block: continues` but no python block before it")
    return python_source(before[-1], blocks) + block.code


def is_fragment(tree: ast.Module) -> bool:
    """No import anywhere: the block leans on the names the harness gives it."""
    return not any(isinstance(node, ast.Import | ast.ImportFrom) for node in ast.walk(tree))


def uses_unbound(tree: ast.Module, name: str) -> bool:
    """The block reads ``name`` and never binds it."""
    loads = stores = False
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id == name:
            if isinstance(node.ctx, ast.Load):
                loads = True
            else:
                stores = True
        elif isinstance(node, ast.arg) and node.arg == name:
            stores = True
    return loads and not stores


def runs_main_itself(tree: ast.Module) -> bool:
    """A top-level call such as ``anyio.run(main)`` or ``asyncio.run(main())``."""
    for node in tree.body:
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Call):
            func = node.value.func
            if isinstance(func, ast.Attribute) and func.attr == "run":
                return True
    return False
