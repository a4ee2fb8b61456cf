"""A short, reproducible run of the Foxglove engine fuzz harness (``fuzz/fuzz_foxglove.py``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

from _util import examples

# CPU-bound searches: under parallel workers on a busy machine they may take
# several times their quiet minute, more than the suite's 120 s per test
pytestmark = pytest.mark.timeout(360)

HARNESS = Path(__file__).resolve().parents[1] / "fuzz" / "fuzz_foxglove.py"


def _load_harness() -> ModuleType:
    spec = importlib.util.spec_from_file_location("fuzz_foxglove", HARNESS)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module


def test_fuzz_harness_short_run() -> None:
    harness = _load_harness()
    harness.STATS.clear()
    # every path named below is reached within the first ten or so sessions
    # (seeds 0-3, 150 or 30 sessions): a short run's 30 (tests/_util.py) too
    harness.run(max_examples=examples(150), seed=0)
    # The run reached the interesting paths, not just the violation branch.
    for name in ("ServerInfo", "Advertise", "MessageData", "ProtocolViolation"):
        assert harness.STATS[name] > 0, (name, dict(harness.STATS))


def test_fuzz_harness_main_entry_point(capsys: pytest.CaptureFixture[str]) -> None:
    harness = _load_harness()
    assert harness.main(["--examples", "10", "--seed", "1"]) == 0
    assert "ok: 10 sessions" in capsys.readouterr().out
