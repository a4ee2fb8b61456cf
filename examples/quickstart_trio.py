"""The same session on trio: one code base, two event loops.

rmb demo --serve --port 8765 &
python examples/quickstart_trio.py ws://127.0.0.1:8765
"""

from __future__ import annotations

import sys

import trio

import ros_mobile_bridge as rmb


async def main(url: str) -> int:
    # SIGINT, SIGTERM and SIGHUP cancel the block (the teardown still runs)
    async with rmb.cancel_on_signals() as stop, rmb.connect(url) as robot:
        async with trio.open_nursery() as nursery:

            async def battery() -> None:
                async with robot.subscribe("/battery") as sub:
                    async for msg in sub:
                        print(f"battery {msg.data.percentage * 100:.1f}%")
                        nursery.cancel_scope.cancel()

            nursery.start_soon(battery)
        print("parameters:", await robot.list_parameters())
    return stop.exit_code or 0


if __name__ == "__main__":
    sys.exit(trio.run(main, sys.argv[1] if len(sys.argv) > 1 else "ws://127.0.0.1:8765"))
