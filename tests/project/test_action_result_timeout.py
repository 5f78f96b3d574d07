"""Every action server of the platform keeps finished goals ACTION_RESULT_TIMEOUT_S, not rclpy's 900 s.

A status message carries every goal the server still keeps, and every client converts it to Python; with
rclpy's default the arrays grew by thousands of entries over a run (tms_common.node.ACTION_RESULT_TIMEOUT_S).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("tms_ts", "tms_rc", "tms_rp", "tms_if_opera", "tms_sp", "tms_ur", "tms_launch", "com3_can", "sim_bridge",
            "tms_db", "tms_common")


def _action_server_calls() -> list[tuple[Path, ast.Call]]:
    calls = []
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if (
                    isinstance(node, ast.Call)
                    and getattr(node.func, "id", getattr(node.func, "attr", "")) == "ActionServer"
                ):
                    calls.append((path, node))
    return calls


def test_every_action_server_passes_the_platform_result_timeout() -> None:
    calls = _action_server_calls()
    assert len(calls) >= 6, [str(p) for p, _ in calls]  # subtasks, planner, arm controller, navigator, vessel, demo
    wrong = [
        f"{p.relative_to(ROOT)}:{c.lineno}"
        for p, c in calls
        if not any(
            k.arg == "result_timeout" and isinstance(k.value, ast.Name) and k.value.id == "ACTION_RESULT_TIMEOUT_S"
            for k in c.keywords
        )
    ]
    assert not wrong, f"ActionServer without result_timeout=ACTION_RESULT_TIMEOUT_S: {wrong}"
