"""Small statistics helpers shared by the benchmarks."""

from __future__ import annotations

import statistics
from collections.abc import Sequence


def percentile(values: Sequence[float], q: float) -> float:
    """The q-th percentile (0..100) by nearest rank."""
    ordered = sorted(values)
    if not ordered:
        raise ValueError("percentile of no values")
    rank = max(0, min(len(ordered) - 1, round(q / 100 * (len(ordered) - 1))))
    return ordered[rank]


def summary_ms(values_s: Sequence[float]) -> str:
    """``median X ms, p99 Y ms (n=N)`` for durations in seconds."""
    return (
        f"median {statistics.median(values_s) * 1e3:.3f} ms, p99 {percentile(values_s, 99) * 1e3:.3f} ms, "
        f"max {max(values_s) * 1e3:.3f} ms (n={len(values_s)})"
    )
