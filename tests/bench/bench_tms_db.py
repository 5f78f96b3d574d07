"""tms_db benchmarks (issue 7): the embedded store across processes.

1. Concurrency campaign: 4 writer + 4 reader processes for 30 s (increments, compare-and-set loops,
   whole-record updates, blackboard flags); prints operation counts and checks no lost update, no torn
   document, every acknowledged write present.
2. Parameter read latency in 4 reader processes while 4 writer processes write flags: median, p99
   (goal: median < 1 ms), and the sustained flag writes/s of those writers (goal >= 1,000/s).

``python -m tests.bench tms_db`` (``TMS_DB_BENCH_SECONDS`` shortens the campaign).
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from tests.bench.stats import summary_ms
from tests.tms_db.workers import run_hammer, verify_store


def main() -> None:
    seconds = float(os.environ.get("TMS_DB_BENCH_SECONDS", "30"))
    with tempfile.TemporaryDirectory(prefix="tms_db_bench_") as tmp:
        tmp = Path(tmp)
        (tmp / "a").mkdir()
        wsum, rsum, acks, _ = run_hammer(tmp / "a" / "db", tmp / "a", writers=4, readers=4, seconds=seconds)
        problems = verify_store(tmp / "a" / "db", acks, exact=True) + [p for r in rsum for p in r["first_problems"]]
        ops = {k: sum(w[k] for w in wsum) for k in ("inc", "cas", "set", "flag", "cas_retries")}
        writes = ops["inc"] + ops["cas"] + ops["set"] + ops["flag"]
        print(f"concurrency, 4 writers + 4 readers, {seconds:.0f} s: {writes} acknowledged writes "
              f"({writes / seconds:.0f}/s: {ops['inc']} increments, {ops['cas']} compare-and-set "
              f"[{ops['cas_retries']} retries], {ops['set']} record updates, {ops['flag']} flags), "
              f"{sum(r['reads'] for r in rsum)} checked reads; "
              f"problems: {len(problems)}{' ' + str(problems[:3]) if problems else ''}")

        (tmp / "b").mkdir()
        lat_seconds = min(seconds, 10.0)
        wsum, rsum, acks, samples = run_hammer(tmp / "b" / "db", tmp / "b", writers=4, readers=4,
                                               seconds=lat_seconds, mode="flags", sample_reads=True)
        latencies = [v for path in samples for v in json.loads(path.read_text())]
        flags = sum(w["flag"] for w in wsum)
        span = max(w["seconds"] for w in wsum)
        problems = verify_store(tmp / "b" / "db", acks, exact=True, mode="flags")
        print(f"parameter read latency (get_parameter ic120/LOAD_PATH) in 4 reader processes while 4 processes "
              f"write flags: {summary_ms(latencies)}")
        print(f"sustained flag writes (set_fields, 4 writer processes, {lat_seconds:.0f} s): "
              f"{flags / span:.0f} writes/s; problems: {len(problems)}")

        (tmp / "c").mkdir()
        wsum, _r, acks, _s = run_hammer(tmp / "c" / "db", tmp / "c", writers=1, readers=0,
                                        seconds=min(seconds, 5.0), mode="flags")
        print(f"flag writes, 1 writer process alone: {wsum[0]['flag'] / wsum[0]['seconds']:.0f} writes/s")
        print(f"TmsdbGetParameter service round trip to a tms_db_reader process: {service_latency(tmp / 'b' / 'db')}")


def service_latency(db: Path, calls: int = 500) -> str:
    """Round trip of ``/tms_db_reader_parameter`` from this process to a reader node process."""
    import time

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from tests.rosproc import Proc, executable, isolated_domain, ros_env
    from tms_msg_db.srv import TmsdbGetParameter

    with isolated_domain() as domain:
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        node_proc = Proc([str(executable("tms_db", "tms_db_reader")), "--ros-args", "-p", f"db_path:={db}"],
                         ros_env(domain))
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        try:
            node = rclpy.create_node("bench_tms_db", context=context)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            client = node.create_client(TmsdbGetParameter, "/tms_db_reader_parameter")
            if not client.wait_for_service(timeout_sec=30):
                raise RuntimeError(f"tms_db_reader did not come up:\n{node_proc.output}")
            request = TmsdbGetParameter.Request(model_name="ic120", record_name="LOAD_PATH")
            durations = []
            for i in range(calls + 20):
                t = time.perf_counter()
                future = client.call_async(request)
                executor.spin_until_future_complete(future, timeout_sec=10)
                if not future.done() or not future.result().keys:
                    raise RuntimeError("TmsdbGetParameter call failed")
                if i >= 20:  # warm-up excluded
                    durations.append(time.perf_counter() - t)
            return summary_ms(durations)
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.shutdown(context=context)
            node_proc.kill()
