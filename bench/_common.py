"""Small helpers every benchmark here shares."""

from __future__ import annotations

import importlib.metadata
import platform
from collections.abc import Sequence
from contextlib import suppress

import ros_mobile_bridge as rmb

__all__ = ["subscription_counts", "versions"]


def versions(names: Sequence[str]) -> str:
    """The Python version and the installed versions of ``names``."""
    found = []
    for name in names:
        with suppress(importlib.metadata.PackageNotFoundError):
            found.append(f"{name} {importlib.metadata.version(name)}")
    return f"python {platform.python_version()}, " + ", ".join(found)


def subscription_counts(stats: rmb.SubscriptionStats) -> dict[str, int]:
    """A subscription's frame counters, for a benchmark's JSON."""
    return {
        "received": stats.received,
        "delivered": stats.delivered,
        "dropped_throttle": stats.dropped_throttle,
        "dropped_overflow": stats.dropped_overflow,
        "decode_failures": stats.decode_failures,
    }
