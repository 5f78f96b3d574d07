"""Helpers to read the paper trees and seed in tests (no ROS)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
SEED = ROOT / "config" / "seeds" / "paper.yaml"
TREE_FILES = sorted((ROOT / "trees").glob("paper_*.xml"))  # the paper experiment (fleet: tests/tms_sp/test_fleet.py)

# BehaviorTree.CPP v3 built-ins the runtime (tms_ts) supports, as used by the original XMLs.
BUILTINS = {
    "Sequence", "Fallback", "ReactiveSequence", "IfThenElse", "WhileDoElse", "Parallel", "Repeat",
    "RetryUntilSuccessful", "KeepRunningUntilFailure", "ForceSuccess", "AlwaysSuccess", "AlwaysFailure",
    "Delay", "SetBlackboard",
}
# Custom node ids (the original's tms_ts custom nodes) and their ports (BT.CPP rejects unknown ports).
CUSTOM_PORTS = {
    "BlackboardValueReaderMongo": {"output_port", "mongo_record_name", "mongo_param_name"},
    "MongoValueWriter": {"input_value", "mongo_record_name", "mongo_param_name"},
    "ConditionalExpression": {"conditional_expression"},
    "KeepRunningUntilFlgup": {"key"},
    "SetLocalBlackboard": {"value", "output_key"},
    "LeafNodeIc120": {"model_name", "record_name", "subtask_name"},
    "LeafNodeZx200": {"model_name", "record_name", "subtask_name"},
}
SUBTASKS = {
    "zx200": {"subtask_zx200_change_pose", "subtask_zx200_excavate_simple", "subtask_zx200_release_simple"},
    "ic120": {
        "st_ic120_follow_waypoints", "st_ic120_follow_waypoints_deg", "st_ic120_navigate_anywhere",
        "st_ic120_navigate_anywhere_deg", "st_ic120_navigate_through_poses", "st_ic120_navigate_through_poses_deg",
        "st_ic120_release_soil",
    },
}


def load_seed() -> dict:
    return yaml.safe_load(SEED.read_text())


def tree_root(path: Path) -> ET.Element:
    """The single <BehaviorTree> element of a file."""
    root = ET.parse(path).getroot()
    trees = root.findall("BehaviorTree")
    assert len(trees) == 1, f"{path.name}: expected one BehaviorTree, found {len(trees)}"
    return trees[0]


def node_id(el: ET.Element) -> str:
    return el.get("ID") if el.tag in ("Action", "Decorator", "Condition", "Control") else el.tag


def iter_nodes(path: Path):
    """Every tree node element below <BehaviorTree> (not the BehaviorTree itself)."""
    return list(tree_root(path).iter())[1:]
