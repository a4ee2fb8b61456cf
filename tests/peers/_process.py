"""Ending a peer's subprocess, the same way for every peer."""

from __future__ import annotations

import contextlib
import subprocess
import threading
from collections.abc import Iterable


def end_process(
    proc: subprocess.Popen[bytes] | subprocess.Popen[str],
    *,
    grace: float = 5.0,
    readers: Iterable[threading.Thread] = (),
) -> int | None:
    """Close ``proc``'s stdin (the peers exit at its end), wait ``grace``
    seconds, then terminate it, then kill it (5 s each); join the threads
    reading its pipes (they end at EOF) and close the pipes. Returns the
    exit code (None if even the kill was not reaped in time)."""
    with contextlib.suppress(OSError):
        if proc.stdin:
            proc.stdin.close()
    try:
        return proc.wait(grace)
    except subprocess.TimeoutExpired:
        proc.terminate()
        try:
            return proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
            try:
                return proc.wait(5)
            except subprocess.TimeoutExpired:
                return None
    finally:
        for reader in readers:
            reader.join(5)
        for stream in (proc.stdout, proc.stderr):
            if stream:
                stream.close()
