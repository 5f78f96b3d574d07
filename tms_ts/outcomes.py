"""Names of the subtask outcome codes, for people (the codes are defined once, in tms_msg/action/Subtask.action).

Logic compares codes (``Subtask.Result.SERVER_LOST``); :func:`code_name` only labels them in messages and logs.
Imports message types only (no rclpy).
"""

from __future__ import annotations

from tms_msg.action import Subtask

__all__ = ["CODE_NAMES", "SERVER_LOST", "code_name"]

SERVER_LOST: int = Subtask.Result.SERVER_LOST

#: error_code -> constant name, read from the generated Subtask.Result class (its uppercase int attributes)
CODE_NAMES: dict[int, str] = {
    value: name for name in dir(Subtask.Result)
    if name.isupper() and isinstance(value := getattr(Subtask.Result, name), int)
}


def code_name(code: int) -> str:
    """``SERVER_LOST`` for 9005; ``code 1234`` for a code this build does not know."""
    return CODE_NAMES.get(code, f"code {code}")
