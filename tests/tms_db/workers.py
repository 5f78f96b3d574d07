"""Start hammer worker processes and check the store afterwards (shared by tests and the bench); ``db`` is an
embedded store's directory or a ``mongodb://`` URI with its database (:func:`tests.tms_db.hammer.open_at`).

``python -m tests.tms_db.workers append --path DB --record R --model M --wid W --count K [--start-at T]``: one
process appending ``K`` waypoints to record ``R`` through the DB boundary's ``pose_query`` (:func:`append_waypoints`);
:func:`run_appenders` starts several at once.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

from tests.rosproc import ROOT
from tests.tms_db import hammer

PY = sys.executable


def spawn(role: str, path: Path | str, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([PY, "-m", "tests.tms_db.hammer", role, "--path", str(path), *extra], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def summary_of(proc: subprocess.Popen, timeout: float) -> dict:
    out, err = proc.communicate(timeout=timeout)
    if proc.returncode != 0:
        raise AssertionError(f"worker exited {proc.returncode}: {err[-2000:]}")
    return json.loads(out.strip().splitlines()[-1])


def read_acks(path: Path) -> tuple[Counter, dict[str, int]]:
    """Counts of acknowledged ``inc``/``cas`` and the last acknowledged ``set``/``flag`` numbers."""
    counts: Counter = Counter()
    last = {"set": 0, "flag": 0}
    if path.exists():
        for line in path.read_text().splitlines():
            kind, _, num = line.partition(" ")
            counts[kind] += 1
            if num:
                last[kind] = max(last[kind], int(num))
    return counts, last


def run_hammer(
    db: Path | str,
    workdir: Path,
    *,
    writers: int = 4,
    readers: int = 4,
    seconds: float = 5.0,
    mode: str = "mixed",
    sample_reads: bool = False,
) -> tuple[list[dict], list[dict], list[Path], list[Path]]:
    """Run writers + readers concurrently for ``seconds``; returns their summaries, ack files, sample files."""
    hammer.prepare(str(db), writers)
    start_at = f"{time.time() + 2.0:.3f}"  # all workers start together, after interpreter start-up
    acks = [workdir / f"ack{w}.log" for w in range(writers)]
    samples = [workdir / f"samples{r}.json" for r in range(readers)]
    wprocs = [spawn("writer", db, "--wid", str(w), "--seconds", str(seconds), "--ack", str(acks[w]),
                    "--mode", mode, "--start-at", start_at) for w in range(writers)]
    rprocs = [spawn("reader", db, "--writers", str(writers), "--seconds", str(seconds), "--start-at", start_at,
                    *(["--samples", str(samples[r])] if sample_reads else [])) for r in range(readers)]
    wsum = [summary_of(p, seconds + 60) for p in wprocs]
    rsum = [summary_of(p, seconds + 60) for p in rprocs]
    return wsum, rsum, acks, samples


def verify_store(
    db: Path | str, acks: list[Path], *, exact: bool, mode: str = "mixed", slack: int | None = None
) -> list[str]:
    """Every acknowledged write is present (``exact``: and nothing else, i.e. no write in flight)."""
    problems = []
    with hammer.open_at(db) as store:
        problems += store.check()
        totals: Counter = Counter()
        for w, path in enumerate(acks):
            counts, last = read_acks(path)
            totals.update(counts)
            flag = store.get_record("FLAGS")[f"w{w}"]
            if not (flag == last["flag"] or (not exact and flag == last["flag"] + 1)):
                problems.append(f"FLAGS.w{w} = {flag}, last acknowledged {last['flag']}")
            if mode == "mixed":
                doc = store.get_record(f"W{w}")
                problem = hammer.check_w(doc)
                if problem:
                    problems.append(problem)
                if not (doc["seq"] == last["set"] or (not exact and doc["seq"] == last["set"] + 1)):
                    problems.append(f"W{w}.seq = {doc['seq']}, last acknowledged {last['set']}")
        if mode == "mixed":
            doc = store.get_record("HAMMER")
            slack = 0 if exact else (len(acks) if slack is None else slack)
            for field, kind in (("counter", "inc"), ("cas", "cas")):
                if not totals[kind] <= doc[field] <= totals[kind] + slack:
                    problems.append(f"HAMMER.{field} = {doc[field]}, acknowledged {totals[kind]} (lost updates)")
    return problems


def waypoint(wid: int, i: int) -> dict[str, float]:
    """Appender ``wid``'s ``i``-th pose: every field derived from ``x`` (= 1000 * wid + i), so a waypoint whose fields
    did not land at one index of every array shows."""
    x = 1000.0 * wid + i
    return {"x": x, "y": -x, "z": x + 0.5, "qx": 0.0, "qy": 0.0, "qz": x / 1e4, "qw": 1.0}


def append_waypoints(path: str, record: str, model: str, wid: int, count: int, start_at: float = 0.0) -> dict:
    """Append ``count`` waypoints (:func:`waypoint`) to ``record`` of ``model``, one ``pose_query`` each, as the
    original's ``tms_db_writer_param`` does for every ``TmsdbQuery`` it receives."""
    from tms_db.boundary import apply_query

    with hammer.open_at(path) as store:
        delay = start_at - time.time()
        if delay > 0:
            time.sleep(delay)
        t0 = time.monotonic()
        for i in range(count):
            apply_query(store, "pose_query", "", record, model, waypoint(wid, i), [])
        return {"role": "appender", "wid": wid, "appended": count, "seconds": time.monotonic() - t0}


def run_appenders(db: Path | str, record: str, model: str, *, appenders: int, count: int) -> list[dict]:
    """``appenders`` processes appending ``count`` waypoints each to one record at once; their summaries."""
    start_at = f"{time.time() + 2.0:.3f}"  # all start together, after interpreter start-up
    procs = [subprocess.Popen([PY, "-m", "tests.tms_db.workers", "append", "--path", str(db), "--record", record,
                               "--model", model, "--wid", str(w), "--count", str(count), "--start-at", start_at],
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              start_new_session=True) for w in range(appenders)]
    try:
        return [summary_of(p, 120) for p in procs]
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="workers")
    p.add_argument("role", choices=["append"])
    p.add_argument("--path", required=True)
    p.add_argument("--record", required=True)
    p.add_argument("--model", default="")
    p.add_argument("--wid", type=int, default=0)
    p.add_argument("--count", type=int, default=25)
    p.add_argument("--start-at", type=float, default=0.0)
    args = p.parse_args(argv)
    summary = append_waypoints(args.path, args.record, args.model, args.wid, args.count, args.start_at)
    print(json.dumps(summary), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
