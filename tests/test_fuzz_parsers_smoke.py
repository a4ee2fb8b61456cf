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

from _util import SHORT_SEARCHES, examples

# CPU-bound searches: under parallel workers on a busy machine they may take
# several times their quiet minute, more than the suite's 120 s per test
pytestmark = pytest.mark.timeout(360)

FUZZ = Path(__file__).resolve().parents[1] / "fuzz"

CASES = {
    # harness: (sessions, paths every run must reach, paths only a full run
    # must reach). A short run (tests/_util.py) takes a fifth of the sessions:
    # 200 codec and 50 schema sessions reached every path (seeds 0-2); 200
    # walker sessions reached publishes and violations, but no cbor-raw
    # publish (about 1 session in 100 is one, none in the first 200 of seeds
    # 0-4) and a status in only 3 of those 5 seeds: those are the full run's.
    "fuzz_codec": (
        1000,
        (
            "valid: ok",
            "round trips",
            "huge length: error",
            "truncated: error",
            "random: error",
            "class decoder agrees: ok",
            "class decoder agrees: error",
        ),
        (),
    ),
    "fuzz_schema": (
        250,
        (
            "ros2msg seed: registered",
            "ros2msg mutated: SchemaError",
            "cdr decoder: ok",
            "template: ok",
        ),
        (),
    ),
    "fuzz_cbor_walker": (
        1000,
        ("walker: Publish", "ProtocolViolation"),
        ("Publish/cbor-raw", "cbor-raw agrees with cbor2", "Status"),
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
    full, reached, rare = CASES[name]
    harness = _load(name)
    harness.STATS.clear()
    harness.run(max_examples=examples(full), seed=0)
    for path in reached if SHORT_SEARCHES else reached + rare:
        assert harness.STATS[path] > 0, (path, dict(harness.STATS))


@pytest.mark.parametrize("name", sorted(CASES))
def test_fuzz_harness_command_line(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert _load(name).main(["--examples", "5", "--seed", "1"]) == 0
    assert "ok: 5 sessions" in capsys.readouterr().out
