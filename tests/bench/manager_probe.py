"""``tms_ts_manager`` with its tick timed from outside the code under test (run as a script, not as a module).

``python tests/bench/manager_probe.py --ros-args ...`` runs :func:`tms_ts.nodes.tms_ts_manager.main` as the installed
executable does, with ``TaskManager._tick`` wrapped to note when each tick starts. The times (monotonic seconds,
one a line) are appended to the file named by ``TMS_PROBE_TICKS`` every 0.5 s, so they survive a kill. The wrapper
touches nothing but the clock, so the same probe times the manager of another checkout
(``PYTHONPATH=/tmp/old python tests/bench/manager_probe.py``: the import resolves to that checkout's ``tms_ts``).

It imports nothing from ``tests`` (run from another checkout, that package may not have this file).
"""

from __future__ import annotations

import os
import sys
import time


def main() -> int:
    from tms_ts.nodes import tms_ts_manager as manager

    out_path = os.environ["TMS_PROBE_TICKS"]
    ticks: list[float] = []
    flushed = [time.monotonic()]
    tick = manager.TaskManager._tick

    def timed_tick(self) -> None:
        now = time.monotonic()
        ticks.append(now)
        try:
            tick(self)
        finally:
            if now - flushed[0] >= 0.5:
                flushed[0] = now
                with open(out_path, "a") as f:
                    f.write("".join(f"{t:.6f}\n" for t in ticks))
                ticks.clear()

    manager.TaskManager._tick = timed_tick
    print(f"manager_probe: tms_ts from {os.path.dirname(os.path.dirname(manager.__file__))}", flush=True)
    return manager.main()


if __name__ == "__main__":
    sys.path[:] = [p for p in sys.path if os.path.abspath(p) != os.path.dirname(os.path.abspath(__file__))]
    sys.exit(main())
