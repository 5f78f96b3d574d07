"""The VM runner's pure parts, without booting anything: settings validation, kernel choice, result parsing."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from tests.rosproc import ROOT

_spec = importlib.util.spec_from_file_location("run_vcan_vm", ROOT / "scripts" / "vm" / "run_vcan_vm.py")
assert _spec and _spec.loader
vm = importlib.util.module_from_spec(_spec)
sys.modules["run_vcan_vm"] = vm
_spec.loader.exec_module(vm)

GOOD = (ROOT / "config" / "vm" / "vcan.yaml").read_text()


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "vcan.yaml"
    path.write_text(text)
    return path


def test_shipped_config_loads_and_bounds_the_run_well_under_ci_limit():
    cfg = vm.load_config()
    assert cfg.module == "vcan" and cfg.interface == "vcan0"
    assert 0 < cfg.boot_timeout_s <= cfg.timeout_s <= 1800  # CI has 5,400 s for everything
    assert "can_backend" in " ".join(cfg.pytest_args)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace("module: vcan", "module: 'vcan; reboot'"), "module/interface must be plain names"),
        (lambda t: t.replace("cpus: 2", "cpus: two"), "cpus: expected"),
        (lambda t: t.replace("kvm: false", "kvm: 0"), "kvm: expected"),
        (lambda t: t.replace("boot_timeout_s: 240", "boot_timeout_s: 5000"), "need 0 < boot_timeout_s <= timeout_s"),
        (lambda t: t.replace("time_scale: 6", "time_scale: 0"), "time_scale must be > 0"),
        (lambda t: t.replace("cpus: 2", "cpus: 2\nram: 1G"), "unknown key(s) ['ram']"),
        (lambda t: t.replace("known_failures:", "known_failures:\n  test_x: no reason given\n  other:"),
         "known_failures: each key must be a test id"),
        (lambda t: "\n".join(line for line in t.splitlines() if not line.startswith("interface:")),
         "missing key 'interface'"),
    ],
)
def test_bad_settings_name_the_key(tmp_path, edit, message):
    path = write(tmp_path, edit(GOOD))
    with pytest.raises(vm.VmConfigError) as err:
        vm.load_config(path)
    assert message in str(err.value) and str(path) in str(err.value)


def test_kernel_choice_newest_image_with_modules(tmp_path):
    boot, mods = tmp_path / "boot", tmp_path / "modules"
    boot.mkdir()
    for ver in ("6.1.0-9-amd64", "6.1.0-56-amd64", "6.12.0-1-amd64"):
        (boot / f"vmlinuz-{ver}").write_bytes(b"k")
    for ver in ("6.1.0-9-amd64", "6.1.0-56-amd64"):  # 6.12 has an image but no modules tree
        (mods / ver).mkdir(parents=True)
    image, version = vm.find_kernel(boot, mods)
    assert (image.name, version) == ("vmlinuz-6.1.0-56-amd64", "6.1.0-56-amd64")


def test_no_kernel_image_is_unavailable_naming_the_package(tmp_path):
    (tmp_path / "boot").mkdir()
    with pytest.raises(vm.VmUnavailableError, match=r"no kernel image in .*apt-get install linux-image-amd64"):
        vm.find_kernel(tmp_path / "boot", tmp_path / "modules")
    (tmp_path / "boot" / "vmlinuz-6.18.44-custom").write_bytes(b"k")
    with pytest.raises(vm.VmUnavailableError, match=r"vmlinuz-6.18.44-custom have no .*modules/<ver>"):
        vm.find_kernel(tmp_path / "boot", tmp_path / "modules")


def test_preflight_names_every_missing_tool(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))  # no qemu, no busybox on PATH
    with pytest.raises(vm.VmUnavailableError) as err:
        vm.preflight(vm.load_config(), venv=tmp_path / "novenv")
    text = str(err.value)
    assert "qemu-system-x86_64 not found (install: apt-get install qemu-system-x86)" in text
    assert "busybox not found (install: apt-get install busybox-static)" in text
    assert "virtme-ng not installed" in text


def test_junit_cases_name_each_outcome(tmp_path):
    (tmp_path / "junit.xml").write_text(
        '<testsuites><testsuite tests="3" failures="1" errors="0" skipped="1">'
        '<testcase classname="tests.a" name="ok" file="tests/a.py"/>'
        '<testcase classname="tests.a" name="bad" file="tests/a.py"><failure message="x"/></testcase>'
        '<testcase classname="tests.b" name="skip"><skipped message="y"/></testcase>'
        '</testsuite></testsuites>')
    assert vm.junit_cases(tmp_path / "junit.xml") == {
        "tests/a.py::ok": "passed", "tests/a.py::bad": "failed", "tests/b.py::skip": "skipped"}


def test_junit_summary_and_progress_parsing(tmp_path):
    (tmp_path / "junit.xml").write_text(
        '<testsuites><testsuite tests="5" failures="1" errors="0" skipped="1">'
        '<testcase classname="a" name="x"/></testsuite></testsuites>')
    assert vm.junit_summary(tmp_path / "junit.xml") == {"tests": 5, "failures": 1, "errors": 0, "skipped": 1,
                                                        "passed": 3}
    (tmp_path / "progress").write_text("guest-started 31.2 \nfail 33.0 modprobe vcan failed: not found\n")
    assert vm.read_progress(tmp_path / "progress") == [
        ("guest-started", ""),
        ("fail", "modprobe vcan failed: not found"),
    ]


def test_vng_command_boots_without_kvm_and_shares_only_the_output_dir_read_write(tmp_path):
    cfg = vm.load_config()
    pre = vm.Prereqs(vng=Path("/v/vng"), qemu=Path("/q"), busybox=Path("/b"), kernel=Path("/boot/vmlinuz-x"),
                     kernel_version="x")
    cmd = vm.vng_command(cfg, pre, tmp_path)
    assert cmd[:2] == ["/v/vng", "--disable-kvm"]
    assert cmd[cmd.index("--rwdir") + 1] == str(tmp_path)
    assert cmd[cmd.index("--overlay-rwdir") + 1] == str(ROOT)  # repo writable in the guest only
    assert "--rw" not in cmd
    assert cmd[-1].endswith(f"guest.sh {tmp_path}")


def test_unavailable_vm_skips_naming_why_even_on_ci(monkeypatch):
    """A missing VM is the environment's doing: the VM test skips with the runner's reason, CI=true or not;
    only TMS_VM_REQUIRED=1 makes it a failure."""
    from tests.vcan import test_vm

    monkeypatch.setenv("TMS_VM", "0")
    monkeypatch.setenv("CI", "true")
    monkeypatch.delenv("TMS_VM_REQUIRED", raising=False)
    with pytest.raises(pytest.skip.Exception, match="VM UNAVAILABLE: disabled by TMS_VM=0"):
        test_vm._runner("--check", timeout=60)
    monkeypatch.setenv("TMS_VM_REQUIRED", "1")
    with pytest.raises(pytest.fail.Exception, match="required here .* disabled by TMS_VM=0"):
        test_vm._runner("--check", timeout=60)
