"""Task parameters: a task's initial blackboard entries (its document's ``blackboard``), resolved at load for the
ports a leaf reads once (model_name, subtask_name); errors name the task, the key and the line."""

from __future__ import annotations

import pytest

from tms_ts.bt.core import TreeContext
from tms_ts.errors import TreeLoadError
from tms_ts.loader import check_task_blackboard, load_tree

TREE = """<root main_tree_to_execute="T">
  <BehaviorTree ID="T">
    <Sequence>
      <Action ID="LeafNodeIc120" name="enter" model_name="{machine}" record_name="ENTER_PATH"
              subtask_name="st_ic120_follow_waypoints"/>
      <Action ID="MongoValueWriter" name="holder" input_value="{machine}" mongo_record_name="BB" \
mongo_param_name="WHO"/>
    </Sequence>
  </BehaviorTree>
</root>"""


def test_one_tree_serves_every_machine_of_a_kind():
    for name in ("ic120_1", "ic120_2"):
        tree = load_tree(TREE, TreeContext(), source="task 12", blackboard={"machine": name})
        (leaf,) = tree.leaves
        assert leaf.model_name == name and leaf.action == f"/{name}/st_ic120_follow_waypoints"
        assert tree.ctx.blackboard.get("machine") == name  # other nodes read it at every tick


def test_the_parameter_is_fixed_for_the_run_as_the_original_reads_model_name_once():
    tree = load_tree(TREE, TreeContext(), source="task 12", blackboard={"machine": "ic120_1"})
    tree.ctx.blackboard.set("machine", "ic120_2")
    assert tree.leaves[0].model_name == "ic120_1"


def test_a_missing_parameter_names_task_key_node_and_line():
    with pytest.raises(TreeLoadError) as info:
        load_tree(TREE, TreeContext(), source="task 12")
    msg = str(info.value)
    assert msg.startswith("task 12: ") and "'machine'" in msg and "LeafNodeIc120 'enter'" in msg
    assert "line 4" in msg and "port 'model_name'" in msg and "field 'blackboard'" in msg


def test_parameter_values_are_checked_naming_task_and_key():
    with pytest.raises(TreeLoadError, match=r"task 3: field 'blackboard': key 'machine' = \[1\] must be"):
        check_task_blackboard({"machine": [1]}, "task 3")
    with pytest.raises(TreeLoadError, match="task 3: field 'blackboard' must be a mapping"):
        check_task_blackboard(["machine"], "task 3")
    with pytest.raises(TreeLoadError, match="task 3: .*key '{x}'"):
        check_task_blackboard({"{x}": 1}, "task 3")
    with pytest.raises(TreeLoadError, match=r"task 4: .*'machine' = True: expected a name"):
        load_tree(TREE, TreeContext(), source="task 4", blackboard={"machine": True})


def test_a_literal_model_name_still_works_and_subtask_name_may_be_a_parameter():
    xml = TREE.replace('model_name="{machine}"', 'model_name="ic120"').replace(
        'subtask_name="st_ic120_follow_waypoints"', 'subtask_name="{travel}"')
    tree = load_tree(xml, TreeContext(), blackboard={"travel": "st_ic120_follow_waypoints_deg", "machine": "x"})
    assert tree.leaves[0].action == "/ic120/st_ic120_follow_waypoints_deg"


def test_the_store_keeps_the_task_parameters_and_refuses_bad_ones(tmp_path):
    from tms_db import open_store
    from tms_db.errors import ValidationError

    store = open_store(path=tmp_path / "db")
    tid = store.add_task(TREE, task_id=12, blackboard={"machine": "ic120_1"}, model_name="ic120_1")
    doc = store.get_task(tid)
    assert doc["blackboard"] == {"machine": "ic120_1"} and doc["model_name"] == "ic120_1"
    with pytest.raises(ValidationError, match="task_id 13: field 'blackboard': key 'a.b'"):
        store.add_task(TREE, task_id=13, blackboard={"a.b": 1})
    with pytest.raises(ValidationError, match="task_id 13: field 'blackboard': key 'm' = "):
        store.add_task(TREE, task_id=13, blackboard={"m": {"x": 1}})
