"""Subtask outcome codes and where they travel (the codes are defined once, in tms_msg/msg/SubtaskOutcome.msg).

The leaf -> subtask action is the original's ``tms_msg_ts/action/LeafNodeBase`` (result: ``bool result``,
feedback: ``string status``). Our typed outcome goes beside it: the subtask server publishes a
``tms_msg/SubtaskOutcome`` (goal id, ``error_code``, ``error_msg``) on ``/<model_name>/subtask_outcome``
just before each goal ends, and, for a client that reads only the original's type, the last feedback
``status`` of a failed goal is ``<CODE>: <error_msg>``.

Logic compares codes (``SubtaskOutcome.SERVER_LOST``); :func:`code_name` only labels them in messages and logs.
Imports message types only (no rclpy).
"""

from __future__ import annotations

from tms_msg.msg import SubtaskOutcome

__all__ = ["CODE_NAMES", "SERVER_LOST", "SUBTASK_OUTCOME_TOPIC", "OUTCOME_GRACE_S", "code_name"]

SERVER_LOST: int = SubtaskOutcome.SERVER_LOST
#: relative to /<model_name>: tms_msg/msg/SubtaskOutcome of every subtask goal of that machine
SUBTASK_OUTCOME_TOPIC = "subtask_outcome"
#: [s wall] a client with a failed result waits at most this long for the goal's outcome message
#: (topic and result service are separate DDS channels: either may arrive first)
OUTCOME_GRACE_S = 1.0

#: error_code -> constant name, read from the generated SubtaskOutcome class (its uppercase int attributes)
CODE_NAMES: dict[int, str] = {
    value: name for name in dir(SubtaskOutcome)
    if name.isupper() and isinstance(value := getattr(SubtaskOutcome, name), int)
}


def code_name(code: int) -> str:
    """``SERVER_LOST`` for 9005; ``code 1234`` for a code this build does not know."""
    return CODE_NAMES.get(code, f"code {code}")
