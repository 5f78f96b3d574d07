"""A scripted test leaf (like py_trees' StatusQueue): ``<Scripted id="a"/>``.

Blackboard ``script_<id>`` holds a string of statuses consumed one per tick (S/F/R; the last one
repeats). Every tick appends ``"<id>"`` and every halt of a RUNNING leaf ``"halt <id>"`` to the
blackboard list ``log``.
"""

from __future__ import annotations

from tms_ts.bt.core import FAILURE, RUNNING, SUCCESS, ActionNode, Port, Status
from tms_ts.loader import load_tree, register_node

_MAP = {"S": SUCCESS, "F": FAILURE, "R": RUNNING}


class Scripted(ActionNode):
    PORTS = {"id": Port("str")}

    def _tick(self) -> Status:
        key = self.get_input("id")
        bb = self.ctx.blackboard
        script = bb.get(f"script_{key}")
        bb.get("log").append(key)
        if len(script) > 1:
            bb.set(f"script_{key}", script[1:])
        return _MAP[script[0]]

    def on_halted(self) -> None:
        self.ctx.blackboard.get("log").append(f"halt {self.get_input('id')}")


register_node("Scripted", Scripted)


def tree(body: str, **scripts: str):
    """Load ``body`` (the inside of one BehaviorTree) with scripts ``id=statuses``."""
    t = load_tree(f'<root main_tree_to_execute="T"><BehaviorTree ID="T">{body}</BehaviorTree></root>')
    t.ctx.blackboard.set("log", [])
    for key, script in scripts.items():
        t.ctx.blackboard.set(f"script_{key}", script)
    return t


def log(t) -> list[str]:
    out = list(t.ctx.blackboard.get("log"))
    t.ctx.blackboard.get("log").clear()
    return out
