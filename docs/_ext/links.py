"""mkdocs hook: links from a docs page to a file outside ``docs/``.

The pages under ``docs/`` are read on GitHub too, where ``../bench/README.md``
is a fine link. On the site it points nowhere, and ``mkdocs build --strict``
fails on it. Before each page is converted, this hook rewrites such a link:

- to the site page that shows that file (``bench/README.md`` is shown by
  ``benchmarks.md``);
- else, when ``repo_url`` is set in ``mkdocs.yml``, to the file in the
  repository (``<repo_url>/blob/main/<path>``);
- else to the link's text alone (the file name stays readable; there is no
  address to send the reader to).

Links inside fenced code blocks are left alone."""

from __future__ import annotations

import logging
import posixpath
import re
from typing import Any

log = logging.getLogger("mkdocs.hooks.links")

SITE_PAGES = {
    "bench": "benchmarks.md",
    "bench/README.md": "benchmarks.md",
}
"""Repository path (relative to the repository root) -> the docs page showing it."""

_FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.MULTILINE | re.DOTALL)
_LINK = re.compile(r"(?<!!)\[(?P<text>[^\]\n]*)\]\((?P<target>[^)\s]+)\)")


def _rewrite(text: str, page: str, docs_prefix: str, repo_url: str | None) -> str:
    page_dir = posixpath.dirname(page)

    def link(match: re.Match[str]) -> str:
        target = match["target"]
        if re.match(r"^[a-z][a-z0-9+.-]*:|^#|^/", target):
            return match[0]  # absolute URL, anchor or site-absolute path
        path, _, anchor = target.partition("#")
        inside = posixpath.normpath(posixpath.join(page_dir, path))
        if not inside.startswith("../"):
            return match[0]  # a docs page: mkdocs checks it
        repo_path = posixpath.normpath(posixpath.join(docs_prefix, inside))
        suffix = f"#{anchor}" if anchor else ""
        if repo_path in SITE_PAGES:
            local = posixpath.relpath(SITE_PAGES[repo_path], page_dir or ".")
            return f"[{match['text']}]({local}{suffix})"
        if repo_url:
            return f"[{match['text']}]({repo_url.rstrip('/')}/blob/main/{repo_path}{suffix})"
        log.info("%s: no repo_url in mkdocs.yml, link to %s shown as text", page, repo_path)
        return match["text"]

    out: list[str] = []
    last = 0
    for fence in _FENCE.finditer(text):
        out.append(_LINK.sub(link, text[last : fence.start()]))
        out.append(fence[0])
        last = fence.end()
    out.append(_LINK.sub(link, text[last:]))
    return "".join(out)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    docs_prefix = posixpath.relpath(config["docs_dir"], posixpath.dirname(config.config_file_path))
    return _rewrite(
        markdown, page.file.src_uri, docs_prefix.replace("\\", "/"), config.get("repo_url")
    )
