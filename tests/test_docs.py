"""The documentation site builds with ``mkdocs build --strict`` (every link,
anchor, nav entry, snippet and docstring reference resolves), and the pages
generated from the docstrings hold what they should.

Plain (sync) tests: they run once, not once per anyio backend. They need the
``[docs]`` extra (mkdocs-material, mkdocstrings-python)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

pytestmark = [
    pytest.mark.docs,  # built on the main Python only (scripts/test)
    # one pytest-xdist worker runs this module, so the site is built once per
    # run (the build is seconds of CPU), not once by each worker that got one
    # of the tests that read it
    pytest.mark.xdist_group("docs-site"),
]

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site, built once per run (the module's tests share one worker)
    from this checkout's sources."""
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), *filter(None, [env.get("PYTHONPATH")])])
    env["NO_MKDOCS_2_WARNING"] = "1"  # mkdocs-material's banner about its successor
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--config-file",
            str(ROOT / "mkdocs.yml"),
            "--site-dir",
            str(out),
        ],
        cwd=out,  # not the checkout: every path in mkdocs.yml must hold from anywhere
        env=env,
        capture_output=True,
        text=True,
        timeout=100,
    )
    assert result.returncode == 0, f"mkdocs build --strict failed:\n{result.stderr}"
    assert "WARNING" not in result.stderr, result.stderr
    return out


def _page(site: Path, name: str) -> str:
    return (site / name / "index.html").read_text(encoding="utf-8")


def test_site_builds_strict_with_every_page(site: Path) -> None:
    for name in (
        "getting-started",
        "sync-and-notebooks",
        "concepts",
        "transports/foxglove",
        "transports/rosbridge",
        "zenoh",
        "connection-options",
        "cli",
        "recording",
        "serving",
        "examples",
        "mcp",
        "errors",
        "reference/configuration",
        "reference/api",
        "performance",
        "benchmarks",
        "security",
        "migration-roslibpy",
        "architecture",
        "message-classes",
    ):
        assert (site / name / "index.html").is_file(), name
    assert (site / "index.html").is_file()
    assert not (site / "_ext").exists()  # the build's own extensions are not published


def test_configuration_reference_is_generated_from_the_docstrings(site: Path) -> None:
    page = _page(site, "reference/configuration")
    # a field of each policy, with its docstring text from src/
    assert 'id="ros_mobile_bridge.ClientOptions.teardown_timeout"' in page
    assert "Deadline of the whole teardown" in page
    assert 'id="ros_mobile_bridge.ReconnectPolicy"' in page
    assert 'id="ros_mobile_bridge.BreakerPolicy"' in page


def test_api_reference_renders_roles_as_markdown(site: Path) -> None:
    page = _page(site, "reference/api")
    for anchor in ("connect", "Client.subscribe", "Subscription", "Message", "ServiceTimeout"):
        assert f'id="ros_mobile_bridge.{anchor}"' in page, anchor
    # Sphinx roles from the docstrings were rewritten, not shown raw
    for role in (":class:", ":meth:", ":func:", ":attr:", ":data:"):
        assert role not in page, role
    # a role naming a documented object became a link to it
    assert 'href="#ros_mobile_bridge.Client"' in page


def test_snippets_are_included_not_shown(site: Path) -> None:
    for name in ("getting-started", "benchmarks"):
        assert "--8&lt;--" not in _page(site, name) and "--8<--" not in _page(site, name)
    assert "cancel_on_signals" in _page(site, "getting-started")  # examples/quickstart_*.py
    assert "bench_rosbridge.py" in _page(site, "benchmarks")  # bench/README.md


def _extension(name: str) -> ModuleType:
    """A module of docs/_ext/ (the build's hook and griffe extension)."""
    spec = importlib.util.spec_from_file_location(f"docs_{name}", ROOT / f"docs/_ext/{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_sphinx_roles_become_markdown() -> None:
    convert = _extension("griffe_roles").roles_to_markdown
    assert convert("see :class:`~ros_mobile_bridge.Client`.") == (
        "see [`Client`][ros_mobile_bridge.Client]."
    )
    assert convert(":func:`connect`") == "[`connect()`][ros_mobile_bridge.connect]"
    assert convert(":meth:`retry` or :attr:`on_latency`") == "`retry()` or `on_latency`"
    titled = ":meth:`Client.send_action_goal\n    <ros_mobile_bridge.Client.send_action_goal>`"
    assert convert(titled) == "`Client.send_action_goal()`"
    assert convert("States::\n\n    closed") == "States:\n\n    closed"
    assert convert("a ``literal`` stays") == "a ``literal`` stays"


def test_links_out_of_docs_are_rewritten_for_the_site() -> None:
    rewrite = _extension("links")._rewrite
    text = (
        "[method](../bench/README.md#zenoh) and [bench](../bench) and "
        "[policy](../SECURITY.md) and [page](zenoh.md) and [web](https://example.org)\n"
        "```\n[kept](../SECURITY.md)\n```\n"
    )
    site_only = rewrite(text, "performance.md", "docs", None)
    assert "[method](benchmarks.md#zenoh)" in site_only
    assert "[bench](benchmarks.md)" in site_only
    assert "and policy and" in site_only  # no repository address: the text alone
    assert "[page](zenoh.md)" in site_only and "[web](https://example.org)" in site_only
    assert "[kept](../SECURITY.md)" in site_only  # code is left alone
    nested = rewrite("[m](../../bench/README.md)", "transports/x.md", "docs", None)
    assert nested == "[m](../benchmarks.md)"
    with_repo = rewrite("[policy](../SECURITY.md)", "security.md", "docs", "https://h/o/r/")
    assert with_repo == "[policy](https://h/o/r/blob/main/SECURITY.md)"
