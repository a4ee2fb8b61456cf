"""CPU per small WebSocket send: the library's transport against a bare
``websockets`` client sending the same frames to the same server, in one
run (stand-alone script).

    .venv/bin/python bench/bench_send.py [--count 20000] [--reps 5] [--size 44]

Every ``publish``, ``unsubscribe`` and (in ``save_bandwidth`` mode) every
pause and resumption is one small frame written by the client. The server
is a bare ``websockets`` server in its own process on 127.0.0.1 that reads
and counts every message, so this process's CPU time
(``time.process_time()``) is the client's alone. Cases, alternating, each
``--reps`` times ``--count`` sends of a ``--size``-byte text message:

* ``websockets``: ``websockets.asyncio.client``'s ``send`` (the baseline);
* ``library asyncio`` and ``library trio``: the library's WebSocket
  (``ros_mobile_bridge.transport.connect_websocket``) on each loop.

The server's count is checked after each case: a send that did not arrive
fails the run. A time, not a target: the median of each case and its ratio
to the baseline's median are printed.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import textwrap
import time

import anyio

from ros_mobile_bridge.transport import connect_websocket

SERVER = textwrap.dedent(
    """
    import asyncio, sys
    from websockets.asyncio.server import serve

    count = 0

    async def handler(ws):
        global count
        async for message in ws:
            if message == "count?":
                await ws.send(str(count))
                count = 0
            else:
                count += 1

    async def main():
        async with serve(handler, "127.0.0.1", 0, max_size=None) as server:
            print(server.sockets[0].getsockname()[1], flush=True)
            await asyncio.Future()

    asyncio.run(main())
    """
)


async def bare(url: str, count: int, message: str) -> tuple[float, int]:
    from websockets.asyncio.client import connect

    async with connect(url, max_size=None) as ws:
        start = time.process_time()
        for _ in range(count):
            await ws.send(message)
        spent = time.process_time() - start
        await ws.send("count?")
        arrived = int(await ws.recv())
    return spent, arrived


async def library(url: str, count: int, message: str) -> tuple[float, int]:
    ws = await connect_websocket(url)
    try:
        start = time.process_time()
        for _ in range(count):
            await ws.send(message)
        spent = time.process_time() - start
        await ws.send("count?")
        reply = await ws.receive()
        arrived = int(reply if isinstance(reply, str) else bytes(reply).decode())
    finally:
        await ws.aclose(timeout=1.0)
    return spent, arrived


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=20000)
    parser.add_argument("--reps", type=int, default=5)
    parser.add_argument("--size", type=int, default=44)
    args = parser.parse_args()
    message = "x" * args.size
    server = subprocess.Popen([sys.executable, "-c", SERVER], stdout=subprocess.PIPE, text=True)
    try:
        assert server.stdout is not None
        url = f"ws://127.0.0.1:{server.stdout.readline().strip()}"
        cases = {
            "websockets": lambda: anyio.run(bare, url, args.count, message, backend="asyncio"),
            "library asyncio": lambda: anyio.run(
                library, url, args.count, message, backend="asyncio"
            ),
            "library trio": lambda: anyio.run(library, url, args.count, message, backend="trio"),
        }
        per_send: dict[str, list[float]] = {name: [] for name in cases}
        lost = 0
        for _ in range(args.reps):
            for name, run in cases.items():
                spent, arrived = run()
                lost += args.count - arrived
                per_send[name].append(spent / args.count * 1e6)
    finally:
        server.terminate()
        server.wait()
    base = statistics.median(per_send["websockets"])
    print(f"{args.count} sends of {args.size} bytes, {args.reps} repetitions, alternating")
    print(f"{'case':<18}{'median us/send':>16}{'range':>18}{'/ websockets':>14}")
    for name, values in per_send.items():
        median = statistics.median(values)
        spread = f"{min(values):.1f}-{max(values):.1f}"
        print(f"{name:<18}{median:>16.1f}{spread:>18}{median / base:>13.2f}x")
    if lost:
        print(f"FAIL: {lost} sends did not arrive")
        return 1
    print("every send arrived")
    return 0


if __name__ == "__main__":
    sys.exit(main())
