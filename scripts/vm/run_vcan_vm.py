#!/usr/bin/env python3
"""Boot a VM with real SocketCAN once and run the CAN-layer tests inside it on ``vcan0``.

Why: this machine's kernel (and CI's) has no SocketCAN, so the udp_multicast stand-in is all the host can
test. A Debian kernel (``linux-image-amd64``) booted by virtme-ng under qemu software emulation over the
host's own filesystem has the ``vcan`` module, and sees the project's ``.venv`` as it is.

What it does: preflight (qemu, a kernel image whose modules include vcan, a static busybox, virtme-ng;
anything missing -> exit 77 with ``VM UNAVAILABLE: <what>, install: <how>``), then one boot running
``scripts/vm/guest.sh``, which brings up loopback and ``vcan0`` and runs pytest with
``TMS_CAN_TEST_BACKEND=socketcan``. The whole run is bounded by ``timeout_s`` (and the boot by
``boot_timeout_s``): past it the VM's process group is killed and the run fails naming the phase it hung
in. A failed ``modprobe`` or interface setup fails with the guest's own message. Tests that were skipped
inside the VM count as a failure: the point of the VM is that they run.

Exit status: 0 tests ran and passed; 1 anything failed (reason on stderr and in ``--json``); 77 unavailable.
Settings: ``config/vm/vcan.yaml``. Usage: ``.venv/bin/python scripts/vm/run_vcan_vm.py [--check]
[--timeout S] [--module NAME] [--json FILE] [-- extra pytest args]``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[2]
VENV = ROOT / ".venv"
DEFAULT_CONFIG = ROOT / "config" / "vm" / "vcan.yaml"
GUEST_SCRIPT = ROOT / "scripts" / "vm" / "guest.sh"
EXIT_UNAVAILABLE = 77
#: guest.sh's own exit codes -> what failed
GUEST_FAILURES = {90: "kernel module load", 91: "CAN interface setup", 92: "loopback setup", 93: "guest job"}
POLL_S = 0.25
TAG = "[vcan-vm]"


class VmUnavailableError(Exception):
    """The VM cannot be had on this machine; the message says what is missing and how to install it."""


class VmConfigError(ValueError):
    """config/vm/vcan.yaml is malformed; the message names the file, key and value."""


@dataclass(frozen=True)
class VmConfig:
    """Settings of the SocketCAN VM (config/vm/vcan.yaml)."""

    timeout_s: float
    boot_timeout_s: float
    kvm: bool
    cpus: int
    memory: str
    module: str
    interface: str
    time_scale: float
    boot_attempts: int
    pytest_args: tuple[str, ...]
    known_failures: dict[str, str] = field(default_factory=dict)


_FIELDS: dict[str, type | tuple[type, ...]] = {
    "timeout_s": (int, float),
    "boot_timeout_s": (int, float),
    "kvm": bool,
    "cpus": int,
    "memory": str,
    "module": str,
    "interface": str,
    "time_scale": (int, float),
    "boot_attempts": int,
    "pytest_args": list,
    "known_failures": dict,
}


def load_config(path: Path = DEFAULT_CONFIG) -> VmConfig:
    """Read and validate the VM settings; a missing key or wrong type raises VmConfigError naming it."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise VmConfigError(f"{path}: cannot read VM settings: {exc}") from exc
    if not isinstance(data, dict):
        raise VmConfigError(f"{path}: expected a mapping of VM settings, got {type(data).__name__}")
    for key, kind in _FIELDS.items():
        if key not in data:
            raise VmConfigError(f"{path}: missing key {key!r}")
        value = data[key]
        if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
            raise VmConfigError(f"{path}: {key}: expected {kind}, got {value!r}")
    unknown = sorted(set(data) - set(_FIELDS))
    if unknown:
        raise VmConfigError(f"{path}: unknown key(s) {unknown}; accepted: {sorted(_FIELDS)}")
    if data["timeout_s"] <= 0 or not 0 < data["boot_timeout_s"] <= data["timeout_s"]:
        raise VmConfigError(f"{path}: need 0 < boot_timeout_s <= timeout_s, got "
                            f"boot_timeout_s={data['boot_timeout_s']} timeout_s={data['timeout_s']}")
    known = data["known_failures"]
    bad = [k for k, v in known.items() if not (isinstance(k, str) and "::" in k and isinstance(v, str) and v.strip())]
    if bad:
        raise VmConfigError(f"{path}: known_failures: each key must be a test id 'file::name' with a reason, got {bad}")
    if not 1 <= data["boot_attempts"] <= 3:
        raise VmConfigError(f"{path}: boot_attempts must be 1..3, got {data['boot_attempts']}")
    if data["time_scale"] <= 0:
        raise VmConfigError(f"{path}: time_scale must be > 0, got {data['time_scale']}")
    if not re.fullmatch(r"[A-Za-z0-9_-]+", data["module"]) or not re.fullmatch(r"[A-Za-z0-9_.-]+", data["interface"]):
        raise VmConfigError(f"{path}: module/interface must be plain names, got "
                            f"{data['module']!r}/{data['interface']!r}")
    return VmConfig(**{**data, "timeout_s": float(data["timeout_s"]),
                       "boot_timeout_s": float(data["boot_timeout_s"]),
                       "time_scale": float(data["time_scale"]),
                       "pytest_args": tuple(str(a) for a in data["pytest_args"]),
                       "known_failures": dict(known)})


def find_kernel(boot: Path = Path("/boot"), modules: Path = Path("/lib/modules")) -> tuple[Path, str]:
    """Newest ``boot/vmlinuz-<ver>`` that has a ``modules/<ver>`` tree; VmUnavailableError if there is none.

    Whether the tree holds the wanted module is deliberately *not* checked here: a missing module is the
    VM's own failure (the guest's modprobe fails and the run fails with its message), not a missing tool.
    """
    images = sorted(boot.glob("vmlinuz-*"), key=lambda p: _version_key(p.name[len("vmlinuz-"):]), reverse=True)
    if not images:
        raise VmUnavailableError(f"no kernel image in {boot} (install: apt-get install linux-image-amd64)")
    for image in images:
        version = image.name[len("vmlinuz-"):]
        if (modules / version).is_dir():
            if not os.access(image, os.R_OK):
                raise VmUnavailableError(f"kernel image {image} is not readable by this user "
                                    f"(sudo chmod a+r {image}, or run as root)")
            return image, version
    found = ", ".join(p.name for p in images)
    raise VmUnavailableError(f"no kernel image with its modules: {found} have no {modules}/<ver> directory "
                        f"(install: apt-get install linux-image-amd64)")


def _version_key(version: str) -> tuple[int, ...]:
    return tuple(int(n) for n in re.findall(r"\d+", version))


@dataclass(frozen=True)
class Prereqs:
    """What the boot needs, found on this machine."""

    vng: Path
    qemu: Path
    busybox: Path
    kernel: Path
    kernel_version: str


def preflight(cfg: VmConfig, venv: Path = VENV) -> Prereqs:
    """Find qemu, virtme-ng, busybox and a kernel image with its modules; VmUnavailableError names what is missing."""
    missing: list[str] = []
    qemu = shutil.which("qemu-system-x86_64")
    if qemu is None:
        missing.append("qemu-system-x86_64 not found (install: apt-get install qemu-system-x86)")
    vng = venv / "bin" / "vng"
    if not os.access(vng, os.X_OK):
        missing.append(f"virtme-ng not installed in {venv} (install: bash scripts/vm/setup.sh)")
    busybox = shutil.which("busybox")
    if busybox is None:
        missing.append("busybox not found (install: apt-get install busybox-static)")
    kernel: tuple[Path, str] | None = None
    try:
        kernel = find_kernel()
    except VmUnavailableError as exc:
        missing.append(str(exc))
    if missing or kernel is None or qemu is None or busybox is None:
        raise VmUnavailableError("; ".join(missing))
    return Prereqs(vng=vng, qemu=Path(qemu), busybox=Path(busybox), kernel=kernel[0], kernel_version=kernel[1])


def vng_command(cfg: VmConfig, pre: Prereqs, outdir: Path) -> list[str]:
    """The virtme-ng command line: boot ``pre.kernel``, repo as a guest-only overlay, ``outdir`` shared r/w."""
    cmd = [str(pre.vng), "--run", str(pre.kernel), "--user", "root", "--cpus", str(cfg.cpus),
           "--memory", cfg.memory, "--overlay-rwdir", str(ROOT), "--rwdir", str(outdir),
           "--busybox", str(pre.busybox), "--qemu", str(pre.qemu),
           "--exec", f"sh {shlex.quote(str(GUEST_SCRIPT))} {shlex.quote(str(outdir))}"]
    if not cfg.kvm:
        cmd.insert(1, "--disable-kvm")
    return cmd


@dataclass
class VmResult:
    """Outcome of one VM run; ``reason`` is empty on success."""

    ok: bool
    reason: str
    exit_code: int | None
    wall_s: float
    kernel: str = ""
    phases_s: dict[str, float] = field(default_factory=dict)
    tests: dict[str, int] = field(default_factory=dict)
    known_failed: dict[str, str] = field(default_factory=dict)
    known_passed: list[str] = field(default_factory=list)
    boot_failures: list[str] = field(default_factory=list)
    guest_failure: str = ""
    outdir: str = ""


def read_progress(path: Path) -> list[tuple[str, str]]:
    """Lines ``<phase> <guest uptime> <detail>`` of guest.sh's progress file as (phase, detail)."""
    if not path.exists():
        return []
    out = []
    for line in path.read_text(errors="replace").splitlines():
        parts = line.split(" ", 2)
        if parts and parts[0]:
            out.append((parts[0], parts[2] if len(parts) > 2 else ""))
    return out


def junit_summary(path: Path) -> dict[str, int]:
    """tests/failures/errors/skipped/passed counted over every testsuite of a junit XML file."""
    root = ET.parse(path).getroot()
    suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))
    counts = {k: sum(int(s.get(k, 0)) for s in suites) for k in ("tests", "failures", "errors", "skipped")}
    counts["passed"] = counts["tests"] - counts["failures"] - counts["errors"] - counts["skipped"]
    return counts


def junit_cases(path: Path) -> dict[str, str]:
    """junit testcase ``file::name`` -> outcome (passed | failed | error | skipped)."""
    cases: dict[str, str] = {}
    for case in ET.parse(path).getroot().iter("testcase"):
        file = case.get("file") or case.get("classname", "").replace(".", "/") + ".py"
        outcome = "passed"
        for tag, name in (("failure", "failed"), ("error", "error"), ("skipped", "skipped")):
            if case.find(tag) is not None:
                outcome = name
        cases[f"{file}::{case.get('name')}"] = outcome
    return cases


def _kill_group(proc: subprocess.Popen[bytes]) -> None:
    """SIGTERM then SIGKILL the VM's whole process group (vng, virtme-run, qemu) until none of it is left.

    Waiting for the group leader (vng) alone is not enough: virtme-run outlived it by seconds when measured.
    """
    for sig, grace in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        end = time.monotonic() + grace
        while time.monotonic() < end:
            proc.poll()  # reap the leader, else its zombie keeps the group "alive"
            if not _group_alive(proc.pid):
                return
            time.sleep(0.05)
    proc.poll()


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _tail(path: Path, lines: int = 15) -> str:
    if not path.exists():
        return "(no console output)"
    text = path.read_text(errors="replace").replace("\r", "").splitlines()
    return "\n".join(text[-lines:]) or "(no console output)"


def run_vm(cfg: VmConfig, pre: Prereqs, outdir: Path, extra_pytest_args: list[str] | None = None) -> VmResult:
    """Boot once, run the tests in the guest, and classify the outcome; never blocks past ``cfg.timeout_s``."""
    outdir.mkdir(parents=True, exist_ok=True)
    (outdir / "job.env").write_text(
        f"REPO={shlex.quote(str(ROOT))}\nMODULE={cfg.module}\nIFACE={cfg.interface}\nTIME_SCALE={cfg.time_scale:g}\n")
    (outdir / "pytest_args").write_text("\n".join([*cfg.pytest_args, *(extra_pytest_args or [])]) + "\n")
    env = dict(os.environ, PATH=f"{VENV / 'bin'}:{os.environ.get('PATH', '/usr/bin:/bin')}")
    console = outdir / "console.log"
    progress_file = outdir / "progress"
    start = time.monotonic()
    phases: dict[str, float] = {}
    boot_failures: list[str] = []
    for attempt in range(1, cfg.boot_attempts + 1):
        # A retry only for a boot that never reached the guest script (qemu crash, boot hang), and only
        # while a whole boot still fits in the overall bound.
        if attempt > 1 and time.monotonic() - start + cfg.boot_timeout_s > cfg.timeout_s:
            break
        progress_file.unlink(missing_ok=True)
        phases = {}
        attempt_start = time.monotonic()
        with console.open("ab") as log:
            log.write(f"--- {TAG} boot attempt {attempt}\n".encode())
            log.flush()
            proc = subprocess.Popen(vng_command(cfg, pre, outdir), stdin=subprocess.DEVNULL, stdout=log,
                                    stderr=subprocess.STDOUT, env=env, cwd=ROOT, start_new_session=True)
            timed_out = ""
            try:
                while proc.poll() is None:
                    elapsed = time.monotonic() - start
                    for phase, _ in read_progress(progress_file):
                        phases.setdefault(phase, round(elapsed, 1))
                    if "guest-started" not in phases and time.monotonic() - attempt_start > cfg.boot_timeout_s:
                        timed_out = (f"VM boot timed out: the guest script had not started after "
                                     f"{cfg.boot_timeout_s:.0f} s (kernel {pre.kernel_version})")
                    elif elapsed > cfg.timeout_s:
                        last = max(phases, key=phases.__getitem__) if phases else "boot"
                        timed_out = f"VM timed out after {cfg.timeout_s:.0f} s (last phase reached: {last})"
                    if timed_out:
                        _kill_group(proc)
                        break
                    time.sleep(POLL_S)
            finally:
                if proc.poll() is None:
                    _kill_group(proc)
        for phase, _ in read_progress(progress_file):
            phases.setdefault(phase, round(time.monotonic() - start, 1))
        if "guest-started" in phases:
            break
        boot_failures.append(timed_out or f"qemu/vng exited {proc.returncode} before the guest script ran")
        print(f"{TAG} boot attempt {attempt} failed: {boot_failures[-1]}", flush=True)
    wall = round(time.monotonic() - start, 1)
    for phase, _ in read_progress(progress_file):
        phases.setdefault(phase, wall)
    result = VmResult(ok=False, reason="", exit_code=proc.returncode, wall_s=wall, kernel=pre.kernel_version,
                      phases_s=phases, outdir=str(outdir))
    progress = read_progress(progress_file)
    fails = [detail for phase, detail in progress if phase == "fail"]
    junit = outdir / "junit.xml"
    cases: dict[str, str] = {}
    if junit.exists():
        try:
            result.tests = junit_summary(junit)
            cases = junit_cases(junit)
        except ET.ParseError:
            result.tests = {}
    failed = {case for case, outcome in cases.items() if outcome in ("failed", "error")}
    stale = sorted(case for case in cfg.known_failures if cases.get(case) == "passed")
    result.boot_failures = boot_failures
    if timed_out:
        result.reason = f"{timed_out}; console tail:\n{_tail(console)}"
        if "tests-started" in phases:  # what the tests had got to (and why any failed) before the kill
            result.reason += f"\npytest.log tail:\n{_tail(outdir / 'pytest.log', 60)}"
    elif proc.returncode in GUEST_FAILURES and fails:
        result.guest_failure = fails[-1]
        result.reason = f"VM {GUEST_FAILURES[proc.returncode]} failed: {fails[-1]}"
    elif "guest-started" not in phases:
        result.reason = (f"VM failed before the guest script ran (vng exit {proc.returncode}; boot attempts: "
                         f"{boot_failures}); console tail:\n{_tail(console)}")
    elif proc.returncode != 0 and not (proc.returncode == 1 and failed and failed <= set(cfg.known_failures)):
        unknown = sorted(failed - set(cfg.known_failures))
        result.reason = (f"tests failed inside the VM (pytest exit {proc.returncode}); {_summary_line(outdir)}"
                         + (f"; failed: {unknown}" if unknown else ""))
    elif not result.tests or result.tests["tests"] == 0:
        result.reason = f"no test ran inside the VM; {_summary_line(outdir)}"
    elif result.tests["skipped"]:
        result.reason = (f"{result.tests['skipped']} test(s) were skipped inside the VM, where SocketCAN is there: "
                         f"{_skip_reasons(outdir)}")
    else:
        result.ok = True
        result.known_failed = {case: cfg.known_failures[case] for case in sorted(failed)}
        result.known_passed = stale
    return result


def _summary_line(outdir: Path) -> str:
    log = outdir / "pytest.log"
    lines = log.read_text(errors="replace").splitlines() if log.exists() else []
    for line in reversed(lines):
        if re.search(r"\d+ (passed|failed|error|skipped|deselected)|no tests ran", line):
            return line.strip("= ")
    return "(no pytest summary line; see pytest.log)"


def _skip_reasons(outdir: Path) -> str:
    log = outdir / "pytest.log"
    lines = log.read_text(errors="replace").splitlines() if log.exists() else []
    return "; ".join(line for line in lines if line.startswith("SKIPPED"))[:2000] or "(see pytest.log)"


def _exit_on_signal(signum: int, _frame: object) -> None:
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="VM settings (YAML)")
    parser.add_argument("--check", action="store_true", help="only check that the VM can be had (exit 0 or 77)")
    parser.add_argument("--timeout", type=float, help="override timeout_s (whole run, seconds)")
    parser.add_argument("--boot-timeout", type=float, help="override boot_timeout_s (seconds)")
    parser.add_argument("--module", help="override the kernel module loaded in the guest")
    parser.add_argument("--outdir", type=Path, help="where guest logs, progress and junit.xml go (default: a temp dir)")
    parser.add_argument("--json", type=Path, help="write the result as JSON here")
    parser.add_argument("--quiet", action="store_true", help="do not print the guest's pytest output")
    parser.add_argument("pytest_args", nargs="*", help="extra pytest arguments for the guest run (after --)")
    args = parser.parse_args(argv)
    try:
        cfg = load_config(args.config)
    except VmConfigError as exc:
        print(f"{TAG} ERROR: {exc}", file=sys.stderr)
        return 1
    overrides: dict[str, Any] = {}
    if args.timeout is not None:
        overrides["timeout_s"] = args.timeout
        overrides["boot_timeout_s"] = min(cfg.boot_timeout_s, args.timeout)
    if args.boot_timeout is not None:
        overrides["boot_timeout_s"] = args.boot_timeout
    if args.module:
        overrides["module"] = args.module
    cfg = VmConfig(**{**asdict(cfg), **overrides})
    if os.environ.get("TMS_VM", "1") == "0":
        print(f"{TAG} VM UNAVAILABLE: disabled by TMS_VM=0", file=sys.stderr)
        return EXIT_UNAVAILABLE
    try:
        pre = preflight(cfg)
    except VmUnavailableError as exc:
        print(f"{TAG} VM UNAVAILABLE: {exc}", file=sys.stderr)
        if args.json:
            args.json.write_text(json.dumps({"ok": False, "unavailable": str(exc)}))
        return EXIT_UNAVAILABLE
    if args.check:
        print(f"{TAG} VM available: kernel {pre.kernel}, {pre.qemu}, {pre.vng}")
        return 0
    # SIGTERM/SIGHUP (CI cancelling the job, a timeout killing this process) exit through run_vm's `finally`,
    # which kills the VM's process group: qemu runs in its own session and would otherwise outlive us.
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _exit_on_signal)
    outdir = args.outdir or Path(tempfile.mkdtemp(prefix="tms-vcan-vm-"))
    print(f"{TAG} booting {pre.kernel} (kvm={'on' if cfg.kvm else 'off'}, timeout {cfg.timeout_s:.0f} s); "
          f"logs in {outdir}", flush=True)
    result = run_vm(cfg, pre, outdir, args.pytest_args)
    log = outdir / "pytest.log"
    if not args.quiet and log.exists():
        print(log.read_text(errors="replace").rstrip())
    p = result.phases_s
    print(f"{TAG} wall time {result.wall_s:.1f} s: guest script started at {p.get('guest-started', '-')} s, "
          f"{cfg.interface} up at {p.get('interface-up', '-')} s, tests {p.get('tests-started', '-')}"
          f"..{p.get('tests-done', '-')} s", flush=True)
    if args.json:
        args.json.write_text(json.dumps(asdict(result), indent=2))
    for case, why in result.known_failed.items():
        print(f"{TAG} KNOWN FAILURE under emulation (listed in {args.config.name}): {case}: {why}", flush=True)
    for case in result.known_passed:
        print(f"{TAG} listed as a known failure but PASSED this time (drop it from known_failures once it "
              f"passes reliably): {case}", flush=True)
    if result.ok:
        t = result.tests
        print(f"{TAG} PASSED inside the VM on socketcan ({cfg.interface}, kernel {pre.kernel_version}): "
              f"{t['passed']} passed, {t['failures'] + t['errors']} failed ({len(result.known_failed)} known), "
              f"{t['skipped']} skipped in {result.wall_s:.1f} s wall", flush=True)
        return 0
    print(f"{TAG} FAILED: {result.reason}", file=sys.stderr, flush=True)
    return 1


if __name__ == "__main__":
    sys.exit(main())
