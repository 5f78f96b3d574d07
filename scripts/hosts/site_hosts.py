#!/usr/bin/env python3
"""One site split over Linux network namespaces standing for its computers (docs/deployment.md).

Hosts (one network namespace each, named ``<prefix><host>``):

* ``site_server``  - DB, task scheduler, subtask servers, sensing, supervisor;
* ``zx200_pc``, ``ic120_pc`` - each machine's onboard PC: its COM3 converter, controller or navigator,
  localisation;
* ``plant``        - simulation only: the MuJoCo plant, standing for the machines themselves.

Links:

* the site network: a bridge named ``site0`` in the calling namespace (the site switch; run this under
  ``scripts/isolated.sh`` so it stays off the computer's own network) with one veth per host, called ``site0``
  inside the host and ``lan-<host>`` on the bridge. DDS uses only ``site0`` (``config/dds/fastdds_hosts.xml``).
  Addresses 10.74.0.0/24: the bridge .1, site_server .10, zx200_pc .20, ic120_pc .21, plant .30.
* each machine's "CAN cable": a veth ``can-<machine>`` straight from its PC to the plant (10.75.<i>.0/30),
  carrying the machine's python-can ``udp_multicast`` bus (group and port of ``config/can/<machine>.yaml``,
  routed onto the cable). DDS never uses it; a partition of the site network does not cut it, as unplugging a
  PC's network cable does not cut the machine's CAN bus.

A partition is ``cut <host>`` (the host's port on the switch goes down) and ``restore <host>``.

Which node runs on which host: the containers of the launch file (``container:`` key), except that a COM3
converter runs on its machine's PC, where its CAN bus is (in the one-computer simulation it shares the plant's
process instead; docs/architecture.md "Processes and hosts"). ``launchfile <host>`` writes that host's part of
a launch file as a small launch file for ``tms-launch``.

CLI (as root; ``--prefix`` names the namespaces, default ``tms-``)::

    scripts/isolated.sh .venv/bin/python scripts/hosts/site_hosts.py demo     # whole paper demo over the hosts
    .venv/bin/python scripts/hosts/site_hosts.py up | down | check
    .venv/bin/python scripts/hosts/site_hosts.py cut zx200_pc | restore zx200_pc
    .venv/bin/python scripts/hosts/site_hosts.py launchfile zx200_pc [--launch FILE] > zx200_pc.yaml
    .venv/bin/python scripts/hosts/site_hosts.py exec zx200_pc -- .venv/bin/tms-launch zx200_pc.yaml
    .venv/bin/python scripts/hosts/site_hosts.py env        # the DDS environment of a host process
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import yaml  # noqa: E402

#: the computers of a site, in start order (the plant first: the others' simulated clock comes from it)
HOSTS = ("plant", "site_server", "zx200_pc", "ic120_pc")
#: machine -> its onboard PC
MACHINE_PC = {"zx200": "zx200_pc", "ic120": "ic120_pc"}
#: the site network interface in every host (and the bridge's name in the calling namespace)
SITE_IF = "site0"
LAN = "10.74.0"
BRIDGE_ADDRESS = f"{LAN}.1"
ADDRESS = {"site_server": f"{LAN}.10", "zx200_pc": f"{LAN}.20", "ic120_pc": f"{LAN}.21", "plant": f"{LAN}.30"}
DEFAULT_PREFIX = "tms-"
HOST_PROFILES = ROOT / "config" / "dds" / "fastdds_hosts.xml"
PAPER_LAUNCH = ROOT / "config" / "launch" / "paper_experiment.yaml"
#: [s wall] a machine PC's converter latches emg_stop after this long without its site heartbeat (sent every
#: 0.05 s by the machine's subtask server: three may be lost or late). The machine must be at rest within 0.5 s
#: of a cut: the latch comes 0.22-0.23 s after it, the pilot cut-off then needs about 0.2 s to bring the front to
#: rest (docs/deployment.md: 0.40-0.44 s in five runs; with 0.25 s, 0.46 and 0.53 s).
SITE_TIMEOUT_S = 0.2
#: niceness of the site heartbeat's senders (the subtask servers) in the hosts layout, as the paper launch gives
#: the ZX200's control path
SITE_SENDER_NICE = -10


class HostsError(RuntimeError):
    """A namespace or link could not be made; the message names the command and what it said."""


def run(cmd: Sequence[str]) -> str:
    """Run an ``ip`` command; raise :class:`HostsError` naming it and its error output on failure."""
    proc = subprocess.run(list(cmd), capture_output=True, text=True)
    if proc.returncode != 0:
        raise HostsError(f"`{' '.join(cmd)}` failed ({proc.returncode}): {proc.stderr.strip() or proc.stdout.strip()}")
    return proc.stdout


def unavailable() -> str | None:
    """Why network namespaces with veth links and a bridge cannot be made here, or None when they can."""
    if shutil.which("ip") is None or shutil.which("unshare") is None:
        return "iproute2 (ip) and util-linux (unshare) are needed for network namespaces"
    if os.geteuid() != 0:
        return "network namespaces need root (CAP_NET_ADMIN, CAP_SYS_ADMIN)"
    probe = subprocess.run(
        ["unshare", "-n", "sh", "-c", "ip link add tmsv0 type veth peer name tmsv1 && ip link add tmsb0 type bridge"],
        capture_output=True, text=True)
    if probe.returncode != 0:
        return f"this kernel cannot make network namespaces with veth pairs and a bridge: {probe.stderr.strip()}"
    return None


def host_env() -> dict[str, str]:
    """Environment of every ROS process on a site host: the host DDS profile, discovery beyond localhost."""
    return {"FASTRTPS_DEFAULT_PROFILES_FILE": str(HOST_PROFILES), "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}


def can_group(machine: str) -> tuple[str, int]:
    """The udp_multicast group and port of ``machine``'s COM3 bus (``config/can/<machine>.yaml``)."""
    from com3_can.bus import load_bus_config

    cfg = load_bus_config(machine)
    if cfg.get("interface") != "udp_multicast":
        raise HostsError(f"config/can/{machine}.yaml: interface {cfg.get('interface')!r}; the simulated CAN cable "
                         "between a machine PC and the plant carries udp_multicast")
    return str(cfg["channel"]), int(cfg["port"])


@dataclass(frozen=True)
class Site:
    """The namespaces of one site (``prefix`` + host name)."""

    prefix: str = DEFAULT_PREFIX
    machines: tuple[str, ...] = tuple(MACHINE_PC)

    def ns(self, host: str) -> str:
        if host not in HOSTS:
            raise HostsError(f"unknown host {host!r}; the hosts are {', '.join(HOSTS)}")
        return f"{self.prefix}{host}"

    def ip(self, host: str, *args: str) -> list[str]:
        return ["ip", "-n", self.ns(host), *args]

    def exec_cmd(self, host: str, cmd: Sequence[str], env: Mapping[str, str] | None = None) -> list[str]:
        """The command line running ``cmd`` inside ``host`` with the host DDS environment (plus ``env``)."""
        extra = {**host_env(), **(env or {})}
        return ["ip", "netns", "exec", self.ns(host), "env", *(f"{k}={v}" for k, v in extra.items()), *cmd]

    # -- making and removing -----------------------------------------------------------------------
    def up(self) -> None:
        """Create the hosts, the site network and the CAN cables (removing a left-over site first)."""
        self.down()
        try:
            run(["ip", "link", "add", SITE_IF, "type", "bridge"])
            # without an IGMP querier a snooping bridge would stop forwarding the DDS multicast after the
            # membership interval; a site switch of a few hosts floods it
            run(["ip", "link", "set", SITE_IF, "type", "bridge", "mcast_snooping", "0"])
            run(["ip", "addr", "add", f"{BRIDGE_ADDRESS}/24", "dev", SITE_IF])
            run(["ip", "link", "set", SITE_IF, "up"])
            for host in HOSTS:
                run(["ip", "netns", "add", self.ns(host)])
                run(self.ip(host, "link", "set", "lo", "up"))
                port = f"lan-{host}"
                run(["ip", "link", "add", port, "type", "veth", "peer", "name", "tmsnew0", "netns", self.ns(host)])
                run(self.ip(host, "link", "set", "tmsnew0", "name", SITE_IF))
                run(self.ip(host, "addr", "add", f"{ADDRESS[host]}/24", "dev", SITE_IF))
                run(self.ip(host, "link", "set", SITE_IF, "up"))
                run(["ip", "link", "set", port, "master", SITE_IF])
                run(["ip", "link", "set", port, "up"])
                # DDS discovery multicast leaves by the site network
                run(self.ip(host, "route", "add", "224.0.0.0/4", "dev", SITE_IF))
            for i, machine in enumerate(self.machines, start=1):
                self._cable(i, machine)
        except BaseException:
            self.down()
            raise

    def _cable(self, index: int, machine: str) -> None:
        pc, link = MACHINE_PC[machine], f"can-{machine}"
        group, _ = can_group(machine)
        run(["ip", "link", "add", "tmsnew1", "netns", self.ns("plant"), "type", "veth",
             "peer", "name", "tmsnew2", "netns", self.ns(pc)])
        for host, tmp, addr in (("plant", "tmsnew1", f"10.75.{index}.1/30"), (pc, "tmsnew2", f"10.75.{index}.2/30")):
            run(self.ip(host, "link", "set", tmp, "name", link))
            run(self.ip(host, "addr", "add", addr, "dev", link))
            run(self.ip(host, "link", "set", link, "up"))
            # python-can udp_multicast joins and sends by route lookup (no interface option): the bus's group
            # goes onto the cable, more specific than the site network's 224.0.0.0/4
            run(self.ip(host, "route", "add", f"{group}/32", "dev", link))

    def down(self) -> None:
        """Remove the hosts (their veth ends go with them) and the bridge; silent where already gone."""
        for host in HOSTS:
            subprocess.run(["ip", "netns", "del", self.ns(host)], capture_output=True)
        subprocess.run(["ip", "link", "del", SITE_IF], capture_output=True)

    def exists(self) -> bool:
        names = run(["ip", "netns", "list"]).split()
        return all(self.ns(h) in names for h in HOSTS)

    # -- partition ----------------------------------------------------------------------------------
    def cut(self, host: str) -> None:
        """Unplug ``host`` from the site network (its switch port down); its CAN cable stays."""
        self.ns(host)
        run(["ip", "link", "set", f"lan-{host}", "down"])

    def restore(self, host: str) -> None:
        self.ns(host)
        run(["ip", "link", "set", f"lan-{host}", "up"])


# -- which node on which host ----------------------------------------------------------------------
#: hosts of the paper launch's nodes by executable, for a launch file written before the ``container:`` key
#: (the key, where present, is what counts)
UNCONTAINED_HOST = {
    "sim_plant": "plant",
    "excavator_arm_controller": "zx200_pc", "zx200_planner": "zx200_pc",
    "ic120_localization": "ic120_pc", "ic120_navigator": "ic120_pc", "ic120_vessel": "ic120_pc",
    "tms_ts_subtasks": "site_server", "tms_sp_sensing": "site_server", "tms_ts_manager": "site_server",
    "tms_ur_experiment": "site_server", "tms_ur_panel": "site_server",
}


#: containers of the launch file that run on another container's host, as a process of their own there (the
#: site's sensing computer on the site server: sensing's long scan callbacks must not delay the manager's)
CONTAINER_HOST = {"sensing_pc": "site_server"}


def host_of(node: Mapping[str, Any]) -> str:
    """The host of a launch-file node: a COM3 converter on its machine's PC, any other node on its container."""
    if (node.get("package"), node.get("executable")) == ("com3_can", "com3_bridge"):
        machine = str((node.get("parameters") or {}).get("machine", ""))
        if machine not in MACHINE_PC:
            raise HostsError(f"com3_bridge {node.get('namespace', '')}/{node['name']}: machine {machine!r} has no PC "
                             f"host (known: {', '.join(MACHINE_PC)})")
        return MACHINE_PC[machine]
    container = node.get("container", UNCONTAINED_HOST.get(str(node.get("executable"))))
    container = CONTAINER_HOST.get(container, container)
    if container not in HOSTS:
        raise HostsError(f"node {node['name']!r}: container {container!r} is not a host ({', '.join(HOSTS)}); "
                         "every node of a launch file run over hosts names one")
    return str(container)


def host_launch(host: str, launch: Path = PAPER_LAUNCH, skip: Iterable[str] = (),
                overrides: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, Any]:
    """``host``'s part of ``launch`` as a launch-file mapping: its nodes, all in one container named ``host``.

    ``skip``: node names left out (tests leave out the supervisor); ``overrides``: node name -> parameters
    that replace the file's. Relative paths of the file are made absolute, so the result runs from anywhere.
    """
    from tms_launch.launch_file import NODE_KEYS
    from tms_ts.nodes.ros_port import HEARTBEAT_TOPIC

    composable = "container" in NODE_KEYS  # tms-launch runs a host's nodes as one container
    data = yaml.safe_load(Path(launch).read_text())
    skip = set(skip)
    nodes = []
    for node in data["nodes"]:
        if node["name"] in skip or host_of(node) != host:
            continue
        node = dict(node)
        if composable:
            node["container"] = node["container"] if node.get("container") in CONTAINER_HOST else host
        else:
            node.pop("container", None)
        params = dict(node.get("parameters") or {})
        if (node["package"], node["executable"]) == ("tms_ts", "tms_ts_subtasks"):
            # their heartbeat is what the machine PCs' site watchdogs wait for: a starved sender would stop a
            # machine as a cut link does, so it runs at a control loop's priority (root; else unchanged)
            node["nice"] = min(node.get("nice", 0), SITE_SENDER_NICE)
        if (node["package"], node["executable"]) == ("com3_can", "com3_bridge"):
            # on its machine's PC the converter watches the site link (com3_can/README.md, site watchdog)
            params.setdefault("site_heartbeat_topic", HEARTBEAT_TOPIC)
            params.setdefault("site_timeout_s", SITE_TIMEOUT_S)
        if isinstance(params.get("config"), str) and not Path(params["config"]).is_absolute():
            params["config"] = str(ROOT / params["config"])
        params.update((overrides or {}).get(node["name"], {}))
        node["parameters"] = params
        nodes.append(node)
    if not nodes:
        raise HostsError(f"{launch}: no node runs on host {host!r}")
    out = {k: v for k, v in data.items() if k != "nodes"}
    out["name"] = f"{data.get('name', Path(launch).stem)}@{host}"
    out["nodes"] = nodes
    return out


def write_host_launch(host: str, directory: Path, launch: Path = PAPER_LAUNCH, skip: Iterable[str] = (),
                      overrides: Mapping[str, Mapping[str, Any]] | None = None) -> Path:
    path = Path(directory) / f"{host}.yaml"
    path.write_text(yaml.safe_dump(host_launch(host, launch, skip, overrides), sort_keys=False))
    return path


# -- CLI -------------------------------------------------------------------------------------------
def _demo(site: Site, launch: Path, layout: str) -> int:
    """The paper launch over the hosts: every host's part under tms-launch, the plant first; ends with the
    site server's (its supervisor ends the run)."""
    import time

    reason = unavailable()
    if reason:
        print(f"[hosts] {reason}", file=sys.stderr)
        return 2
    site.up()
    procs: list[subprocess.Popen] = []
    tmp = Path(tempfile.mkdtemp(prefix="tms-hosts-"))
    try:
        db = os.environ.get("TMS_DB_PATH") or str(ROOT / "runs" / time.strftime("db-hosts-%Y%m%d-%H%M%S"))
        Path(db).mkdir(parents=True, exist_ok=True)
        subprocess.run([str(ROOT / ".venv" / "bin" / "tms-db"), "seed", "paper"], env={**os.environ, "TMS_DB_PATH": db},
                       check=True)
        from tms_launch.launch_file import NODE_KEYS

        tms_launch = [str(ROOT / ".venv" / "bin" / "tms-launch")]
        if "container" in NODE_KEYS:  # a launcher with layouts
            tms_launch += ["--layout", layout]
        for host in HOSTS:
            file = write_host_launch(host, tmp, launch)
            cmd = site.exec_cmd(host, [*tms_launch, str(file)], {"TMS_DB_PATH": db})
            print(f"[hosts] {host}: {' '.join(cmd)}", flush=True)
            procs.append(subprocess.Popen(cmd, cwd=ROOT))
        return procs[HOSTS.index("site_server")].wait()
    except KeyboardInterrupt:
        return 130
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(2)
                try:
                    p.wait(40)
                except subprocess.TimeoutExpired:
                    p.kill()
        site.down()
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--prefix", default=DEFAULT_PREFIX, help="namespace name prefix (default %(default)s)")
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("check", help="say whether namespaces can be made here")
    sub.add_parser("up", help="create the hosts and links")
    sub.add_parser("down", help="remove them")
    for name in ("cut", "restore"):
        sub.add_parser(name, help=f"{name} a host's site link").add_argument("host", choices=HOSTS)
    lf = sub.add_parser("launchfile", help="print a host's part of a launch file")
    lf.add_argument("host", choices=HOSTS)
    lf.add_argument("--launch", type=Path, default=PAPER_LAUNCH)
    ex = sub.add_parser("exec", help="run a command in a host with the host DDS environment")
    ex.add_argument("host", choices=HOSTS)
    ex.add_argument("command", nargs=argparse.REMAINDER)
    sub.add_parser("env", help="print the DDS environment of a host process")
    demo = sub.add_parser("demo", help="run the paper launch over the hosts")
    demo.add_argument("--launch", type=Path, default=PAPER_LAUNCH)
    demo.add_argument("--layout", default="composed", choices=("composed", "per-node"))
    args = ap.parse_args(argv)
    site = Site(args.prefix)
    try:
        if args.cmd == "check":
            reason = unavailable()
            print(reason or "ok: network namespaces, veth pairs and bridges can be made")
            return 1 if reason else 0
        if args.cmd == "up":
            site.up()
        elif args.cmd == "down":
            site.down()
        elif args.cmd == "cut":
            site.cut(args.host)
        elif args.cmd == "restore":
            site.restore(args.host)
        elif args.cmd == "launchfile":
            sys.stdout.write(yaml.safe_dump(host_launch(args.host, args.launch), sort_keys=False))
        elif args.cmd == "env":
            for k, v in host_env().items():
                print(f"export {k}={v}")
        elif args.cmd == "exec":
            cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
            if not cmd:
                ap.error("exec: no command given")
            os.execvp("ip", site.exec_cmd(args.host, cmd))
        elif args.cmd == "demo":
            return _demo(site, args.launch, args.layout)
    except HostsError as exc:
        print(f"[hosts] {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
