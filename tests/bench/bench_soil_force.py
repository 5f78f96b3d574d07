"""CPU per call of the soil-tool force (sim_bridge.soil_force) the plant makes once per 10 ms step.

``fee_force`` and ``tool_force`` for 1 and 10 cutting tools (sandy loam, rakes 40-100 deg, depths 0.05-0.5 m,
moving at up to 1 m/s), best of ``SOIL_FORCE_BENCH_ROUNDS`` rounds of ``SOIL_FORCE_BENCH_CALLS`` calls each
(``time.process_time``, so other processes on the machine do not count). Printed: microseconds per call, and
for scale the cost of one small numpy call (``np.sin`` of 10 values) in the same run: the model is a fixed
number of such calls, so its cost hardly depends on the tool count.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

CALLS = int(os.environ.get("SOIL_FORCE_BENCH_CALLS", "2000"))
ROUNDS = int(os.environ.get("SOIL_FORCE_BENCH_ROUNDS", "5"))


def _per_call_us(fn) -> float:
    fn()  # warm the caches (the beta grid's trigonometry per soil)
    best = math.inf
    for _ in range(ROUNDS):
        start = time.process_time()
        for _ in range(CALLS):
            fn()
        best = min(best, (time.process_time() - start) / CALLS)
    return best * 1e6


def main() -> None:
    from sim_bridge.soil_force import load_soil_types

    soil = load_soil_types()["sandy_loam"]
    rng = np.random.default_rng(0)
    ten = rng.uniform(0.0, 1.0, 10)
    print(f"soil_force: one numpy call (np.sin of 10 values) {_per_call_us(lambda: np.sin(ten)):.2f} us", flush=True)
    for n in (1, 10):
        fee, tool = _bench(soil, rng, n)
        print(f"soil_force {n:2d} tool(s): fee_force {fee:6.1f} us/call, tool_force {tool:6.1f} us/call "
              f"({tool / 1e4:.2%} of a 10 ms step)", flush=True)


def _bench(soil, rng: np.random.Generator, n: int) -> tuple[float, float]:
    from sim_bridge.soil_force import fee_force, tool_force

    rake = np.radians(rng.uniform(40.0, 100.0, n))
    depth = rng.uniform(0.05, 0.5, n)
    width = rng.uniform(0.8, 3.5, n)
    vel = np.column_stack([rng.uniform(-1.0, 1.0, (n, 2)), rng.uniform(-0.2, 0.2, n)])
    speed = np.hypot(vel[:, 0], vel[:, 1])
    return (_per_call_us(lambda: fee_force(soil, rake, depth, width, speed=speed)),
            _per_call_us(lambda: tool_force(soil, vel, rake, depth, width)))

if __name__ == "__main__":
    main()
