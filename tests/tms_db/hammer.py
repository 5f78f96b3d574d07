"""Worker processes that hammer one store: used by the concurrency/durability tests and the bench.

``--path`` is an embedded store's directory or a ``mongodb://`` URI naming its database (:func:`open_at`).

``python -m tests.tms_db.hammer writer --path DB --wid 0 --seconds 5 --ack FILE [--start-at T] [--mode mixed|flags]``
``python -m tests.tms_db.hammer reader --path DB --writers 4 --seconds 5 [--start-at T] [--samples FILE]``

Writers (mode ``mixed``) repeat four kinds of acknowledged write and append one line per *returned*
call to their ack file (O_APPEND, unbuffered, so a SIGKILL loses at most the line of the call in flight):
``inc`` (increment of the shared ``HAMMER.counter``), ``cas`` (compare-and-set loop on ``HAMMER.cas``),
``set N`` (whole-record update of ``W<wid>``: seq=N, neg=-N, text="N", even=(N is even), arr=[N]*7) and
``flag N`` (field ``w<wid>`` of the shared blackboard record ``FLAGS``). Mode ``flags`` only does ``flag``.
Readers check every document they see: ``W<k>`` internally consistent (no torn document) with types kept,
and per-writer values never going backwards. Each process prints one JSON summary line at the end.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from tms_db import Store, open_store

SETUP_RECORDS = ("HAMMER", "FLAGS")


def open_at(location: str | os.PathLike) -> Store:
    """The store at ``location``: a ``mongodb://`` URI, else an embedded store's directory."""
    text = str(location)
    return open_store(uri=text) if text.startswith(("mongodb://", "mongodb+srv://")) else open_store(path=text)


def prepare(path: str, writers: int) -> None:
    """Create the records the workers use."""
    with open_at(path) as store:
        store.upsert_parameter({"record_name": "HAMMER", "type": "dynamic", "counter": 0, "cas": 0})
        store.upsert_parameter({"record_name": "FLAGS", "type": "dynamic", **{f"w{k}": 0 for k in range(writers)}})
        for k in range(writers):
            store.upsert_parameter({"record_name": f"W{k}", "type": "dynamic", "seq": 0, "neg": 0, "text": "0",
                                    "even": True, "arr": [0] * 7})
        # a bench record to read
        store.upsert_parameter({"model_name": "ic120", "type": "static", "record_name": "LOAD_PATH",
                                "x": [1.0, 2.0, 3.0], "y": [0.0, 1.0, 2.0], "z": [0.0] * 3, "qx": [0.0] * 3,
                                "qy": [0.0] * 3, "qz": [0.0] * 3, "qw": [1.0] * 3})


def _wait_start(start_at: float) -> None:
    delay = start_at - time.time()
    if delay > 0:
        time.sleep(delay)


def writer(args: argparse.Namespace) -> dict:
    store = open_at(args.path)
    ack = os.open(args.ack, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    _wait_start(args.start_at)
    deadline = time.monotonic() + args.seconds
    counts = {"inc": 0, "cas": 0, "set": 0, "flag": 0, "cas_retries": 0}
    # continue numbering after a restart (durability test), so acknowledged numbers only grow
    n = max(store.get_record(f"W{args.wid}")["seq"], store.get_record("FLAGS")[f"w{args.wid}"])
    t0 = time.monotonic()
    while time.monotonic() < deadline:
        n += 1
        if args.mode == "mixed":
            store.increment("HAMMER", "counter")
            os.write(ack, b"inc\n")
            counts["inc"] += 1
            while True:
                current = store.get_record("HAMMER")["cas"]
                if store.compare_and_set("HAMMER", "cas", current, current + 1):
                    break
                counts["cas_retries"] += 1
            os.write(ack, b"cas\n")
            counts["cas"] += 1
            store.set_fields(f"W{args.wid}", {"seq": n, "neg": -n, "text": str(n), "even": n % 2 == 0, "arr": [n] * 7})
            os.write(ack, f"set {n}\n".encode())
            counts["set"] += 1
        store.set_fields("FLAGS", {f"w{args.wid}": n})
        os.write(ack, f"flag {n}\n".encode())
        counts["flag"] += 1
    counts["seconds"] = time.monotonic() - t0
    os.close(ack)
    store.close()
    return {"role": "writer", "wid": args.wid, **counts}


def check_w(doc: dict) -> str | None:
    """Problem with one ``W<k>`` document, or None when it is whole and typed."""
    n = doc["seq"]
    if type(n) is not int or type(doc["neg"]) is not int or type(doc["even"]) is not bool:
        return f"types changed: {doc!r}"
    if doc["neg"] != -n or doc["text"] != str(n) or doc["even"] != (n % 2 == 0) or doc["arr"] != [n] * 7:
        return f"torn document: {doc!r}"
    return None


def reader(args: argparse.Namespace) -> dict:
    store = open_at(args.path)
    _wait_start(args.start_at)
    deadline = time.monotonic() + args.seconds
    last_seq = [0] * args.writers
    last_flag = [0] * args.writers
    last_counter = 0
    reads = 0
    problems: list[str] = []
    latencies: list[float] = []
    while time.monotonic() < deadline:
        if args.samples:  # bench: time the parameter read a subtask does
            t = time.perf_counter()
            store.get_parameter("ic120", "LOAD_PATH")
            latencies.append(time.perf_counter() - t)
            reads += 1
        hammer = store.get_record("HAMMER")
        if hammer["counter"] < last_counter:
            problems.append(f"HAMMER.counter went back {last_counter} -> {hammer['counter']}")
        last_counter = hammer["counter"]
        flags = store.get_record("FLAGS")
        for k in range(args.writers):
            if type(flags[f"w{k}"]) is not int or flags[f"w{k}"] < last_flag[k]:
                problems.append(f"FLAGS.w{k} went back {last_flag[k]} -> {flags[f'w{k}']!r}")
            last_flag[k] = flags[f"w{k}"]
            if not args.samples:
                doc = store.get_record(f"W{k}")
                problem = check_w(doc)
                if problem is None and doc["seq"] < last_seq[k]:
                    problem = f"W{k}.seq went back {last_seq[k]} -> {doc['seq']}"
                if problem:
                    problems.append(problem)
                last_seq[k] = doc["seq"]
                reads += 1
        reads += 2
    store.close()
    if args.samples:
        with open(args.samples, "w") as fh:
            json.dump(latencies, fh)
    return {"role": "reader", "reads": reads, "problems": len(problems), "first_problems": problems[:5]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="hammer")
    p.add_argument("role", choices=["writer", "reader", "prepare"])
    p.add_argument("--path", required=True)
    p.add_argument("--wid", type=int, default=0)
    p.add_argument("--writers", type=int, default=4)
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--ack", default=None)
    p.add_argument("--mode", choices=["mixed", "flags"], default="mixed")
    p.add_argument("--start-at", type=float, default=0.0)
    p.add_argument("--samples", default=None, help="reader: time parameter reads and write them here (JSON)")
    args = p.parse_args(argv)
    if args.role == "prepare":
        prepare(args.path, args.writers)
        return 0
    summary = writer(args) if args.role == "writer" else reader(args)
    print(json.dumps(summary), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
