"""griffe extension (mkdocstrings): the reST in the library's docstrings as
Markdown.

The docstrings name other objects with reST roles (``:class:`Client```,
``:meth:`retry```), which Markdown would show as they are. This rewrites each
role to inline code, and a role naming a public object that the API reference
renders to a link to it (``[`Client`][ros_mobile_bridge.Client]``)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import griffe

DOCUMENTED = frozenset(
    match["name"]
    for page in (Path(__file__).parents[1] / "reference").glob("*.md")
    for match in re.finditer(
        r"^::: ros_mobile_bridge\.(?P<name>[\w.]+)", page.read_text(encoding="utf-8"), re.M
    )
)
"""Public names rendered by docs/reference/*.md (read from their ``:::``
lines, so the list cannot drift from the pages): a role naming one becomes
a link."""

_TITLED = re.compile(r"(?P<shown>.+?)\s*<(?P<target>[^<>]+)>")
_LITERAL = re.compile(r"(?<=\S)::\n\n")
_ROLE = re.compile(r":(?:py:)?(?P<kind>class|func|meth|attr|data|exc|mod|obj):`(?P<target>[^`]+)`")


def _markdown(match: re.Match[str]) -> str:
    text = " ".join(match["target"].split())
    titled = _TITLED.fullmatch(text)  # :meth:`shown <target>`
    if titled:
        shown, target = titled["shown"], titled["target"].lstrip("~").lstrip(".")
    else:
        target = text.lstrip("~").lstrip(".")
        shown = target.rsplit(".", 1)[-1] if text.startswith("~") else target
    if match["kind"] in ("func", "meth"):
        shown += "()"
    name = target.removeprefix("ros_mobile_bridge.")
    if name in DOCUMENTED:
        return f"[`{shown}`][ros_mobile_bridge.{name}]"
    return f"`{shown}`"


def roles_to_markdown(text: str) -> str:
    """``text`` with every Sphinx role replaced (see the module docstring),
    and reST's ``::`` before a literal block shown as ``:`` (the indented
    block after it is already a code block in Markdown)."""
    return _LITERAL.sub(":\n\n", _ROLE.sub(_markdown, text))


class SphinxRoles(griffe.Extension):
    """Rewrites the roles of every docstring once the object tree is loaded."""

    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = roles_to_markdown(obj.docstring.value)
