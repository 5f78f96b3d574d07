"""`make bench`: run every tests/bench/bench_*.py module's ``main()`` and print its figures.

``python -m tests.bench [name ...]`` runs only the named modules (e.g. ``ros_baseline``).
"""

from __future__ import annotations

import importlib
import sys
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    here = Path(__file__).parent
    names = sorted(p.stem.removeprefix("bench_") for p in here.glob("bench_*.py"))
    chosen = argv or names
    unknown = sorted(set(chosen) - set(names))
    if unknown:
        print(f"unknown benchmark(s) {unknown}; known: {names}", file=sys.stderr)
        return 2
    failed = 0
    for name in chosen:
        print(f"=== bench {name} ===", flush=True)
        start = time.monotonic()
        try:
            importlib.import_module(f"tests.bench.bench_{name}").main()
        except Exception as exc:  # noqa: BLE001 - one failing benchmark must not hide the others
            failed += 1
            print(f"bench {name} FAILED: {type(exc).__name__}: {exc}", flush=True)
        print(f"=== bench {name}: {time.monotonic() - start:.1f} s ===", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
