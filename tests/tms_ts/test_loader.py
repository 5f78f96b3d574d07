"""Loader: both XML formats, typed ports, and errors that name the node id and its position."""

from __future__ import annotations

import pytest

from tms_ts.bt.core import SUCCESS
from tms_ts.errors import TreeLoadError
from tms_ts.loader import load_tree

GROOT1 = """<?xml version="1.0"?>
<root main_tree_to_execute="BehaviorTree">
  <BehaviorTree ID="BehaviorTree">
    <Sequence>
      <Action ID="SetLocalBlackboard" value="true" output_key="FLG"/>
      <Condition ID="ConditionalExpression" conditional_expression="FLG == true"/>
      <Decorator ID="RetryUntilSuccessful" num_attempts="2">
        <Action ID="AlwaysSuccess"/>
      </Decorator>
    </Sequence>
  </BehaviorTree>
  <TreeNodesModel>
    <Action ID="SetLocalBlackboard"><input_port name="value"/></Action>
  </TreeNodesModel>
</root>"""


def test_groot1_document_loads_and_runs_ignoring_the_palette():
    t = load_tree(GROOT1)
    assert t.tick() is SUCCESS
    assert t.ctx.blackboard.get("FLG") is True


def _err(xml: str) -> str:
    with pytest.raises(TreeLoadError) as info:
        load_tree(xml, source="task.xml")
    return str(info.value)


def test_unknown_node_id_names_id_and_line():
    msg = _err(
        '<root>\n<BehaviorTree ID="B">\n<Sequence>\n    <Action ID="MoveArm"/>\n</Sequence></BehaviorTree></root>'
    )
    assert "MoveArm" in msg and "line 4, column 5" in msg and "unknown node ID" in msg


def test_unknown_port_names_port_node_and_line():
    msg = _err('<root><BehaviorTree ID="B">\n<Action ID="LeafNodeZx200" name="pose" model_name="zx200" '
               'subtask_name="s" record_name="r" recordname="x"/></BehaviorTree></root>')
    assert "LeafNodeZx200 'pose'" in msg and "'recordname'" in msg and "line 2" in msg


def test_malformed_xml_names_position():
    msg = _err('<root><BehaviorTree ID="B">\n<Sequence>\n</BehaviorTree></root>')
    assert "malformed XML at line 3" in msg


def test_bad_literal_type_and_missing_port_and_child_count():
    assert "port 'num_cycles': expected an integer, got 'many'" in _err(
        '<root><BehaviorTree ID="B"><Repeat num_cycles="many"><AlwaysSuccess/></Repeat></BehaviorTree></root>')
    assert "missing required port 'num_cycles'" in _err(
        '<root><BehaviorTree ID="B"><Repeat><AlwaysSuccess/></Repeat></BehaviorTree></root>')
    assert "needs 3 children, has 2" in _err(
        '<root><BehaviorTree ID="B"><WhileDoElse><AlwaysSuccess/><AlwaysSuccess/></WhileDoElse></BehaviorTree></root>')
    assert "needs 2..3 children, has 1" in _err(
        '<root><BehaviorTree ID="B"><IfThenElse><AlwaysSuccess/></IfThenElse></BehaviorTree></root>')


def test_leaf_model_and_subtask_are_literals_or_task_parameters():
    msg = _err('<root><BehaviorTree ID="B"><Action ID="LeafNodeIc120" model_name="{m}" subtask_name="s" '
               'record_name="r"/></BehaviorTree></root>')
    assert "LeafNodeIc120" in msg and "model_name" in msg and "'m'" in msg and "field 'blackboard'" in msg


def test_main_tree_and_subtree_errors():
    assert "names no BehaviorTree" in _err('<root main_tree_to_execute="X"><BehaviorTree ID="B"><AlwaysSuccess/>'
                                           '</BehaviorTree></root>')
    assert "no BehaviorTree with ID 'Missing'" in _err('<root><BehaviorTree ID="B"><SubTree ID="Missing"/>'
                                                       '</BehaviorTree></root>')
    assert "recursive subtree" in _err('<root main_tree_to_execute="A"><BehaviorTree ID="A"><SubTree ID="A"/>'
                                       '</BehaviorTree></root>')
    assert "expected <root>" in _err("<tree/>")


def test_legacy_set_local_blackboard_key_port_and_string_flag():
    t = load_tree('<root><BehaviorTree ID="B"><Sequence><Action ID="SetLocalBlackboard" key="false" output_key="F"/>'
                  '<Action ID="SetLocalBlackboard" value="-12" output_key="I"/>'
                  '<Action ID="SetLocalBlackboard" value=".5" output_key="D"/>'
                  '<Action ID="SetLocalBlackboard" value="LOAD" output_key="S"/>'
                  '<SetBlackboard value="-12" output_key="T"/>'
                  '<Action ID="SetLocalBlackboard" value="{T}" output_key="I2"/>'
                  '</Sequence></BehaviorTree></root>')
    assert t.tick() is SUCCESS
    # value is the original's InputPort<std::string>: {T} reads the text, which is then typed
    assert t.ctx.blackboard.snapshot() == {"F": False, "I": -12, "D": 0.5, "S": "LOAD", "T": "-12", "I2": -12}
    assert "needs port 'value'" in _err('<root><BehaviorTree ID="B"><Action ID="SetLocalBlackboard" output_key="F"/>'
                                        '</BehaviorTree></root>')
