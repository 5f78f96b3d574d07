"""pytest plugin loaded only inside the SocketCAN VM (``-p tests.vcan.vm_plugin`` in config/vm/vcan.yaml).

Under qemu software emulation a Python process that imports rclpy takes tens of seconds to start (measured:
50-90 s on the shared 2-core machine), so the host-tuned waits of tests.rosproc.Proc (e.g. "node ready within
30 s") would fail for slowness, not for a fault. This stretches exactly those waits by TMS_TEST_TIME_SCALE
(set by scripts/vm/guest.sh from config/vm/vcan.yaml ``time_scale``); assertions are unchanged (the com3_can
tests widen their own timing tolerances by the same variable).

It also prints each failure's traceback the moment the test fails, not only in pytest's end-of-session
summary: when the VM is killed at ``timeout_s`` the summary never comes, and the runner's reason quotes the
tail of pytest.log, so the log still says why an earlier test failed.
"""

from __future__ import annotations

import os

import pytest


def pytest_configure(config: pytest.Config) -> None:
    scale = float(os.environ.get("TMS_TEST_TIME_SCALE", "1"))
    if scale <= 0:
        raise pytest.UsageError(f"TMS_TEST_TIME_SCALE must be > 0, got {scale}")
    if scale == 1:
        return
    from tests import rosproc

    wait_for, wait = rosproc.Proc.wait_for, rosproc.Proc.wait

    def scaled_wait_for(self: rosproc.Proc, text: str, timeout: float) -> bool:
        return wait_for(self, text, timeout * scale)

    def scaled_wait(self: rosproc.Proc, timeout: float) -> int | None:
        return wait(self, timeout * scale)

    rosproc.Proc.wait_for = scaled_wait_for  # type: ignore[method-assign]
    rosproc.Proc.wait = scaled_wait  # type: ignore[method-assign]
    config.issue_config_time_warning(
        pytest.PytestConfigWarning(f"process waits scaled x{scale:g} for the VM (TMS_TEST_TIME_SCALE)"), stacklevel=2)


@pytest.hookimpl(trylast=True)
def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Write a failed test's traceback to the log at once (see the module docstring)."""
    if report.failed and _terminal:
        _terminal[0].write_line(f"\n[vm-plugin] FAILED {report.nodeid} ({report.when}, {report.duration:.1f} s):\n"
                                f"{report.longreprtext[-4000:]}\n[vm-plugin] end of failure report", flush=True)


@pytest.hookimpl(trylast=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        _terminal.append(reporter)


_terminal: list = []
