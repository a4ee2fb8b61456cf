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

It fails (exit 1) when the package alone loads numpy, websockets or rosbags:
that would be the eager import coming back.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys

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
    heavy = _loaded_by_package()
    if heavy:
        print(f"FAIL: import ros_mobile_bridge loaded {', '.join(heavy)}")
        return 1
    target = medians["import ros_mobile_bridge"]
    print(
        f"import ros_mobile_bridge: {target:.1f} ms (target < 60 ms: {'met' if target < 60 else 'MISSED'})"
    )
    return 0 if target < 60 else 1


if __name__ == "__main__":
    raise SystemExit(main())
