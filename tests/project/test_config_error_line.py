"""A node given a bad config file or parameter prints one line naming the culprit and exits 2, no traceback."""

from __future__ import annotations

import pytest

from tests.rosproc import executable


def _run(procs, args: list[str]) -> tuple[int | None, list[str]]:
    proc = procs([executable("tms_rc", "ic120_vessel"), "--ros-args", "-p", "machine:=ic120", *args])
    code = proc.wait(60)
    lines = [line for line in proc.output.splitlines() if line.strip()]
    return code, lines


def test_malformed_config_file_names_file_and_line(procs, tmp_path):
    bad = tmp_path / "ic120_bad.yaml"
    bad.write_text("vessel:\n  max_angle: 1.0\n  rate: [1, 2\nother: 3\n")
    code, lines = _run(procs, ["-p", f"machine_config:={bad}"])
    assert code == 2, lines
    assert len(lines) == 1 and "Traceback" not in lines[0], lines
    assert lines[0].startswith("[ic120_vessel] ConfigError: ") and f"{bad}:4" in lines[0], lines


def test_parameter_of_the_wrong_type_is_one_line(procs):
    code, lines = _run(procs, ["-p", "rate_hz:=fast"])
    assert code == 2, lines
    assert len(lines) == 1 and "rate_hz" in lines[0] and "Traceback" not in lines[0], lines


@pytest.mark.parametrize("missing", ["/nonexistent/ic120.yaml"])
def test_missing_config_file_is_named(procs, missing):
    code, lines = _run(procs, ["-p", f"nav_config:={missing}"])
    assert code == 2 and len(lines) == 1 and f"{missing}: cannot read" in lines[0], lines
