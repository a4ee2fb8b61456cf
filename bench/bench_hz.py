"""``rmb hz`` against a bare counter of the same stream, in one run.

The Foxglove SDK server (``bench/_peer.py``, its own process) publishes
``/bench/string`` (99-byte CDR payloads) on a fixed schedule at each rate in
turn. Two clients are subscribed to it at once:

* the bare counter: a ``websockets`` receive loop in this process that
  counts binary frames and stamps the first and the last;
* ``rmb hz /bench/string --json`` in its own process, which counts frames on
  arrival (``subscribe(decode=False)``, the ``received`` counter).

For each rate it prints what was sent, what each counter received, the
rate each measured (the bare counter: frames over the span from the first
to the last frame; ``rmb hz``: its last JSON line), and the ratio of the
two rates. Every frame ``rmb hz`` received is accounted for: taken by the
printer or dropped by its buffer (``received``, ``dropped``); a run whose
``rmb hz`` received more than was sent, or whose counts do not add up,
fails (exit 1). Raise ``--rates`` until the bare counter falls short of the
schedule: that is where it saturates.

    python bench/bench_hz.py                       # 1k to 100k msg/s, 3 s each
    python bench/bench_hz.py --rates 2000,50000 --seconds 2
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Final

from _peer import STRING_TOPIC
from websockets.sync.client import connect

HERE: Final = Path(__file__).resolve().parent
SUBPROTOCOL: Final = "foxglove.sdk.v1.1"


def start_peer(backlog: int) -> tuple[subprocess.Popen[str], int]:
    peer = subprocess.Popen(
        [sys.executable, str(HERE / "_peer.py"), str(backlog)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert peer.stdout is not None
    first = peer.stdout.readline().split()
    assert first[0] == "port", first
    return peer, int(first[1])


class HzProcess:
    """``rmb hz TOPIC --json`` in its own process; its JSON lines kept."""

    def __init__(
        self, url: str, backend: str, src: Path, *, protocol: str = "auto", domain: int = 0
    ) -> None:
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join([str(src), *sys.path]),
            "ROS_DOMAIN_ID": str(domain),
        }
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "ros_mobile_bridge",
                "--backend",
                backend,
                "--protocol",
                protocol,
                "-u",
                url,
                "hz",
                STRING_TOPIC,
                "--json",
                "-w",
                "100000000",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env=env,
        )
        self.lines: list[dict[str, Any]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(json.loads(line))

    def last(self) -> dict[str, Any] | None:
        return next((line for line in reversed(self.lines) if "rate_hz" in line), None)

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(10)


def bare_counter(url: str, stop: threading.Event, counts: dict[str, Any]) -> None:
    """Subscribe to the topic and count binary frames until ``stop``."""
    with connect(url, subprotocols=[SUBPROTOCOL], max_size=None, compression=None) as ws:  # type: ignore[list-item]
        while True:
            message = ws.recv()
            if isinstance(message, str):
                op = json.loads(message)
                channels = op.get("channels", []) if op.get("op") == "advertise" else []
                ids = [ch["id"] for ch in channels if ch["topic"] == STRING_TOPIC]
                if ids:
                    sub = {"id": 1, "channelId": ids[0]}
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": [sub]}))
                    break
        counts["ready"].set()
        n = 0
        first = last = 0
        while not stop.is_set():
            try:
                message = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            if isinstance(message, bytes):
                last = time.monotonic_ns()
                if n == 0:
                    first = last
                n += 1
        counts.update(n=n, first=first, last=last)


def one_rate(
    url: str, peer: subprocess.Popen[str], rate: int, seconds: float, backend: str, src: Path
) -> dict[str, Any]:
    assert peer.stdin is not None
    assert peer.stdout is not None
    hz = HzProcess(url, backend, src)
    time.sleep(2.0)  # rmb connects and subscribes
    stop = threading.Event()
    counts: dict[str, Any] = {"ready": threading.Event()}
    counter = threading.Thread(target=bare_counter, args=(url, stop, counts), daemon=True)
    counter.start()
    assert counts["ready"].wait(10), "the bare counter did not subscribe"
    count = int(rate * seconds)
    peer.stdin.write(f"pace {STRING_TOPIC} {count} {rate}\n")
    peer.stdin.flush()
    answers = [peer.stdout.readline().split() for _ in range(2)]
    assert answers[0] == ["started"], answers
    assert answers[1][0] == "done", answers
    sent_seconds = float(answers[1][2])
    time.sleep(2.5)  # both drain, and rmb hz prints its last figures
    stop.set()
    counter.join(10)
    hz.stop()
    last = hz.last() or {}
    span = (counts["last"] - counts["first"]) / 1e9
    bare_rate = (counts["n"] - 1) / span if span > 0 else 0.0
    return {
        "target_hz": rate,
        "sent": count,
        "sent_hz": count / sent_seconds,
        "bare_received": counts["n"],
        "bare_hz": bare_rate,
        "rmb_received": last.get("received", 0),
        "rmb_dropped": last.get("dropped", 0),
        "rmb_hz": last.get("rate_hz", 0.0),
        "ratio": last.get("rate_hz", 0.0) / bare_rate if bare_rate else 0.0,
    }


def zenoh_rows(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Zenoh: bursts as fast as the publisher puts (``bench_zenoh.py``'s
    router and publisher), counted by a bare eclipse-zenoh subscriber
    callback and by ``rmb hz --protocol zenoh``."""
    import random
    from contextlib import ExitStack

    import bench_zenoh as bz
    import zenoh

    rows = []
    with ExitStack() as stack:
        locator, _what = bz.router(stack)
        domain = random.randrange(100, 200)
        publisher = bz.Publisher(locator, domain)
        stack.callback(publisher.close)
        for count in (int(c) for c in args.zenoh_counts.split(",")):
            hz = HzProcess(locator, args.backend, args.src, protocol="zenoh", domain=domain)
            time.sleep(3.0)  # rmb connects, subscribes, the declaration reaches the router
            session = zenoh.open(bz.zenoh_config("client", locator))
            got = {"n": 0, "first": 0.0, "last": 0.0}

            def on_sample(_sample: Any, got: dict[str, Any] = got) -> None:
                now = bz.monotonic()
                if got["n"] == 0:
                    got["first"] = now
                got["last"] = now
                got["n"] += 1

            subscriber = session.declare_subscriber(bz.selector(domain, "string"), on_sample)
            time.sleep(1.0)
            sent, start, end = publisher.burst("string", count)
            time.sleep(3.0)  # both drain, and rmb hz prints its last figures
            subscriber.undeclare()  # type: ignore[no-untyped-call]
            session.close()  # type: ignore[no-untyped-call]
            hz.stop()
            last = hz.last() or {}
            span = got["last"] - got["first"]
            bare_rate = (got["n"] - 1) / span if span > 0 else 0.0
            rows.append(
                {
                    "target_hz": 0,
                    "sent": sent,
                    "sent_hz": sent / (end - start),
                    "bare_received": got["n"],
                    "bare_hz": bare_rate,
                    "rmb_received": last.get("received", 0),
                    "rmb_dropped": last.get("dropped", 0),
                    "rmb_hz": last.get("rate_hz", 0.0),
                    "ratio": last.get("rate_hz", 0.0) / bare_rate if bare_rate else 0.0,
                }
            )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rates", default="1000,5000,20000,50000,100000")
    parser.add_argument("--seconds", type=float, default=3.0, help="stream length per rate")
    parser.add_argument("--backend", choices=("asyncio", "trio"), default="asyncio")
    parser.add_argument("--backlog", type=int, default=1_000_000, help="server backlog per client")
    parser.add_argument("--json", type=Path, help="also write the rows here")
    parser.add_argument("--transport", choices=("foxglove", "zenoh"), default="foxglove")
    parser.add_argument(
        "--zenoh-counts",
        default="100000,400000",
        help="zenoh: the burst sizes (put as fast as the publisher goes)",
    )
    parser.add_argument(
        "--src",
        type=Path,
        default=HERE.parent / "src",
        help="the ros_mobile_bridge sources rmb hz runs from (another version's to compare)",
    )
    args = parser.parse_args()
    header = (
        f"{'target':>8} {'sent/s':>9} {'bare n':>8} {'bare/s':>9} "
        f"{'rmb n':>8} {'rmb drop':>8} {'rmb hz':>9} {'ratio':>6}"
    )
    rows: list[dict[str, Any]] = []
    failed: list[str] = []

    def show(row: dict[str, Any]) -> None:
        rows.append(row)
        print(
            f"{row['target_hz'] or 'burst':>8} {row['sent_hz']:>9.0f} {row['bare_received']:>8} "
            f"{row['bare_hz']:>9.0f} {row['rmb_received']:>8} {row['rmb_dropped']:>8} "
            f"{row['rmb_hz']:>9.0f} {row['ratio']:>6.2f}",
            flush=True,
        )
        if row["rmb_received"] > row["sent"] or row["bare_received"] > row["sent"]:
            failed.append(f"{row['target_hz']}: more received than sent")
        if row["rmb_received"] == 0:
            failed.append(f"{row['target_hz']}: rmb hz printed no figures")

    print(header)
    if args.transport == "zenoh":
        for row in zenoh_rows(args):
            show(row)
    else:
        peer, port = start_peer(args.backlog)
        url = f"ws://127.0.0.1:{port}"
        try:
            for rate in (int(r) for r in args.rates.split(",")):
                show(one_rate(url, peer, rate, args.seconds, args.backend, args.src))
        finally:
            assert peer.stdin is not None
            peer.stdin.write("quit\n")
            peer.stdin.flush()
            peer.wait(10)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    if failed:
        print("FAILED: " + "; ".join(failed))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
