"""The frame path: CPU per CAN frame of python-can's in-process ``virtual`` bus against ``udp_multicast``, same run.

One process, two threads, as the plant and a converter would share a process: a *sender* emits the ZX200's state
frames at their DBC cycle times (``FrameScheduler``, as sim_bridge's PlantCanIO does: encode with the COM3 codec,
``bus.send``) and, after each send burst, drains its own bus as the plant polls for commands; a *receiver*
blocks in ``bus.recv`` and decodes every frame (the converter's side). On ``udp_multicast`` every frame also
reaches the sender's own socket (the sender reads and drops it, as the plant does); the ``virtual`` buses are
opened with ``receive_own_messages=False`` (com3_can.bus), so nothing comes back. The sender sleeps until the
next frame is due (the ZX200 set's cycle times share 10 ms multiples: about 100 wakes a second on both).

Each interface runs ``FRAMES_BENCH_S`` seconds, alternating ``FRAMES_BENCH_ROUNDS`` times so both see the same
machine load. Printed per interface: frames sent and received, the process's CPU per received frame (rusage,
both threads), the sender's own echoes; then the ratio virtual / udp_multicast.
"""

from __future__ import annotations

import os
import random
import resource
import threading
import time

SECONDS = float(os.environ.get("FRAMES_BENCH_S", "10"))
ROUNDS = int(os.environ.get("FRAMES_BENCH_ROUNDS", "2"))


def _bus_configs(domain: int) -> dict[str, dict]:
    from tests.rosproc import free_can_ports

    group = f"239.74.{random.randrange(1, 255)}.{random.randrange(1, 255)}"
    port = free_can_ports(domain, 1)[0]
    return {"virtual": {"interface": "virtual", "channel": f"bench_frames_{os.getpid()}"},
            "udp_multicast": {"interface": "udp_multicast", "channel": group, "port": port}}


def _run(cfg: dict, seconds: float) -> dict[str, float]:
    import can

    from com3_can.bus import open_bus
    from com3_can.codec import load_codec
    from com3_can.scheduler import FrameScheduler

    codec = load_codec("zx200")
    rng = random.Random(1)
    values = {n: {s.name: rng.uniform(s.minimum, s.maximum) for s in codec.signals(n)} for n in codec.state_frames}
    sender, receiver = open_bus(cfg), open_bus(cfg)
    stop = threading.Event()
    counts = {"sent": 0, "received": 0, "echoes": 0, "decode_errors": 0}

    def receive() -> None:
        while not stop.is_set():
            msg = receiver.recv(timeout=0.1)
            if msg is None:
                continue
            try:
                codec.decode(msg.arbitration_id, bytes(msg.data))
            except Exception:  # noqa: BLE001 - counted; a bench must not stop on one frame
                counts["decode_errors"] += 1
            counts["received"] += 1

    def send(end: float) -> None:
        schedule = FrameScheduler({n: codec.cycle_ms(n) / 1000.0 for n in codec.state_frames}, time.monotonic())
        while True:
            now = time.monotonic()
            if now >= end:
                return
            for frame in schedule.due(now):
                data = codec.encode(frame, values[frame])
                sender.send(can.Message(arbitration_id=codec.frame_id(frame), data=data, is_extended_id=True))
                counts["sent"] += 1
            while sender.recv(timeout=0.0) is not None:  # the plant's poll: its own frames come back here
                counts["echoes"] += 1
            time.sleep(max(0.0, min(end, schedule.next_due()) - time.monotonic()))  # to the next due frame

    rx = threading.Thread(target=receive, daemon=True)
    rx.start()
    time.sleep(0.5)  # the receiver is waiting before the first frame
    r0, w0 = resource.getrusage(resource.RUSAGE_SELF), time.monotonic()
    send(w0 + seconds)
    time.sleep(0.2)  # the last frames arrive
    r1, wall = resource.getrusage(resource.RUSAGE_SELF), time.monotonic() - w0
    stop.set()
    rx.join(2.0)
    sender.shutdown()
    receiver.shutdown()
    cpu = r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime
    return {"cpu_s": cpu, "wall_s": wall, **counts}


def main() -> None:
    from com3_can.codec import load_codec

    codec = load_codec("zx200")
    rate = sum(1000.0 / codec.cycle_ms(n) for n in codec.state_frames)
    print(f"ZX200 state set: {len(codec.state_frames)} frames, {rate:.0f} frames/s at their cycle times; "
          f"{SECONDS:g} s per run, {ROUNDS} rounds", flush=True)
    from tests.rosproc import isolated_domain

    with isolated_domain() as domain:
        configs = _bus_configs(domain)
        totals: dict[str, list[dict[str, float]]] = {name: [] for name in configs}
        runs = [(name, _run(cfg, SECONDS)) for _ in range(ROUNDS) for name, cfg in configs.items()]
    for name, r in runs:
        totals[name].append(r)
        lost = r["sent"] - r["received"]
        print(f"{name:13s}: sent {r['sent']:.0f}, received {r['received']:.0f} (lost {lost:.0f}), "
              f"sender's own echoes {r['echoes']:.0f}; {r['cpu_s'] / r['wall_s'] * 100:.1f} % of a core, "
              f"{r['cpu_s'] / max(1, r['received']) * 1e6:.1f} us CPU per frame", flush=True)
    per_frame = {
        name: sum(r["cpu_s"] for r in rs) / max(1, sum(r["received"] for r in rs)) for name, rs in totals.items()
    }
    print(f"CPU per frame (sender + receiver, all rounds): virtual {per_frame['virtual'] * 1e6:.1f} us, "
          f"udp_multicast {per_frame['udp_multicast'] * 1e6:.1f} us; "
          f"ratio virtual/udp_multicast {per_frame['virtual'] / per_frame['udp_multicast']:.2f}", flush=True)


if __name__ == "__main__":
    main()
