"""What one wake-up of an idle event loop costs on this machine: CPU time
per timed wait of one task that waits again and again (stand-alone script).

    .venv/bin/python bench/bench_wakeup.py [--period 0.004] [--seconds 3] [--reps 3]

Read coalescing (``read_coalesce``) trades delay for fewer wake-ups: at
1 kHz with the default 4 ms window, one wake-up per 4 messages. What a
wake-up costs decides how much that saves, and it is not only the loop's
own code: on this project's machine (a virtual machine on a shared host) a
task that sleeps 4 ms and wakes costs far more CPU than the same code run
back to back. This script measures, in one process per case and the same
run, the CPU time (``getrusage``: user and system) per wake-up of:

* ``time.sleep``: a bare thread, no event loop (the floor);
* ``asyncio.sleep``;
* ``trio.sleep``: a cancel scope entered, expired (``Cancelled`` raised
  and caught) and left per wait;
* ``TrioWakeup, own scope``: the library's trio wait with nobody running
  the loop's shared timer (a cancel scope per wait, resumed with a value);
* ``TrioWakeup, shared timer``: the same wait while ``serve_timers`` runs
  the loop's shared timer (a heap entry per wait; the runner's one scope is
  moved on by the loop, never expired).

Each case waits ``--period`` seconds again and again for ``--seconds``,
``--reps`` times, cases alternating; the table shows each case's median
and range. A time, not a count: quote it next to the other cases of the
same run.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable
from typing import Final

CASES: Final = (
    "time.sleep",
    "asyncio.sleep",
    "trio.sleep",
    "TrioWakeup, own scope",
    "TrioWakeup, shared timer",
)


def cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def measure_sync(period: float, seconds: float) -> tuple[int, float]:
    count, c0, t0 = 0, cpu(), time.monotonic()
    while time.monotonic() - t0 < seconds:
        time.sleep(period)
        count += 1
    return count, cpu() - c0


async def measure(wait: Callable[[], Awaitable[None]], seconds: float) -> tuple[int, float]:
    count, c0, t0 = 0, cpu(), time.monotonic()
    while time.monotonic() - t0 < seconds:
        await wait()
        count += 1
    return count, cpu() - c0


def child(case: str, period: float, seconds: float) -> tuple[int, float]:
    if case == "time.sleep":
        return measure_sync(period, seconds)
    if case == "asyncio.sleep":
        import asyncio

        async def sleep() -> None:
            await asyncio.sleep(period)

        return asyncio.run(measure(sleep, seconds))
    import trio
    import trio.testing

    if case == "trio.sleep":

        async def trio_sleep() -> None:
            await trio.sleep(period)

        return trio.run(measure, trio_sleep, seconds)

    from ros_mobile_bridge._loop._trio_wakeup import TrioWakeup
    from ros_mobile_bridge._loop._wakeup import serve_timers

    async def main() -> tuple[int, float]:
        async with trio.open_nursery() as nursery:
            if case == "TrioWakeup, shared timer":
                nursery.start_soon(serve_timers)
                await trio.testing.wait_all_tasks_blocked()
            wakeup = TrioWakeup()

            async def wait() -> None:
                await wakeup.wait(period)

            result = await measure(wait, seconds)
            nursery.cancel_scope.cancel()
        return result

    return trio.run(main)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--period", type=float, default=0.004, help="seconds per wait")
    parser.add_argument("--seconds", type=float, default=3.0, help="per case and repetition")
    parser.add_argument("--reps", type=int, default=3, help="repetitions (cases alternate)")
    parser.add_argument("--case", help=argparse.SUPPRESS)  # a child process (internal)
    args = parser.parse_args()
    if args.case:
        count, used = child(args.case, args.period, args.seconds)
        print(json.dumps({"count": count, "cpu": used}))
        return
    per: dict[str, list[float]] = {case: [] for case in CASES}
    for _ in range(args.reps):
        for case in CASES:
            out = subprocess.run(
                [sys.executable, __file__, "--case", case, "--period", str(args.period),
                 "--seconds", str(args.seconds)],
                check=True, capture_output=True, text=True,
            ).stdout  # fmt: skip
            result = json.loads(out.strip().splitlines()[-1])
            if result["count"] == 0:
                raise SystemExit(f"{case}: no wake-up in {args.seconds} s")
            per[case].append(result["cpu"] / result["count"] * 1e6)
    print(
        f"CPU per wake-up, waits of {args.period * 1000:g} ms, {args.seconds:g} s x {args.reps}"
        " per case (median, range)"
    )
    for case, values in per.items():
        print(
            f"  {case:26} {statistics.median(values):7.1f} us"
            f"   ({min(values):.1f}-{max(values):.1f})"
        )


if __name__ == "__main__":
    main()
