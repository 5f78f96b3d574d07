"""The original's start path: what a ``/task_sequence`` message asks the manager to run (no rclpy).

The original (irvs/ros2_tms_for_construction, ``tms_ts_manager``, node ``exec_task_sequence``) takes a
``std_msgs/String`` on ``/task_sequence`` and a parameter ``task_id`` (default -1):

* ``task_id`` -1: the message is a BehaviorTree XML, run as it is;
* ``task_id`` N: the message is the JSON its GUI button (``tms_ur_button``, parameter ``task_ids``)
  sends, ``{"tasks": [{"task_id": .., "task_sequence": ..}, ...]}``, and the manager runs the entry
  whose ``task_id`` is N (one manager process per task there).

Ours runs many tasks in one manager, so it reads both forms whatever ``task_id`` is: an XML runs
under ``task_id`` (or, at -1, the id of the stored task with the same tree); a JSON runs its entry N,
or at -1 every entry. What cannot start raises :class:`TaskSequenceError` naming the culprit.

Limits (:mod:`tms_ts.limits`), checked before anything is parsed: the message at most ``MAX_TREE_BYTES``, a JSON
nested at most ``MAX_JSON_DEPTH`` (checked without recursion; ``json.loads`` recurses once a level), every task id
(a JSON entry's, or the ``task_id`` parameter's other than -1) in 1..2**31-1 (the interface types' int32), no lone
surrogate (a JSON ``"\\udc00"`` is no character an XML can hold). Each tree is then loaded under the limits of the
loader (size, depth, nodes).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from tms_db import ValidationError, normalise_task_xml
from tms_ts.errors import TaskSequenceError, TreeLoadError
from tms_ts.limits import MAX_JSON_DEPTH, check_tree_size, json_depth_exceeds, task_id_problem

__all__ = ["TASK_SEQUENCE_TOPIC", "NO_TASK_ID", "SequenceTask", "parse_task_sequence", "stored_task_id"]

TASK_SEQUENCE_TOPIC = "/task_sequence"
#: The original's ``task_id`` default: no id given.
NO_TASK_ID = -1


@dataclass(frozen=True)
class SequenceTask:
    """One tree to start: its task id (``None``: an XML whose id is still to be found) and its XML."""

    task_id: int | None
    xml: str


def _is_id(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def parse_task_sequence(data: str, task_id: int = NO_TASK_ID) -> list[SequenceTask]:
    """The trees a ``/task_sequence`` message starts, given the manager's ``task_id`` parameter."""
    try:
        check_tree_size(data, "/task_sequence: the message")
    except TreeLoadError as exc:
        raise TaskSequenceError(str(exc)) from None
    if task_id != NO_TASK_ID and task_id_problem(task_id):
        raise TaskSequenceError(f"/task_sequence: parameter task_id: {task_id_problem(task_id)} (or -1: none)")
    text = data.strip()
    if not text:
        raise TaskSequenceError(
            '/task_sequence: empty message (expected a BehaviorTree XML or the JSON {"tasks": [...]})'
        )
    if not text.startswith("{"):
        if not text.startswith("<"):
            raise TaskSequenceError(f"/task_sequence: neither XML nor JSON: {text[:60]!r}")
        return [SequenceTask(None if task_id == NO_TASK_ID else task_id, _checked_text(text, "the message"))]
    if json_depth_exceeds(text):
        raise TaskSequenceError(f"/task_sequence: the JSON nests deeper than the limit of {MAX_JSON_DEPTH} levels "
                                "(tms_ts.limits.MAX_JSON_DEPTH; the form {\"tasks\": [{...}]} needs 3)")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TaskSequenceError(
            f"/task_sequence: malformed JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from None
    except RecursionError:  # pragma: no cover - json_depth_exceeds refuses these first
        raise TaskSequenceError("/task_sequence: the JSON nests too deep (tms_ts.limits.MAX_JSON_DEPTH)") from None
    tasks = doc.get("tasks") if isinstance(doc, dict) else None
    if not isinstance(tasks, list):
        raise TaskSequenceError(
            '/task_sequence: JSON without a \'tasks\' array (expected {"tasks": [{"task_id", "task_sequence"}]})'
        )
    entries = []
    for i, entry in enumerate(tasks):
        if (
            not isinstance(entry, dict)
            or not _is_id(entry.get("task_id"))
            or not isinstance(entry.get("task_sequence"), str)
        ):
            raise TaskSequenceError(
                f'/task_sequence: tasks[{i}] must be {{"task_id": <int>, "task_sequence": <XML string>}}, got '
                f'{entry!r:.120}'
            )
        problem = task_id_problem(entry["task_id"])
        if problem:
            raise TaskSequenceError(f"/task_sequence: tasks[{i}]: {problem}")
        entries.append(
            SequenceTask(entry["task_id"], _checked_text(entry["task_sequence"], f"tasks[{i}].task_sequence"))
        )
    if task_id == NO_TASK_ID:
        if not entries:
            raise TaskSequenceError("/task_sequence: the JSON's 'tasks' array is empty")
        return entries
    chosen = [e for e in entries if e.task_id == task_id]
    if not chosen:
        raise TaskSequenceError(
            f"/task_sequence: task_id {task_id} (parameter task_id) is not in the JSON's tasks "
            f"{[e.task_id for e in entries]}"
        )
    return chosen[:1]


def _checked_text(text: str, what: str) -> str:
    """``text`` when it is all Unicode characters (a JSON string may hold a lone surrogate, which no XML parser or
    ROS message takes), else TaskSequenceError naming where."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise TaskSequenceError(f"/task_sequence: {what}: character {exc.start + 1} ({text[exc.start]!r}) is a lone "
                                "surrogate, no Unicode character") from None
    return text


def stored_task_id(xml: str, tasks: Iterable[Mapping[str, Any]]) -> int | None:
    """The id of the stored task whose tree is ``xml`` (compared in the store's one-line form), else None."""
    try:
        wanted = normalise_task_xml(xml)
    except ValidationError as exc:
        raise TaskSequenceError(f"/task_sequence: {exc}") from None
    for doc in tasks:
        sequence = doc.get("task_sequence")
        if not _is_id(doc.get("task_id")) or not isinstance(sequence, str):
            continue
        try:
            if normalise_task_xml(sequence) == wanted:
                return doc["task_id"]
        except ValidationError:  # a stored tree that does not parse is nobody's match
            continue
    return None
