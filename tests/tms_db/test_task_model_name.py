"""A task's model_name: the machines its leaves drive, not the machines its XML's node palette lists."""

from __future__ import annotations

from tms_db.schema import detect_model_names

# The shape of the original's demo_202412/new2_task_zx200_act_and_sim.xml: every leaf drives the ZX200, the Groot
# palette (<TreeNodesModel>) also lists LeafNodeIc120 and LeafNodeSampleZx120 with their default machines.
ZX200_WITH_PALETTE = """<?xml version="1.0"?>
<root main_tree_to_execute="BehaviorTree">
    <BehaviorTree ID="BehaviorTree">
        <Decorator ID="KeepRunningUntilFlgup" key="TERMINATE_FLG">
            <Sequence>
                <Action ID="LeafNodeZx200" model_name="zx200" name="leaf_node_zx200" record_name="initial_pose" \
subtask_name="subtask_zx200_change_pose"/>
                <Action ID="MongoValueWriter" input_value="true" mongo_param_name="INITIAL_POS_FLG" \
mongo_record_name="SAMPLE_BLACKBOARD_SHIMIZU"/>
                <Action ID="LeafNodeZx200" model_name="zx200" name="leaf_node_zx200" \
record_name="target_excavate_pose" subtask_name="subtask_zx200_excavate_simple"/>
                <SetBlackboard output_key="TERMINATE_FLG" value="true"/>
            </Sequence>
        </Decorator>
    </BehaviorTree>
    <TreeNodesModel>
        <Action ID="LeafNodeIc120">
            <input_port default="ic120" name=" model_name"/>
            <inout_port name="record_name"/>
            <inout_port name="subtask_name"/>
        </Action>
        <Action ID="LeafNodeSampleZx120">
            <input_port default="zx120" name=" model_name"/>
            <inout_port name="record_name"/>
            <inout_port name="subtask_name"/>
        </Action>
        <Action ID="LeafNodeZx200">
            <input_port name="model_name" type="float"/>
        </Action>
    </TreeNodesModel>
</root>
"""


def test_the_palette_names_no_machine_only_the_leaves_do(store):
    tid = store.add_task(ZX200_WITH_PALETTE, description="ZX200 of the 2024-12 demo")
    assert store.get_task(tid)["model_name"] == "zx200"  # the whole-text search gave "zx200,ic120,zx120"


def test_two_machines_in_leaf_order_each_once_across_subtrees():
    xml = ('<root main_tree_to_execute="Main"><BehaviorTree ID="Main"><Sequence>'
           '<Action ID="LeafNodeIc120" model_name="ic120" record_name="a" subtask_name="st_ic120_follow_waypoints"/>'
           '<SubTree ID="Dig"/>'
           '<Action ID="LeafNodeIc120" model_name="/ic120" record_name="b" subtask_name="st_ic120_release_soil"/>'
           '</Sequence></BehaviorTree><BehaviorTree ID="Dig">'
           '<LeafNodeZx200 model_name="zx200" record_name="p" subtask_name="subtask_zx200_change_pose"/>'
           '</BehaviorTree><TreeNodesModel><Action ID="LeafNodeMst110cr"><input_port default="mst110cr" '
           'name="model_name"/></Action></TreeNodesModel></root>')
    assert detect_model_names(xml) == "ic120,zx200"


def test_a_task_parameter_names_the_machine_and_without_it_the_leaf_names_none(store):
    xml = (
        '<root><BehaviorTree ID="B"><Sequence>'
        '<Action ID="LeafNodeIc120" model_name="{machine}" record_name="ENTER_PATH" '
        'subtask_name="st_ic120_follow_waypoints"/>'
        '<Action ID="LeafNodeZx200" model_name="zx200" record_name="p" subtask_name="subtask_zx200_change_pose"/>'
        "</Sequence></BehaviorTree></root>"
    )
    tid = store.add_task(xml, blackboard={"machine": "ic120_2"})
    assert store.get_task(tid)["model_name"] == "ic120_2,zx200"
    # no such parameter: "{machine}" is no machine's name (neither is the ic120 in the leaf's ID or subtask)
    assert detect_model_names(xml) == "zx200"
    assert detect_model_names(xml, {"machine": 3}) == "zx200"
