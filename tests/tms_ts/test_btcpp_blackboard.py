"""BehaviorTree.CPP 3.8.7's blackboard typing with the original's custom nodes (tms_ts.blackboard has the rules).

Each expectation here is what BT.CPP 3.8.7 (built from its 3.8.7 tag) with the original's node headers
(KeepRunningUntilFlgup.hpp, SetLocalBlackboard.hpp, Counter.hpp, SetLocalBlackboardWithCounter.hpp,
conditional_expression.hpp with the ExprTk it ships) did with the same tree; the quoted texts are its.
"""

from __future__ import annotations

import logging
import math

import pytest

from tms_db import open_store
from tms_ts.blackboard import (
    BOOL,
    DOUBLE,
    INT,
    LONG,
    STRING,
    UINT,
    Blackboard,
    BlackboardError,
    any_cast,
    convert_from_string,
)
from tms_ts.bt.core import FAILURE, RUNNING, SUCCESS, ActionNode, Port, Status, TreeContext
from tms_ts.errors import TreeLoadError, TreeRuntimeError
from tms_ts.loader import load_tree, register_node
from tms_ts.task import FAILED, TaskRun


class _BoolPortProbe(ActionNode):
    """A node with an ``InputPort<bool>`` (no node of the original has one): records what it read."""

    PORTS = {"in": Port("bool")}

    def _tick(self) -> Status:
        self.read = self.get_input("in")
        return SUCCESS


register_node("BoolPortProbe", _BoolPortProbe)


def _tree(body: str, store=None):
    return load_tree(f'<root main_tree_to_execute="T"><BehaviorTree ID="T">{body}</BehaviorTree></root>',
                     TreeContext(store=store))


@pytest.fixture
def store(tmp_path):
    s = open_store(path=tmp_path / "db")
    s.upsert_parameter({"record_name": "BB", "type": "dynamic", "CONTINUE_FLG": False, "N": 3, "D": 1.5})
    yield s
    s.close()


# -- the original's 2024-12 demo trees: SetBlackboard "true" under KeepRunningUntilFlgup --------------------------
DEMO_SHAPE = """<root main_tree_to_execute="BehaviorTree">
  <BehaviorTree ID="BehaviorTree">
    <Decorator ID="KeepRunningUntilFlgup" key="TERMINATE_FLG">
      <Sequence>
        <Action ID="BlackboardValueReaderMongo" mongo_param_name="CONTINUE_FLG" mongo_record_name="BB" \
output_port="CONTINUE_FLG"/>
        <WhileDoElse>
          <Action ID="ConditionalExpression" conditional_expression="CONTINUE_FLG == true"/>
          <AlwaysSuccess/>
          <SetBlackboard output_key="TERMINATE_FLG" value="true"/>
        </WhileDoElse>
      </Sequence>
    </Decorator>
  </BehaviorTree>
</root>"""


def test_the_demo_trees_end_refused_by_keep_running_until_flgup_naming_node_line_key_and_rule(store, caplog):
    # BT.CPP: the text "true" goes into a key no typed port declared -> untyped entry holding std::string;
    # KeepRunningUntilFlgup throws "Unsupported type for key [TERMINATE_FLG]" and the manager ends the task.
    tree = load_tree(DEMO_SHAPE, TreeContext(store=store), source="task 2")
    run = TaskRun(2, tree)
    with caplog.at_level(logging.ERROR, logger="tms_ts.task"):
        run.step()  # no leaves to wait for: starts and ticks at once
    assert run.state == FAILED
    # a tree's own error is one log line naming it, no traceback (those are kept for the manager's bugs)
    assert [r.exc_info for r in caplog.records] == [None] and "TERMINATE_FLG" in caplog.records[0].getMessage()
    entry = tree.ctx.blackboard.get_any("TERMINATE_FLG")
    assert (entry.vtype, entry.value, entry.port_type) == (STRING, "true", None)
    msg = run.message
    assert (
        "KeepRunningUntilFlgup (task 2 line 3, column 5)" in msg and "Unsupported type for key [TERMINATE_FLG]" in msg
    )
    assert "std::string 'true'" in msg and "SetBlackboard writes its value as a std::string" in msg


def test_while_the_flag_is_unset_the_demo_loop_keeps_running(store):
    store.set_fields("BB", {"CONTINUE_FLG": True})
    tree = load_tree(DEMO_SHAPE, TreeContext(store=store))
    assert [tree.tick() for _ in range(3)] == [RUNNING] * 3  # an absent key is "not yet", not an error


def test_set_local_blackboard_then_set_blackboard_into_the_same_key_is_refused():
    # SetLocalBlackboard set() a bool: the entry is typed bool *without* a converter, so the text is not parsed.
    t = _tree('<Sequence><Action ID="SetLocalBlackboard" output_key="TERMINATE_FLG" value="false"/>'
              '<SetBlackboard output_key="TERMINATE_FLG" value="true"/></Sequence>')
    with pytest.raises(TreeRuntimeError) as info:
        t.tick()
    msg = str(info.value)
    assert msg.startswith("SetBlackboard (line 1, column ") and "blackboard key 'TERMINATE_FLG'" in msg
    assert ("Blackboard::set() failed: once declared, the type of a port shall not change. "
            "Declared type [bool] != current type [std::string]") in msg
    assert t.ctx.blackboard.get("TERMINATE_FLG") is False  # unchanged


def test_a_key_a_bool_port_declared_takes_the_text_true_as_a_bool():
    # {FLAG} on an InputPort<bool> creates FLAG typed bool with convertFromString<bool>: "true" is parsed.
    t = _tree('<KeepRunningUntilFlgup key="FLAG"><Sequence><SetBlackboard output_key="FLAG" value="true"/>'
              '<BoolPortProbe in="{FLAG}"/></Sequence></KeepRunningUntilFlgup>')
    assert t.ctx.blackboard.get_any("FLAG").port_type == BOOL and t.ctx.blackboard.get_any("FLAG").empty
    assert t.tick() is SUCCESS
    entry = t.ctx.blackboard.get_any("FLAG")
    assert (entry.vtype, entry.value) == (BOOL, True)
    t2 = _tree('<Sequence><SetBlackboard output_key="FLAG" value="yes"/><BoolPortProbe in="{FLAG}"/></Sequence>')
    with pytest.raises(TreeRuntimeError, match=r"convertFromString<bool> refuses the text: .*invalid bool conversion"):
        t2.tick()


def test_the_text_into_an_int_port_key_is_parsed_as_std_stoi_does():
    # Repeat's InputPort<int> declares N; SetBlackboard's "3" becomes int 3; the Counter text "0" stays text.
    t = _tree('<Sequence><SetBlackboard output_key="C" value="0"/><SetBlackboard output_key="N" value="3abc"/>'
              '<Repeat num_cycles="{N}"><Counter key="C"/></Repeat></Sequence>')
    assert t.tick() is SUCCESS
    assert t.ctx.blackboard.get("N") == 3 and t.ctx.blackboard.get_any("N").vtype == INT
    assert t.ctx.blackboard.get("C") == "3"


def test_a_first_write_through_a_subtree_remapping_is_stored_unparsed_as_bt_cpp_does():
    # createEntryImpl finds the parent's bool entry and set() assigns the string as it is (no type check);
    # the second write from the subtree goes through the local entry and is parsed.
    xml = ('<root main_tree_to_execute="Main"><BehaviorTree ID="Main"><Sequence>'
           '<SubTree ID="Inner" flag="{FLAG}"/>'
           '<KeepRunningUntilFlgup key="FLAG"><BoolPortProbe in="{FLAG}"/></KeepRunningUntilFlgup>'
           '</Sequence></BehaviorTree><BehaviorTree ID="Inner">@BODY@</BehaviorTree></root>')
    once = load_tree(xml.replace("@BODY@", '<SetBlackboard output_key="flag" value="true"/>'))
    with pytest.raises(TreeRuntimeError, match=r"Unsupported type for key \[FLAG\]"):
        once.tick()
    twice = load_tree(xml.replace("@BODY@", '<Sequence><SetBlackboard output_key="flag" value="false"/>'
                                            '<SetBlackboard output_key="flag" value="true"/></Sequence>'))
    assert twice.tick() is SUCCESS and twice.ctx.blackboard.get_any("FLAG").vtype == BOOL


# -- ConditionalExpression over a string entry --------------------------------------------------------------------
@pytest.mark.parametrize("setter,expr,expected,exprtk_input", [
    ('<SetBlackboard output_key="F" value="true"/>', "F == true", FAILURE, '"true" == true'),
    ('<SetBlackboard output_key="F" value="true"/>', "F != true", FAILURE, '"true" != true'),
    ('<SetBlackboard output_key="F" value="true"/>', 'F == "true"', SUCCESS, "true"),
    ('<Action ID="SetLocalBlackboard" output_key="F" value="true"/>', "F == true", SUCCESS, "true == true"),
    ('<SetBlackboard output_key="F" value="DUMP"/>', 'F == "DUMP"', FAILURE, 'false""'),  # the quoted word is a key too
    ('<SetBlackboard output_key="F" value="3"/>', "F == 3", FAILURE, '"3" == 3'),
    ('<Action ID="SetLocalBlackboard" output_key="F" value="0.0000001"/>', "F > 0", FAILURE, "0.000000 > 0"),
    ('<Action ID="SetLocalBlackboard" output_key="F" value="true"/>', "F == true and not(false)", FAILURE,
     'true == true and ""(false)'),  # "not" is a word: substituted by "" (no such key)
    ("<AlwaysSuccess/>", 'UNKNOWN == ""', SUCCESS, "true"),
])
def test_conditional_expression_substitutes_entries_as_the_original(setter, expr, expected, exprtk_input):
    t = _tree(f'<Sequence>{setter}<Condition ID="ConditionalExpression" '
              f'conditional_expression="{expr.replace(chr(34), "&quot;")}"/></Sequence>')
    assert t.tick() is expected, t.root.children[1].feedback_message
    assert t.root.children[1].substitute(expr) == exprtk_input


def test_conditional_expression_leaves_a_long_entry_a_name_exprtk_does_not_know(store):
    store.set_fields("BB", {"L": 2**40})  # a BSON int64: the original sets it as long, which it does not substitute
    t = _tree('<Sequence><Action ID="BlackboardValueReaderMongo" mongo_param_name="L" mongo_record_name="BB" '
              'output_port="L"/><Condition ID="ConditionalExpression" conditional_expression="L &gt; 0"/></Sequence>',
              store)
    assert t.tick() is FAILURE
    assert "undefined symbol 'L'" in t.root.children[1].feedback_message
    assert t.ctx.blackboard.get_any("L").vtype == LONG


# -- a {key} declared std::string by the original's string ports ---------------------------------------------------
def test_a_key_a_string_port_declared_refuses_a_number_from_the_db(store):
    # The fleet ticket pattern: input_value="{N}" declares N std::string; the reader's int is refused (the
    # original's reader catches the LogicError and returns FAILURE).
    t = _tree('<Sequence><Action ID="BlackboardValueReaderMongo" output_port="N" mongo_record_name="BB" '
              'mongo_param_name="N"/><Action ID="MongoValueWriter" input_value="{N}" mongo_record_name="BB" '
              'mongo_param_name="M"/></Sequence>', store)
    assert t.tick() is FAILURE
    reason = t.ctx.failures[-1]
    assert reason.startswith("BlackboardValueReaderMongo (line 1, column ") and "blackboard key 'N'" in reason
    assert "Declared type [std::string] != current type [int]" in reason


def test_a_bool_read_through_a_string_port_is_the_text_1_as_any_cast_gives_it(store):
    # SetBlackboard's copy skips the type check (the original's N_INT idiom); getInput<std::string> of a bool is "1",
    # which MongoValueWriter then writes as the int 1.
    store.set_fields("BB", {"FLG": True})
    t = _tree('<Sequence><Action ID="BlackboardValueReaderMongo" output_port="RAW" mongo_record_name="BB" '
              'mongo_param_name="FLG"/><SetBlackboard output_key="S" value="{RAW}"/>'
              '<Action ID="MongoValueWriter" input_value="{S}" mongo_record_name="BB" mongo_param_name="OUT"/>'
              '<Action ID="SetLocalBlackboard" output_key="B2" value="{S}"/></Sequence>', store)
    assert t.tick() is SUCCESS
    assert store.get_record("BB")["OUT"] == 1 and store.get_record("BB")["OUT"] is not True
    assert t.ctx.blackboard.get("B2") == 1 and t.ctx.blackboard.get_any("B2").vtype == INT


def test_counter_on_a_number_set_by_the_reader_is_refused(store):
    # The reader's set() made N typed int without a converter: Counter's text "4" cannot go back in.
    t = _tree('<Sequence><Action ID="BlackboardValueReaderMongo" output_port="N" mongo_record_name="BB" '
              'mongo_param_name="N"/><Action ID="Counter" key="N"/></Sequence>', store)
    with pytest.raises(
        TreeRuntimeError, match=r"Counter \(line 1.*Declared type \[int\] != current type \[std::string\]"
    ):
        t.tick()


def test_two_ports_of_different_types_on_one_key_are_a_load_error():
    with pytest.raises(TreeLoadError) as info:
        _tree('<Sequence><Repeat num_cycles="{N}"><AlwaysSuccess/></Repeat>'
              '<Delay delay_msec="{N}"><AlwaysSuccess/></Delay></Sequence>')
    msg = str(info.value)
    assert "Delay (line 1, column " in msg and "port 'delay_msec' = '{N}'" in msg
    assert ("the port [N] was initially created with type [int] and, later type [unsigned int] was used somewhere "
            "else") in msg
    # a key first declared std::string may be read by any typed port (xml_parsing.cpp's "string_input")
    _tree('<Sequence><Action ID="MongoValueWriter" input_value="{N}" mongo_record_name="a" mongo_param_name="b"/>'
          '<Repeat num_cycles="{N}"><AlwaysSuccess/></Repeat></Sequence>')


def test_set_blackboard_output_key_in_braces_names_the_key_held_there():
    # output_key is read with getInput<std::string>: {WHERE} is the entry whose name WHERE holds
    t = _tree('<Sequence><SetBlackboard output_key="WHERE" value="TARGET"/>'
              '<SetBlackboard output_key="{WHERE}" value="x"/></Sequence>')
    assert t.tick() is SUCCESS and t.ctx.blackboard.get("TARGET") == "x"


# -- the conversions themselves --------------------------------------------------------------------------------
@pytest.mark.parametrize("text,ctype,expected", [
    ("TRUE", BOOL, True), ("0", BOOL, False), ("12abc", INT, 12), (" -7", INT, -7), ("1.5m", DOUBLE, 1.5),
    (" 2.5", DOUBLE, 2.5), ("-1", UINT, 2**32 - 1), ("x", STRING, "x"), ("inf", DOUBLE, math.inf),
])
def test_convert_from_string_is_bt_cpps(text, ctype, expected):
    assert convert_from_string(text, ctype) == expected


@pytest.mark.parametrize(
    "text,ctype", [("yes", BOOL), ("tRue", BOOL), ("abc", INT), ("3000000000", INT), ("x", DOUBLE)]
)
def test_convert_from_string_refuses_what_bt_cpp_throws_on(text, ctype):
    with pytest.raises(ValueError):
        convert_from_string(text, ctype)


@pytest.mark.parametrize("value,vtype,target,expected", [
    (True, BOOL, STRING, "1"), (1.5, DOUBLE, STRING, "1.500000"), (3, INT, STRING, "3"), (2.0, DOUBLE, INT, 2),
    (3, INT, BOOL, True), (0.5, DOUBLE, BOOL, True), (3, INT, DOUBLE, 3.0), (True, BOOL, INT, 1), (4, LONG, INT, 4),
])
def test_any_cast_converts_numbers_as_bt_cpp(value, vtype, target, expected):
    assert any_cast(value, vtype, target) == expected


@pytest.mark.parametrize("value,vtype,target,why", [
    (1.5, DOUBLE, INT, "Floating point truncated"), (-1, INT, UINT, "Value is negative"),
    (2**40, LONG, INT, "Value too large."), ("3", STRING, INT, "no known safe conversion"),
])
def test_any_cast_refuses_as_bt_cpp(value, vtype, target, why):
    with pytest.raises(ValueError, match=why):
        any_cast(value, vtype, target)


def test_get_input_reads_a_string_entry_with_convert_from_string_and_others_with_any_cast():
    # S is declared std::string first (SetLocalBlackboard's value port), so "1" stays text in it and the bool
    # port reads it with convertFromString<bool>; a double entry is read with Any::cast (!= 0).
    t = _tree('<Sequence><SetBlackboard output_key="S" value="1"/>'
              '<Action ID="SetLocalBlackboard" output_key="X" value="{S}"/><BoolPortProbe in="{S}"/></Sequence>')
    assert t.tick() is SUCCESS and t.root.children[2].read is True
    assert t.ctx.blackboard.get_any("S").vtype == STRING
    # D declared untyped first (SetBlackboard's value port), so it may hold a double
    t2 = _tree('<Sequence><SetBlackboard output_key="Y" value="{D}"/><BoolPortProbe in="{D}"/></Sequence>')
    t2.ctx.blackboard.set("D", 0.0)
    assert t2.tick() is SUCCESS and t2.root.children[1].read is False
    t2.ctx.blackboard.set("D", 0.25)
    assert t2.tick() is SUCCESS and t2.root.children[1].read is True


def test_a_new_string_key_is_untyped_and_a_new_number_typed_without_converter():
    bb = Blackboard()
    bb.set("S", "text")
    bb.set("S", 3)  # an untyped entry takes any type afterwards
    assert bb.get("S") == 3
    bb.set("N", 3)
    with pytest.raises(BlackboardError, match=r"Declared type \[int\] != current type \[std::string\]"):
        bb.set("N", "4")
    with pytest.raises(BlackboardError, match=r"Declared type \[int\] != current type \[double\]"):
        bb.set("N", 4.0)
