"""What a ``/task_sequence`` message starts (the original's start path), without ROS."""

from __future__ import annotations

import json

import pytest

from tms_ts.errors import TaskSequenceError
from tms_ts.task_sequence import SequenceTask, parse_task_sequence, stored_task_id

TREE_A = '<root main_tree_to_execute="A"><BehaviorTree ID="A"><AlwaysSuccess/></BehaviorTree></root>'
TREE_B = '<root main_tree_to_execute="B"><BehaviorTree ID="B"><AlwaysFailure/></BehaviorTree></root>'


def gui_json(*tasks: tuple[int, str]) -> str:
    """The message the original's GUI button publishes for several task ids (``json.dumps``, ensure_ascii off)."""
    return json.dumps({"tasks": [{"task_id": i, "task_sequence": x} for i, x in tasks]}, ensure_ascii=False)


def test_xml_runs_under_the_parameter_or_is_looked_up() -> None:
    assert parse_task_sequence(TREE_A) == [SequenceTask(None, TREE_A)]
    assert parse_task_sequence("\n  " + TREE_A + "\n", task_id=7) == [SequenceTask(7, TREE_A)]


def test_gui_json_runs_every_entry_or_the_one_named_by_task_id() -> None:
    msg = gui_json((1, TREE_A), (2, TREE_B))
    assert parse_task_sequence(msg) == [SequenceTask(1, TREE_A), SequenceTask(2, TREE_B)]
    assert parse_task_sequence(msg, task_id=2) == [SequenceTask(2, TREE_B)]


@pytest.mark.parametrize(
    ("data", "task_id", "match"),
    [
        ("", -1, "empty message"),
        ("run task 3", -1, "neither XML nor JSON"),
        ('{"tasks": [', -1, "malformed JSON at line 1"),
        ('{"task": []}', -1, "without a 'tasks' array"),
        ('{"tasks": []}', -1, "'tasks' array is empty"),
        ('{"tasks": [{"task_id": "1", "task_sequence": "<root/>"}]}', -1, r"tasks\[0\] must be"),
        ('{"tasks": [{"task_id": true, "task_sequence": "<root/>"}]}', -1, r"tasks\[0\] must be"),
        (gui_json((1, TREE_A)), 5, r"task_id 5 \(parameter task_id\) is not in the JSON's tasks \[1\]"),
    ],
)
def test_what_cannot_start_is_named(data: str, task_id: int, match: str) -> None:
    with pytest.raises(TaskSequenceError, match=match):
        parse_task_sequence(data, task_id)


def test_stored_task_id_compares_the_one_line_form() -> None:
    stored = [{"task_id": 4, "task_sequence": TREE_B}, {"task_id": 9, "task_sequence": TREE_A},
              {"task_id": 10, "task_sequence": "<root><broken"}]
    multi_line = TREE_A.replace("><", ">\n    <")
    assert stored_task_id(multi_line, stored) == 9
    assert stored_task_id('<root main_tree_to_execute="C"><BehaviorTree ID="C"/></root>', stored) is None
    with pytest.raises(TaskSequenceError, match="XML does not parse"):
        stored_task_id("<root><BehaviorTree>", stored)
