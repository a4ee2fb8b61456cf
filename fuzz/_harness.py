"""What every fuzz harness here shares: running random sessions under
hypothesis, and the command line that reports what the run reached."""

from __future__ import annotations

import argparse
from collections import Counter
from collections.abc import Callable

from hypothesis import HealthCheck, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

__all__ = ["cli_main", "run_sessions"]


def run_sessions(
    run_session: Callable[[st.DataObject], None], max_examples: int, seed: int | None
) -> None:
    """Run ``max_examples`` random sessions; raises on the first contract
    breach. A ``seed`` makes the run reproducible."""

    @settings(
        max_examples=max_examples,
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(st.data())
    def fuzz(data: st.DataObject) -> None:
        run_session(data)

    if seed is not None:
        fuzz = hypothesis_seed(seed)(fuzz)
    fuzz()


def cli_main(
    doc: str | None,
    run: Callable[[int, int | None], None],
    stats: Counter[str],
    argv: list[str] | None,
) -> int:
    """``--examples`` / ``--seed``, the run, then the counts of what it reached."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0] if doc else None)
    parser.add_argument("--examples", type=int, default=20_000, help="sessions to run")
    parser.add_argument("--seed", type=int, default=None, help="make the run reproducible")
    args = parser.parse_args(argv)
    run(args.examples, args.seed)
    print(f"ok: {args.examples} sessions, no exception escaped the engine")
    for name, count in stats.most_common():
        print(f"  {name:24} {count}")
    return 0
