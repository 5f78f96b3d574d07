"""Hostile and careless trees at the scheduler's entries (issue 38), property-based with hypothesis.

Entries: ``load_tree`` (what ``/tms_ts/start`` runs on a stored tree, and the last step of every other entry) and
``parse_task_sequence`` + ``load_tree`` (``/task_sequence``). Whatever the input, an entry either accepts it or
raises its own one-line error (TreeLoadError / TaskSequenceError) naming the limit or the culprit: never another
exception (a RecursionError there ended the manager), never a name a ROS client would refuse afterwards. Every
input tried is counted per entry and printed (``-s``).
"""

from __future__ import annotations

import collections
import json
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tms_ts.errors import TaskSequenceError, TreeLoadError, TreeRuntimeError
from tms_ts.limits import MAX_JSON_DEPTH, MAX_TREE_BYTES, MAX_TREE_DEPTH, MAX_TREE_NODES, TASK_ID_MAX
from tms_ts.loader import check_tree, load_tree
from tms_ts.names import ros_name_problem
from tms_ts.task_sequence import parse_task_sequence

TRIED: collections.Counter = collections.Counter()
HYPO = settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large]
)

BAD_NAMES = ["d37pxi_24＿", "zx 200", "", " ", "1zx200", "zx200//a", "zx-200", "zx200.a", "ｚｘ２００",
             "zx200\u200b", "{machine", "~zx200", "zx200 ", "a" * 300]


def doc(body: str, extra: str = "") -> str:
    return f'<root main_tree_to_execute="Main"><BehaviorTree ID="Main">{body}</BehaviorTree>{extra}</root>'


def leaf(model: str = "zx200", subtask: str = "subtask_zx200_change_pose", record: str = "initial_pose") -> str:
    from xml.sax.saxutils import quoteattr

    return (f'<Action ID="LeafNodeZx200" model_name={quoteattr(model)} subtask_name={quoteattr(subtask)} '
            f'record_name={quoteattr(record)}/>')


def nested(depth: int) -> str:
    """A Sequence chain ``depth`` deep around one AlwaysSuccess (the issue's 1000-deep 21 KB tree, at 1000)."""
    return doc("<Sequence>" * depth + "<AlwaysSuccess/>" + "</Sequence>" * depth)


def refused(entry: str, xml: str, **kw) -> str:
    """The one-line TreeLoadError ``load_tree`` gives ``xml`` (any other exception fails the test)."""
    TRIED[entry] += 1
    with pytest.raises(TreeLoadError) as err:
        load_tree(xml, source="task 7", **kw)
    message = str(err.value)
    assert "\n" not in message and message.startswith("task 7"), message
    return message


def loads_or_refuses(entry: str, xml: str, **kw):
    """Accepted (the tree) or a one-line TreeLoadError (None); nothing else may come out."""
    TRIED[entry] += 1
    try:
        return load_tree(xml, source="task 7", **kw)
    except TreeLoadError as exc:
        assert "\n" not in str(exc), str(exc)
        return None


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    print("\ninputs tried per entry:", dict(sorted(TRIED.items())))


# -- limits ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("depth", [MAX_TREE_DEPTH, 1000, 10_000, 100_000])
def test_a_deep_tree_is_refused_at_its_line_and_column_without_recursing(depth) -> None:
    # the 1000-deep tree raised RecursionError in the manager's callback; 100,000 deep is 2.2 MB (size limit first)
    message = refused("load_tree", nested(depth))
    if len(nested(depth)) > MAX_TREE_BYTES:
        assert "MAX_TREE_BYTES" in message
    else:
        assert "MAX_TREE_DEPTH" in message and f"nested {MAX_TREE_DEPTH + 1} deep" in message
        assert "line 1, column" in message


def test_the_deepest_tree_allowed_loads_and_ticks() -> None:
    # root + BehaviorTree + 61 Sequences + the leaf = 64 nested elements: at the limit, and it runs
    tree = load_tree(nested(MAX_TREE_DEPTH - 3))
    assert tree.tick().name == "SUCCESS" and len(tree.nodes) == MAX_TREE_DEPTH - 2
    assert tree.snapshot().count("\n") == MAX_TREE_DEPTH - 3


def test_a_5_mb_tree_is_refused_by_its_size_before_it_is_parsed() -> None:
    # the 5 MB tree (172,707 nodes) blocked the executor 5.5 s: now refused before expat sees it
    body = "<Sequence>" + "".join(f'<AlwaysSuccess name="n{i:07d}"/>' for i in range(172_707)) + "</Sequence>"
    xml = doc(body)
    start = time.monotonic()
    message = refused("load_tree", xml)
    assert "MAX_TREE_BYTES" in message and f"{len(xml.encode()):,} bytes" in message and len(xml) > 5_000_000
    assert time.monotonic() - start < 1.0


def test_too_many_elements_are_refused_at_the_element_that_crosses_the_limit() -> None:
    body = "<Sequence>" + "<AlwaysSuccess/>" * MAX_TREE_NODES + "</Sequence>"  # 80 KB, under the size limit
    message = refused("load_tree", doc(body))
    assert "MAX_TREE_NODES" in message and f"element {MAX_TREE_NODES + 1:,}" in message


def test_subtree_chains_cannot_multiply_the_built_tree_past_its_limits() -> None:
    # 10 trees, each holding its next one 3 times: 3**9 = 19,683 leaves from a 1 KB document ("billion laughs")
    trees = (
        "".join(
            f'<BehaviorTree ID="T{i}"><Sequence>' + f'<SubTree ID="T{i + 1}"/>' * 3 + "</Sequence></BehaviorTree>"
            for i in range(9)
        )
        + '<BehaviorTree ID="T9"><AlwaysSuccess/></BehaviorTree>'
    )
    message = refused("load_tree", f'<root main_tree_to_execute="T0">{trees}</root>')
    assert "MAX_TREE_NODES" in message and "SubTrees T0 -> " in message
    # a chain of SubTrees, each 20 deep: the built tree nests deeper than any one document
    chain = "".join(f'<BehaviorTree ID="C{i}">' + "<Sequence>" * 20 + f'<SubTree ID="C{i + 1}"/>' + "</Sequence>" * 20
                    + "</BehaviorTree>" for i in range(5)) + '<BehaviorTree ID="C5"><AlwaysSuccess/></BehaviorTree>'
    message = refused("load_tree", f'<root main_tree_to_execute="C0">{chain}</root>')
    assert "built tree is 65 levels deep" in message and "MAX_TREE_DEPTH" in message


@given(st.integers(MAX_TREE_DEPTH - 2, 30_000))
@HYPO
def test_any_depth_past_the_limit_is_a_tree_load_error(depth) -> None:
    assert "MAX_TREE" in refused("load_tree", nested(depth))


# -- names -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", BAD_NAMES)
def test_a_leaf_model_name_ros_refuses_is_refused_at_load_naming_leaf_line_and_name(name) -> None:
    message = refused("load_tree", doc(f"<Sequence>\n<AlwaysSuccess/>\n{leaf(model=name)}</Sequence>"))
    assert "LeafNodeZx200 (line 3, column 1)" in message and "model_name" in message, message


def test_the_original_typo_names_the_full_width_underscore() -> None:
    # one of the original's task files has d37pxi_24＿ (U+FF3F): rclpy raised ValueError creating the client in the tick
    message = refused("load_tree", doc(leaf(model="d37pxi_24＿", subtask="st_d37pxi_navigate_anywhere")))
    assert "'d37pxi_24＿'" in message and "U+FF3F" in message and "no valid ROS name" in message


def test_a_task_parameter_model_name_is_checked_when_it_is_resolved() -> None:
    # model_name="{machine}" resolves at load from the task's blackboard: the bad value is named with its parameter
    message = refused("load_tree", doc(leaf(model="{machine}")), blackboard={"machine": "d37pxi_24＿"})
    assert "'d37pxi_24＿'" in message and "task parameter 'machine'" in message


@pytest.mark.parametrize("subtask", ["", "st ic120", "1st", "st_ic120＿", "a" * 240])
def test_bad_subtask_names_are_refused_at_load(subtask) -> None:
    message = refused("load_tree", doc(leaf(subtask=subtask)))
    assert "subtask_name" in message or "action name" in message, message


@pytest.mark.parametrize("record", ["", " pose", "pose ", "a" * 300])
def test_bad_literal_record_names_are_refused_at_load(record) -> None:
    assert "record_name" in refused("load_tree", doc(leaf(record=record)))


def test_an_empty_record_is_allowed_where_the_subtask_reads_none() -> None:
    # the MST's swing alignment reads no record (the original sends it none)
    load_tree(doc(leaf(model="mst110cr", subtask="st_mst110cr_swing_align_to_heading", record="")))


@given(st.text(min_size=0, max_size=40))
@HYPO
def test_any_model_name_either_loads_as_a_valid_ros_name_or_is_refused(name) -> None:
    tree = loads_or_refuses("load_tree names", doc(leaf(model=name)))
    if tree is not None:  # what loads is what rclpy takes: no ValueError can come from it in a tick
        (the_leaf,) = tree.leaves
        assert ros_name_problem(the_leaf.action) is None
        assert ros_name_problem(f"/{the_leaf.model_name}/subtask_outcome") is None


# -- unknown types, misspelled ports, missing SubTrees: the loader's own checks --------------------------
def test_unknown_type_misspelled_port_and_missing_subtree_name_their_line_and_column() -> None:
    for body, expected in (
        ("<Sequence>\n  <NoSuchNode/>\n</Sequence>", "NoSuchNode (line 2, column 3): unknown node ID"),
        (
            '<Sequence>\n  <Delay delay_mss="5"><AlwaysSuccess/></Delay>\n</Sequence>',
            "Delay (line 2, column 3): unknown port 'delay_mss'",
        ),
        ('<Sequence>\n  <SubTree ID="Gone"/>\n</Sequence>', "SubTree 'Gone' (line 2, column 3)"),
    ):
        assert expected in refused("load_tree", doc(body))


@given(st.sampled_from(["AlwaysSuccess", "Delay", "Sequence", "SetBlackboard", "Inverter"]),
       st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=12))
@HYPO
def test_a_mutated_node_or_port_is_refused_naming_it(node_id, junk) -> None:
    message = refused("load_tree", doc(f'<Sequence><{node_id}{junk}X/></Sequence>'))
    assert f"{node_id}{junk}X" in message
    message = refused("load_tree", doc(f'<Sequence><AlwaysSuccess {junk}X="1"/></Sequence>'))
    assert f"unknown port '{junk}X'" in message


@given(st.text(max_size=300))
@HYPO
def test_arbitrary_text_is_accepted_or_refused_never_raised(text) -> None:
    loads_or_refuses("load_tree text", text)
    loads_or_refuses("load_tree text", doc(text))


def test_a_deep_condition_expression_fails_its_node_not_the_tick() -> None:
    # ConditionalExpression parses recursively at the tick: 2,000 parentheses raised RecursionError inside it
    tree = load_tree(doc(f'<ConditionalExpression conditional_expression="{"(" * 2000}1{")" * 2000}"/>'))
    TRIED["load_tree"] += 1
    assert tree.tick().name == "FAILURE"
    assert "MAX_EXPRESSION_PARENS" in tree.nodes[0].feedback_message
    tree = load_tree(doc(f'<ConditionalExpression conditional_expression="{"1+" * 2000}1"/>'))
    assert tree.tick().name == "FAILURE" and "MAX_EXPRESSION_TOKENS" in tree.nodes[0].feedback_message


def test_a_run_time_record_name_is_checked_when_the_leaf_reads_it() -> None:
    # record_name="{rec}" is read at the leaf's start: a bad value ends the task (TreeRuntimeError) naming it
    tree = load_tree(doc(f'<Sequence><SetBlackboard output_key="rec" value=" pose"/>{leaf(record="{rec}")}</Sequence>'))
    with pytest.raises(TreeRuntimeError) as err:
        tree.tick()
    assert "LeafNodeZx200 (line 1, column" in str(err.value) and "' pose'" in str(err.value)
    assert "blackboard key 'rec'" in str(err.value)


# -- /task_sequence ---------------------------------------------------------------------------------------
def sequence_entry(data: str, task_id: int = -1) -> list:
    """parse_task_sequence then load_tree on each tree: accepted trees, or only the entries' own errors."""
    TRIED["/task_sequence"] += 1
    try:
        tasks = parse_task_sequence(data, task_id)
    except TaskSequenceError as exc:
        assert "\n" not in str(exc)
        return []
    for task in tasks:
        assert task.task_id is None or 1 <= task.task_id <= TASK_ID_MAX
        try:
            load_tree(task.xml, source=f"task {task.task_id}")
        except TreeLoadError as exc:
            assert "\n" not in str(exc)
    return tasks


@pytest.mark.parametrize("task_id", [0, -1, -5, 2**31, 2**63, True, 1.5, "1"])
def test_json_task_ids_outside_int32_are_refused(task_id) -> None:
    data = json.dumps({"tasks": [{"task_id": task_id, "task_sequence": nested(1)}]})
    TRIED["/task_sequence"] += 1
    with pytest.raises(TaskSequenceError, match=r"tasks\[0\]"):
        parse_task_sequence(data)


@pytest.mark.parametrize("param", [0, -2, 2**31, 2**63])
def test_the_task_id_parameter_outside_int32_is_refused(param) -> None:
    TRIED["/task_sequence"] += 1
    with pytest.raises(TaskSequenceError, match="parameter task_id"):
        parse_task_sequence(nested(1), param)


def test_deep_json_is_refused_before_json_parses_it() -> None:
    for depth in (MAX_JSON_DEPTH + 1, 1000, 100_000):
        for text in ('{"tasks": ' + "[" * depth + "]" * depth + "}", '{"tasks": ' + "[" * depth):
            TRIED["/task_sequence"] += 1
            with pytest.raises(TaskSequenceError, match="MAX_JSON_DEPTH"):
                parse_task_sequence(text)
    # brackets inside strings are text, not nesting
    assert sequence_entry(json.dumps({"tasks": [{"task_id": 3, "task_sequence": nested(1).replace("Main", "[" * 50)}]}))


def test_a_message_over_the_size_limit_and_lone_surrogates_are_refused() -> None:
    TRIED["/task_sequence"] += 2
    with pytest.raises(TaskSequenceError, match="MAX_TREE_BYTES"):
        parse_task_sequence(doc("<AlwaysSuccess/>" * 70_000))
    with pytest.raises(TaskSequenceError, match="lone surrogate"):
        parse_task_sequence('{"tasks": [{"task_id": 1, "task_sequence": "<root>\\udc00</root>"}]}')


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=30,
)


@given(
    st.lists(
        st.fixed_dictionaries(
            {
                "task_id": st.integers(-(2**70), 2**70) | JSON_VALUES,
                "task_sequence": st.sampled_from(
                    [nested(2), nested(200), doc(leaf(model="d37pxi_24＿")), doc("<Nope/>"), "<root>", ""]
                )
                | JSON_VALUES,
            }
        ),
        max_size=4,
    ),
    st.sampled_from([-1, 1, 0, 2**31, 2**63]),
)
@HYPO
def test_any_json_message_starts_valid_ids_or_is_refused(tasks, param) -> None:
    sequence_entry(json.dumps({"tasks": tasks}), param)


@given(JSON_VALUES | st.text(max_size=200))
@HYPO
def test_any_message_text_is_accepted_or_refused_never_raised(value) -> None:
    sequence_entry(value if isinstance(value, str) else json.dumps(value))


def test_check_tree_is_load_tree_without_ros_or_db() -> None:
    # what tms-db task add runs: a valid tree passes, and the same refusals as at start
    assert len(check_tree(doc(leaf()), source="t.xml").leaves) == 1
    with pytest.raises(TreeLoadError, match=r"^t\.xml: LeafNodeZx200 \(line 1, column \d+\)"):
        check_tree(doc(leaf(model="d37pxi_24＿")), source="t.xml")


def _depth(value) -> int:
    if isinstance(value, list):
        return 1 + max((_depth(v) for v in value), default=0)
    if isinstance(value, dict):
        return 1 + max((_depth(v) for v in value.values()), default=0)
    return 0


NESTED_JSON = st.recursive(
    st.text(alphabet='[]{}"\\ab', max_size=6) | st.integers(),
    lambda inner: (
        st.lists(inner, max_size=2) | st.dictionaries(st.text(alphabet='[]{}"\\', max_size=3), inner, max_size=2)
    ),
    max_leaves=40,
)


@given(NESTED_JSON)
@HYPO
def test_the_json_depth_check_is_exact_for_valid_json_whatever_its_strings_hold(value) -> None:
    # brackets, quotes and backslashes inside strings are no nesting; the check agrees with the real depth
    from tms_ts.limits import json_depth_exceeds

    TRIED["json depth"] += 1
    assert json_depth_exceeds(json.dumps(value)) == (_depth(value) > MAX_JSON_DEPTH)


def test_the_json_depth_check_is_linear_on_unterminated_strings() -> None:
    # a string pattern backtracked quadratically over '"\' repeated (minutes for 600 KB): the check must stay fast
    from tms_ts.limits import json_depth_exceeds

    for text in ('"\\' * 300_000, '"' * 1_000_000, "\\" * 1_000_000, '"' + "[" * 1_000_000):
        start = time.monotonic()
        json_depth_exceeds(text)
        assert time.monotonic() - start < 1.0
    TRIED["json depth"] += 4
