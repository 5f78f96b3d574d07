"""Boot the SocketCAN VM (scripts/vm/run_vcan_vm.py) and require the CAN-layer tests to pass inside it.

The main test boots once and runs, on ``socketcan``/vcan0, the com3_can backend-contract tests (the same test
code the host runs on udp_multicast, marker ``can_backend``) and tests/vcan/test_socketcan.py (raw AF_CAN
checks). Two more runs prove the VM's own failures end the run with their reason instead of hanging: a boot
that does not finish in time, and a kernel module that is not there.

Where the VM cannot be had (no qemu, no kernel image, no virtme-ng, ``TMS_VM=0``) these tests skip naming
what is missing: that is the environment, not the code, so it must not fail ``make test``. Only an explicit
``TMS_VM_REQUIRED=1`` (a CI job that has provisioned the VM tools and wants to be told if they vanish) turns
a missing VM into a failure. ``CI=true`` alone does not: CI machines differ in what they may install.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.rosproc import ROOT

pytestmark = [pytest.mark.integration, pytest.mark.slow]

RUNNER = ROOT / "scripts" / "vm" / "run_vcan_vm.py"
EXIT_UNAVAILABLE = 77


def _vm_timeout_s() -> float:
    import yaml

    return float(yaml.safe_load((ROOT / "config" / "vm" / "vcan.yaml").read_text())["timeout_s"])


#: above the runner's own bound (config/vm/vcan.yaml timeout_s) plus its kill grace, so the runner's reason wins
PYTEST_TIMEOUT_S = int(_vm_timeout_s()) + 120


def _vm_required() -> bool:
    """True only when the caller asked for the VM explicitly (``TMS_VM_REQUIRED=1``)."""
    return os.environ.get("TMS_VM_REQUIRED") == "1"


def _runner(*args: str | Path, timeout: float) -> subprocess.CompletedProcess[str]:
    """Run the VM runner as a separate process; skip (or fail where the VM is required) when unavailable."""
    proc = subprocess.run([sys.executable, str(RUNNER), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, stdin=subprocess.DEVNULL)
    if proc.returncode == EXIT_UNAVAILABLE:
        reason = proc.stderr.strip() or proc.stdout.strip()
        if _vm_required():
            pytest.fail(f"the SocketCAN VM is required here (TMS_VM_REQUIRED=1) but: {reason}")
        pytest.skip(reason)
    return proc


def _vm_module():  # the runner script loaded as a module
    import importlib.util

    spec = importlib.util.spec_from_file_location("run_vcan_vm", RUNNER)
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("run_vcan_vm", module)
    spec.loader.exec_module(module)
    return module


def _host_can_backend_tests() -> set[str]:
    """Node ids of the com3_can backend-contract tests as collected on the host (the set the VM must run)."""
    out = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-m", "can_backend",
                          "-p", "no:cacheprovider", "tests/com3_can"], capture_output=True, text=True, cwd=ROOT,
                         timeout=300)
    return {line.strip() for line in out.stdout.splitlines() if line.startswith("tests/com3_can/") and "::" in line}


def _no_vm_left(outdir: Path) -> list[str]:
    """Command lines of processes still running the VM of ``outdir`` (empty when all are gone)."""
    left = []
    for proc_dir in Path("/proc").glob("[0-9]*"):
        try:
            cmdline = (proc_dir / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        # (outdir lies under pytest's tmp_path, so "pytest" in a command line says nothing; skip only ourselves)
        if str(outdir) in cmdline and proc_dir.name != str(os.getpid()):
            left.append(cmdline[:200])
    return left


@pytest.mark.timeout(PYTEST_TIMEOUT_S)
def test_can_layer_tests_pass_inside_the_vm_on_socketcan(tmp_path, capsys):
    """One boot: every can_backend test and the raw AF_CAN checks run on vcan0 and pass, none skipped."""
    host_tests = _host_can_backend_tests()
    outdir = tmp_path / "vm"
    started = time.monotonic()
    proc = _runner("--outdir", outdir, "--json", tmp_path / "result.json", timeout=_vm_timeout_s() + 60)
    wall = time.monotonic() - started
    summary = [line for line in proc.stdout.splitlines() if line.startswith("[vcan-vm]")
               or re.search(r"=+ .*\d+ (passed|failed)", line)]
    with capsys.disabled():  # CI's log shows that the tests ran in the VM, and how long it took
        print("\n" + "\n".join(summary) + f"\n[vcan-vm] host-side wall time of the VM run: {wall:.1f} s")
    assert proc.returncode == 0, f"VM run failed:\n{proc.stderr}\n{proc.stdout[-6000:]}"
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["ok"] and result["tests"]["passed"] > 0 and result["tests"]["skipped"] == 0, result
    cases = _vm_module().junit_cases(outdir / "junit.xml")
    assert cases.get("tests/vcan/test_socketcan.py::test_converter_node_frames_on_vcan0_read_by_raw_socket") == "passed"
    assert cases.get("tests/vcan/test_socketcan.py::test_codec_frame_sent_through_open_bus_is_on_the_wire_bit_exact") \
        == "passed"
    # the same com3_can backend tests as on the host ran on socketcan; each passed or is a listed known failure
    vm_com3 = {case for case in cases if case.startswith("tests/com3_can/")}
    assert vm_com3 and vm_com3 == {re.sub(r"\[.*\]$", "", t) for t in host_tests}, (
        f"in the VM: {sorted(vm_com3)}\non the host: {sorted(host_tests)}")
    known = _vm_module().load_config().known_failures
    assert all(cases[c] == "passed" or (cases[c] == "failed" and c in known) for c in vm_com3), cases


@pytest.mark.timeout(120)
def test_vm_boot_timeout_fails_with_that_reason_and_kills_the_vm(tmp_path):
    """A boot that cannot finish within the bound fails fast, names the boot, and leaves no qemu behind."""
    outdir = tmp_path / "vm"
    started = time.monotonic()
    proc = _runner("--outdir", outdir, "--timeout", "4", "--quiet", timeout=90)
    took = time.monotonic() - started
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "VM boot timed out: the guest script had not started after 4 s" in proc.stderr
    assert took < 60, f"the runner took {took:.0f} s to give up on a 4 s bound"
    assert _no_vm_left(outdir) == []


@pytest.mark.timeout(120)
def test_vm_runner_terminated_mid_boot_takes_the_vm_with_it(tmp_path):
    """CI cancelling the job (SIGTERM to the runner) ends the runner at once and leaves no qemu behind."""
    _runner("--check", timeout=60)  # skips (naming what is missing) where there is no VM
    outdir = tmp_path / "vm"
    proc = subprocess.Popen([sys.executable, str(RUNNER), "--outdir", str(outdir), "--quiet"], cwd=ROOT,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not any("qemu-system" in c for c in _no_vm_left(outdir)) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert any("qemu-system" in c for c in _no_vm_left(outdir)), "qemu never started"
        proc.terminate()
        assert proc.wait(30) == 128 + 15
        assert _no_vm_left(outdir) == []
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.timeout(PYTEST_TIMEOUT_S)
def test_vm_missing_kernel_module_fails_with_modprobe_reason(tmp_path):
    """The guest cannot load the module: the run fails quoting modprobe, and runs no test."""
    outdir = tmp_path / "vm"
    proc = _runner("--outdir", outdir, "--module", "tms_no_such_can_module", "--quiet", timeout=_vm_timeout_s() + 60)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "VM kernel module load failed: modprobe tms_no_such_can_module failed" in proc.stderr
    assert "not found" in proc.stderr
    assert not (outdir / "junit.xml").exists()
    assert _no_vm_left(outdir) == []
