"""Errors of the task scheduler.

``TsError`` is the package base (a :class:`tms_common.errors.TmsError`). ``TreeLoadError`` is raised
before anything runs (malformed XML, unknown node id or port, bad literal, wrong child count); its
message names the node id and its position in the document. ``TreeRuntimeError`` is raised while
ticking (a ``{key}`` that is not on the blackboard, a value of the wrong type); the manager turns it
into the task's FAILURE message. ``SubtaskRecordError`` is raised by the subtask servers when a DB
record is missing or malformed; it names the record and the field. ``SubtaskStateError``: the machine state a
subtask needs besides its record (its ``joint_states``) is not there.
"""

from __future__ import annotations

from tms_common.errors import TmsError

__all__ = ["TsError", "TreeLoadError", "TreeRuntimeError", "SubtaskRecordError", "SubtaskStateError", "ExpressionError",
           "TaskSequenceError"]


class TsError(TmsError):
    """Base of every error raised on purpose by tms_ts."""


class TreeLoadError(TsError, ValueError):
    """A task tree cannot be built; the message names the node id, its line and column."""


class TreeRuntimeError(TsError, RuntimeError):
    """A node cannot run (missing blackboard key, value of the wrong type); names node and key."""


class ExpressionError(TsError, ValueError):
    """A ConditionalExpression cannot be parsed or evaluated; names the expression and position."""


class SubtaskRecordError(TsError, ValueError):
    """A subtask's DB record is missing or malformed; the message names the record and the field."""

    def __init__(self, record_name: str, field: str | None, problem: str) -> None:
        self.record_name = record_name
        self.field = field
        where = f"record '{record_name}'" + (f" field '{field}'" if field else "")
        super().__init__(f"{where}: {problem}")


class SubtaskStateError(TsError, RuntimeError):
    """The machine state a subtask needs (a joint on ``joint_states``) is missing; the message says which."""


class TaskSequenceError(TsError, ValueError):
    """A ``/task_sequence`` message cannot start a task (not XML, malformed JSON, task id absent); names it."""
