"""The §5 node kinds: typed DB reads, string-to-type writes, expressions, flag waiting, counters.

The global-blackboard nodes run against the real embedded tms_db store on disk (tmp_path).
"""

from __future__ import annotations

import pytest

from tests.tms_ts.scripted import log, tree
from tms_db import open_store
from tms_ts.bt.core import FAILURE, RUNNING, SUCCESS, TreeContext
from tms_ts.errors import TreeRuntimeError
from tms_ts.expression import evaluate
from tms_ts.loader import load_tree


@pytest.fixture
def store(tmp_path):
    s = open_store(path=tmp_path / "db")
    s.upsert_parameter({"record_name": "GBB", "type": "dynamic", "FLG": False, "N": 3, "D": 1.5, "S": "text",
                        "ARR": [1, 2]})
    yield s
    s.close()


def _run(xml_body: str, store, **bb):
    t = load_tree(f'<root><BehaviorTree ID="B">{xml_body}</BehaviorTree></root>', TreeContext(store=store))
    for k, v in bb.items():
        t.ctx.blackboard.set(k, v)
    return t


def test_reader_keeps_the_stored_type(store):
    body = (
        "<Sequence>"
        + "".join(
            f'<Action ID="BlackboardValueReaderMongo" output_port="{k.lower()}" mongo_record_name="GBB" '
            f'mongo_param_name="{k}"/>'
            for k in ("FLG", "N", "D", "S")
        )
        + "</Sequence>"
    )
    t = _run(body, store)
    assert t.tick() is SUCCESS
    assert t.ctx.blackboard.snapshot() == {"flg": False, "n": 3, "d": 1.5, "s": "text"}
    assert type(t.ctx.blackboard.get("n")) is int


@pytest.mark.parametrize("record,field,why", [("NOPE", "FLG", "'NOPE' not found"), ("GBB", "MISSING", "no field"),
                                              ("GBB", "ARR", "unsupported type")])
def test_reader_fails_on_missing_record_field_or_type(store, record, field, why):
    t = _run(f'<Action ID="BlackboardValueReaderMongo" output_port="x" mongo_record_name="{record}" '
             f'mongo_param_name="{field}"/>', store)
    assert t.tick() is FAILURE and why in t.root.feedback_message


def test_writer_converts_text_and_resolves_keys(store):
    body = ("<Sequence>"
            '<Action ID="MongoValueWriter" input_value="true" mongo_record_name="GBB" mongo_param_name="FLG"/>'
            '<Action ID="MongoValueWriter" input_value="2.5" mongo_record_name="GBB" mongo_param_name="D"/>'
            '<Action ID="MongoValueWriter" input_value="7" mongo_record_name="GBB" mongo_param_name="N"/>'
            '<Action ID="MongoValueWriter" input_value="abc" mongo_record_name="GBB" mongo_param_name="S"/>'
            '<Action ID="MongoValueWriter" input_value="{v}" mongo_record_name="{rec}" mongo_param_name="K"/>'
            "</Sequence>")
    t = _run(body, store, v="12", rec="GBB")
    assert t.tick() is SUCCESS
    doc = store.get_record("GBB")
    assert doc["FLG"] is True and doc["D"] == 2.5 and doc["N"] == 7 and type(doc["N"]) is int
    assert doc["S"] == "abc" and doc["K"] == 12 and "timestamps" in doc


def test_writer_retries_a_missing_record_then_fails(store):
    t = _run('<Action ID="MongoValueWriter" input_value="1" mongo_record_name="LATER" mongo_param_name="X"/>', store)
    clock = [0.0]
    t.ctx.clock = lambda: clock[0]
    assert t.tick() is RUNNING
    store.upsert_parameter({"record_name": "LATER", "type": "dynamic"})  # appears between retries
    clock[0] += 0.2
    assert t.tick() is SUCCESS and store.get_record("LATER")["X"] == 1
    t2 = _run('<Action ID="MongoValueWriter" input_value="1" mongo_record_name="NEVER" mongo_param_name="X"/>', store)
    t2.ctx.clock = lambda: clock[0]
    statuses = []
    for _ in range(6):
        statuses.append(t2.tick())
        clock[0] += 0.2
        if statuses[-1] is not RUNNING:
            break
    assert statuses == [RUNNING] * 4 + [FAILURE] and "'NEVER' not found after 5 attempts" in t2.root.feedback_message


def test_conditional_expression_over_blackboard():
    ok = [("A == true and N != 3", {"A": True, "N": 4}, True),
          ("LOC == WANTED", {"LOC": "DUMP", "WANTED": "DUMP"}, True),  # two string entries: "DUMP" == "DUMP"
          ('LOC == "DUMP"', {"LOC": "DUMP"}, False),  # the original substitutes the quoted word too (no such key)
          ("(A or B) and C == false", {"A": False, "B": True, "C": False}, True),
          ("(A or B) and not C", {"A": False, "B": True, "C": False}, False),  # "not" is a word: substituted
          ('UNKNOWN == ""', {}, True),  # unknown key is the empty string
          ("UNKNOWN == ''", {}, False),  # "" == '' : ExprTk has no double-quoted strings
          ("N >= 2.5", {"N": 2}, False)]
    for expr, bb, expected in ok:
        t = _run(f'<Condition ID="ConditionalExpression" conditional_expression="{expr.replace(chr(34), "&quot;")}"/>',
                 None, **bb)
        assert (t.tick() is SUCCESS) is expected, expr
    t = _run('<Condition ID="ConditionalExpression" conditional_expression="N == "/>', None, N=1)
    assert t.tick() is FAILURE and "expected a value" in t.root.feedback_message
    t = _run('<Condition ID="ConditionalExpression" conditional_expression="S == 1"/>', None, S="x")
    assert t.tick() is FAILURE and "no double-quoted strings" in t.root.feedback_message
    assert """ExprTk input '"x" == 1'""" in t.root.feedback_message


def test_expression_evaluator_is_not_python_eval():
    for hostile in ("__import__('os').system('true')", "A.__class__", "[1]", "lambda: 1"):
        with pytest.raises(Exception) as info:
            evaluate(hostile, {"A": 1})
        assert type(info.value).__name__ == "ExpressionError"


def test_conditional_expression_bool_only_sees_bools():
    t = _run(
        '<Action ID="ConditionalExpressionBool" conditional_expression_bool="A and not(B)"/>', None, A=True, B=False
    )
    assert t.tick() is SUCCESS
    t = _run(
        '<Action ID="ConditionalExpressionBool" conditional_expression_bool="A and not B"/>', None, A=True, B=False
    )
    assert t.tick() is FAILURE  # ExprTk: not is a function, "not B" does not parse
    t = _run('<Action ID="ConditionalExpressionBool" conditional_expression_bool="A and N"/>', None, A=True, N=1)
    assert t.tick() is FAILURE and "'N' is not a bool" in t.root.feedback_message


def test_keep_running_until_flgup_waits_for_bool_true():
    t = tree('<KeepRunningUntilFlgup key="DONE"><Scripted id="a"/></KeepRunningUntilFlgup>', a="S")
    assert t.tick() is RUNNING  # absent
    t.ctx.blackboard.set("DONE", False)
    assert t.tick() is RUNNING
    t.ctx.blackboard.set("DONE", True)
    assert t.tick() is SUCCESS and log(t) == ["a", "a", "a"]
    t2 = tree('<KeepRunningUntilFlgup key="DONE"><Scripted id="a"/></KeepRunningUntilFlgup>', a="F")
    assert t2.tick() is FAILURE
    t3 = tree('<KeepRunningUntilFlgup key="DONE"><Scripted id="a"/></KeepRunningUntilFlgup>', a="S")
    t3.ctx.blackboard.set("DONE", "true")  # what built-in SetBlackboard writes
    with pytest.raises(TreeRuntimeError, match=r"Unsupported type for key \[DONE\]: it holds std::string 'true'"):
        t3.tick()


def test_counters():
    t = _run('<Sequence><Action ID="Counter" key="n"/><Action ID="Counter" key="n"/>'
             '<Action ID="SetLocalBlackboardWithCounter" key="path" counter_key="n"/></Sequence>', None,
             n="0", path="load_path_0")
    assert t.tick() is SUCCESS
    assert t.ctx.blackboard.get("n") == "2" and t.ctx.blackboard.get("path") == "load_path_2"
    t = _run('<Action ID="Counter" key="n"/>', None, n="x")
    assert t.tick() is FAILURE
    t = _run('<Action ID="SetLocalBlackboardWithCounter" key="path" counter_key="missing"/>', None, path="p0")
    assert t.tick() is FAILURE and "'missing'" in t.root.feedback_message


def test_blackboard_value_checker():
    assert _run('<Action ID="BlackboardValueChecker" key="a"/>', None, a=1.0).tick() is SUCCESS
    assert _run('<Action ID="BlackboardValueChecker" key="a"/>', None).tick() is FAILURE


class _Inbox:
    """The confirm-topic side of RosPort, in memory (the manager fills it from /tms_ts/confirm)."""

    def __init__(self) -> None:
        self.items: list[tuple[int, str]] = []

    def confirm_seq(self) -> int:
        return len(self.items)

    def confirmations(self, since: int) -> list[tuple[int, str]]:
        return [(s, t) for s, t in self.items if s > since]

    def say(self, text: str) -> None:
        self.items.append((len(self.items) + 1, text))


def test_wait_for_click_is_non_blocking_and_honours_task_prefix():
    inbox = _Inbox()
    inbox.say("yes")  # before the node started: ignored
    t = load_tree(
        '<root><BehaviorTree ID="B"><Action ID="WaitForClick" button_info="Load done?"/></BehaviorTree></root>',
        TreeContext(ros=inbox, task_id=3),
    )
    assert t.tick() is RUNNING and "Load done?" in t.root.feedback_message
    inbox.say("4:yes")  # for another task
    assert t.tick() is RUNNING
    inbox.say("3:yes")
    assert t.tick() is SUCCESS
    assert t.tick() is RUNNING  # a new wait
    inbox.say("no")
    assert t.tick() is FAILURE
