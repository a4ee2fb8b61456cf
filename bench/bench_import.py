"""Start-up cost: how long ``import ros_mobile_bridge`` takes, in fresh
interpreters, against ``import asyncio`` measured in the same run.

    .venv/bin/python bench/bench_import.py [--runs 15]

Each case runs in its own ``python -c`` (``-X frozen_modules=on`` as usual;
no bytecode cache is cleared: a user's second run is the common case) and
times only the statement, with ``time.perf_counter`` inside the child, so the
interpreter's own start-up is not counted. Reports medians and the ratio to
``import asyncio``. Cases:

* ``import ros_mobile_bridge``: the package alone (issue 11's target: under
  60 ms; public names load their module on first use);
* ``... ; rmb.ClientOptions`` and ``... ; rmb.connect``: what a program that
  touches the options, or connects, pays on top;
* ``import roslibpy`` when it is installed (the library users compare with).

Then the whole process, timed from outside: ``python -c "import
ros_mobile_bridge"`` against ``python -c pass`` (the interpreter's own
start-up), medians of the same number of runs. And the bundled interfaces'
first-lookup cost, after the import: reading the data file
(``bundled_interface``), then parsing one interface and building its CDR
decoder (``example_interfaces/srv/AddTwoInts``).

It fails (exit 1) when the package alone loads numpy, websockets or rosbags,
or reads the bundled interfaces: that would be the eager import coming back.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import time

CASES: dict[str, str] = {
    "import asyncio (baseline)": "import asyncio",
    "import anyio": "import anyio",
    "import ros_mobile_bridge": "import ros_mobile_bridge",
    "... + rmb.ClientOptions": "import ros_mobile_bridge as rmb; rmb.ClientOptions",
    "... + rmb.connect": "import ros_mobile_bridge as rmb; rmb.connect",
}

_TIMER = (
    "import time as _t\n_s = _t.perf_counter()\n{stmt}\nprint((_t.perf_counter() - _s) * 1000.0)\n"
)


def _time_once(stmt: str) -> float:
    out = subprocess.run(
        [sys.executable, "-c", _TIMER.format(stmt=stmt)],
        capture_output=True,
        text=True,
        check=True,
    )
    return float(out.stdout.strip().splitlines()[-1])


FIRST_LOOKUP: dict[str, tuple[str, str]] = {
    "bundle: first bundled_interface": (
        "import ros_mobile_bridge.codec as c",
        "c.bundled_interface('std_msgs/msg/String')",
    ),
    "bundle: + first AddTwoInts decoder": (
        "import ros_mobile_bridge.codec as c; c.bundled_interface('std_msgs/msg/String')",
        "c.CodecRegistry().decoder('example_interfaces/srv/AddTwoInts_Request', 'cdr')",
    ),
}

_AFTER = (
    "{setup}\nimport time as _t\n_s = _t.perf_counter()\n{stmt}\n"
    "print((_t.perf_counter() - _s) * 1000.0)\n"
)


def _time_after(setup: str, stmt: str) -> float:
    out = subprocess.run(
        [sys.executable, "-c", _AFTER.format(setup=setup, stmt=stmt)],
        capture_output=True,
        text=True,
        check=True,
    )
    return float(out.stdout.strip().splitlines()[-1])


def _process_ms(code: str) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
    return (time.perf_counter() - start) * 1000.0


def _bundle_read_at_import() -> bool:
    code = (
        "import ros_mobile_bridge as rmb\nrmb.ClientOptions(); rmb.connect\n"
        "from ros_mobile_bridge.codec import _bundled\nprint(_bundled.loaded())"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip() != "False"


def _loaded_by_package() -> list[str]:
    code = (
        "import sys, ros_mobile_bridge\n"
        "print(' '.join(sorted({m.split('.')[0] for m in sys.modules}"
        " & {'numpy', 'websockets', 'rosbags', 'cbor2'})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.split()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=15, help="fresh interpreters per case")
    args = parser.parse_args()
    cases = dict(CASES)
    if importlib.util.find_spec("roslibpy") is not None:
        cases["import roslibpy"] = "import roslibpy"
    for stmt in cases.values():  # warm the bytecode caches
        _time_once(stmt)
    medians: dict[str, float] = {}
    for name, stmt in cases.items():
        samples = [_time_once(stmt) for _ in range(args.runs)]
        medians[name] = statistics.median(samples)
    base = medians["import asyncio (baseline)"]
    print(f"python {sys.version.split()[0]}, {args.runs} fresh interpreters per case, medians")
    print(f"{'case':<30} {'ms':>8} {'x asyncio':>10}")
    for name, ms in medians.items():
        print(f"{name:<30} {ms:8.1f} {ms / base:10.2f}")
    wall = {
        "python -c pass": statistics.median(_process_ms("pass") for _ in range(args.runs)),
        "python -c 'import ros_mobile_bridge'": statistics.median(
            _process_ms("import ros_mobile_bridge") for _ in range(args.runs)
        ),
    }
    start_up = wall["python -c pass"]
    print(f"\n{'whole process (wall)':<38} {'ms':>8} {'x pass':>8}")
    for name, ms in wall.items():
        print(f"{name:<38} {ms:8.1f} {ms / start_up:8.2f}")
    print(
        f"the package adds {wall['python -c ' + repr('import ros_mobile_bridge')] - start_up:.1f} ms"
    )
    print(f"\n{'first lookup, after the import':<38} {'ms':>8}")
    for name, (setup, stmt) in FIRST_LOOKUP.items():
        ms = statistics.median(_time_after(setup, stmt) for _ in range(args.runs))
        print(f"{name:<38} {ms:8.1f}")
    heavy = _loaded_by_package()
    if heavy:
        print(f"FAIL: import ros_mobile_bridge loaded {', '.join(heavy)}")
        return 1
    if _bundle_read_at_import():
        print("FAIL: import ros_mobile_bridge read the bundled interfaces")
        return 1
    target = medians["import ros_mobile_bridge"]
    print(
        f"import ros_mobile_bridge: {target:.1f} ms (target < 60 ms: {'met' if target < 60 else 'MISSED'})"
    )
    return 0 if target < 60 else 1


if __name__ == "__main__":
    raise SystemExit(main())
