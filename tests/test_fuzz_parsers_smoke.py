"""Short, reproducible runs of the parser fuzz harnesses added in issue 8:
CDR payloads against their schemas (``fuzz/fuzz_codec.py``), schema texts
(``fuzz/fuzz_schema.py``) and rosbridge's zero-copy CBOR walker
(``fuzz/fuzz_cbor_walker.py``). Each run must end without a contract breach
(an exception other than the parser's own typed error, a per-example
deadline, a memory bound) and must have reached the paths named here, so a
harness that silently stopped exercising the parser fails. Longer runs:
``python fuzz/fuzz_<name>.py --examples 20000``."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

# CPU-bound searches: under parallel workers on a busy machine they may take
# several times their quiet minute, more than the suite's 120 s per test
pytestmark = pytest.mark.timeout(360)

FUZZ = Path(__file__).resolve().parents[1] / "fuzz"

CASES = {
    # harness: (examples, paths the run must reach)
    "fuzz_codec": (
        1000,
        ("valid: ok", "round trips", "huge length: error", "truncated: error", "random: error"),
    ),
    "fuzz_schema": (
        250,
        (
            "ros2msg seed: registered",
            "ros2msg mutated: SchemaError",
            "cdr decoder: ok",
            "template: ok",
        ),
    ),
    "fuzz_cbor_walker": (
        1000,
        (
            "walker: Publish",
            "Publish/cbor-raw",
            "cbor-raw agrees with cbor2",
            "ProtocolViolation",
            "Status",
        ),
    ),
}


def _load(name: str) -> ModuleType:
    if str(FUZZ) not in sys.path:
        sys.path.insert(0, str(FUZZ))  # the harnesses import their shared _harness
    spec = importlib.util.spec_from_file_location(name, FUZZ / f"{name}.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name", sorted(CASES))
def test_fuzz_harness_short_run_reaches_the_parser(name: str) -> None:
    examples, reached = CASES[name]
    harness = _load(name)
    harness.STATS.clear()
    harness.run(max_examples=examples, seed=0)
    for path in reached:
        assert harness.STATS[path] > 0, (path, dict(harness.STATS))


@pytest.mark.parametrize("name", sorted(CASES))
def test_fuzz_harness_command_line(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert _load(name).main(["--examples", "5", "--seed", "1"]) == 0
    assert "ok: 5 sessions" in capsys.readouterr().out
