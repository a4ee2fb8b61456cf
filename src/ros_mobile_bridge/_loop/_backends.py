"""The event loops the library starts itself (the sync client's worker
thread, the ``rmb`` command): asyncio, trio, and asyncio on uvloop.

A program that runs its own loop needs none of this: ``connect()`` runs on
whichever loop awaits it, uvloop included (``anyio.run(main,
backend_options={"use_uvloop": True})``, or uvicorn with uvloop installed).
Here ``"uvloop"`` is a name for asyncio on uvloop, so the loop the library
starts can be chosen by one word."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any, Final, Literal

__all__ = ["BACKENDS", "Backend", "run_args"]

Backend = Literal["asyncio", "trio", "uvloop"]
"""A loop the library can start: asyncio, trio, or asyncio on uvloop."""

BACKENDS: Final[tuple[Backend, ...]] = ("asyncio", "trio", "uvloop")

_PACKAGE: Final = {"trio": "trio", "uvloop": "uvloop"}
"""The package each loop needs, which is also the extra that installs it."""


def run_args(
    backend: object, backend_options: Mapping[str, Any] | None, what: str
) -> tuple[str, dict[str, Any] | None]:
    """``anyio.run``'s ``backend`` and ``backend_options`` for ``backend``.

    ``"uvloop"`` is anyio's asyncio backend with ``use_uvloop`` set (added to
    ``backend_options``). Raises ``ValueError`` for a name not in
    :data:`BACKENDS` and ``ImportError`` naming the extra to install when the
    loop's package is missing (uvloop has no Windows build), both before
    any loop starts; ``what`` names the caller in the message
    (``"connect_sync(backend='uvloop')"``, ``"--backend uvloop"``)."""
    if backend not in BACKENDS:
        names = ", ".join(repr(b) for b in BACKENDS)
        raise ValueError(f"backend must be one of {names}, got {backend!r}")
    package = _PACKAGE.get(str(backend))
    if package is not None:
        try:
            importlib.import_module(package)
        except ImportError:
            raise ImportError(
                f"{what} needs {package}: pip install 'ros-mobile-bridge[{package}]'"
            ) from None
    options = dict(backend_options) if backend_options else None
    if backend == "uvloop":
        return "asyncio", {**(options or {}), "use_uvloop": True}
    return str(backend), options
