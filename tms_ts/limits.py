"""Limits on what a task input may hold, in one place (issue 38): every entry checks them before it builds or stores.

The entries: ``tms-db task add`` (the user's file), ``/task_sequence`` (the message, and each tree of its JSON),
``/tms_ts/start`` (the stored tree, loaded by the same :func:`tms_ts.loader.load_tree`). A tree over a limit is
refused with one line naming the input, the limit and where (the file and the line of the element that crossed
it); nothing is stored and nothing runs.

- ``MAX_TREE_BYTES`` = 1,048,576: UTF-8 bytes of one tree document (and of one ``/task_sequence`` message). The
  largest tree of ``trees/`` is 12.8 KB, the original's task files 4-40 KB: 80x headroom. A 5 MB tree blocked
  the manager's executor 5.5 s.
- ``MAX_TREE_DEPTH`` = 64: nested XML elements, ``<root>`` counting 1, in the document; and levels of the built
  tree (its root node 1, SubTrees inlined). Ours nest at most 12, BT.CPP trees rarely 20. The tick, halt and
  snapshot walk the tree recursively, a few Python frames a level: 64 levels stay far below Python's 1000-frame
  limit, where a tree 1000 deep raised RecursionError and ended the manager.
- ``MAX_TREE_NODES`` = 5,000: XML elements of the document (palette included), and nodes of the built tree
  (SubTrees inlined, so a chain of SubTrees cannot multiply them). Ours have at most 136 elements; building
  costs some 30 us a node, so 5,000 take about 0.15 s.
- ``MAX_JSON_DEPTH`` = 16: nesting of a ``/task_sequence`` JSON (its form needs 3), checked without recursion
  before :func:`json.loads` (which recurses once a level) runs.
- ``TASK_ID_MIN`` .. ``TASK_ID_MAX`` = 1 .. 2**31-1: task ids. The interface types carry int32 (``tms_msg/TaskIds``,
  ``TaskState.task_id``, the ``std_msgs/Int32`` cancel), and stored ids are positive.
- ``MAX_NAME_CHARS`` = 255: a leaf's ``model_name``, ``subtask_name`` and ``record_name`` (ROS names are checked by
  rclpy's rules besides, :mod:`tms_ts.names`).
- ``MAX_EXPRESSION_TOKENS`` = 200, ``MAX_EXPRESSION_PARENS`` = 16: tokens of one ConditionalExpression text (after
  substitution) and its nested parentheses; the expression is parsed and evaluated recursively (8 frames a
  parenthesis). Ours have at most 25 tokens and 2 levels. Over them: that node's FAILURE naming the limit.
"""

from __future__ import annotations

from typing import Any

from tms_ts.errors import TreeLoadError

__all__ = [
    "MAX_TREE_BYTES",
    "MAX_TREE_DEPTH",
    "MAX_TREE_NODES",
    "MAX_JSON_DEPTH",
    "TASK_ID_MIN",
    "TASK_ID_MAX",
    "MAX_NAME_CHARS",
    "MAX_EXPRESSION_TOKENS",
    "MAX_EXPRESSION_PARENS",
    "check_tree_size",
    "task_id_problem",
    "json_depth_exceeds",
]

MAX_TREE_BYTES = 1_048_576
MAX_TREE_DEPTH = 64
MAX_TREE_NODES = 5_000
MAX_JSON_DEPTH = 16
TASK_ID_MIN = 1
TASK_ID_MAX = 2**31 - 1
MAX_NAME_CHARS = 255
MAX_EXPRESSION_TOKENS = 200
MAX_EXPRESSION_PARENS = 16


def check_tree_size(text: str | bytes, source: str) -> None:
    """TreeLoadError naming ``source`` when ``text`` is over :data:`MAX_TREE_BYTES` (UTF-8 bytes)."""
    if isinstance(text, str):
        if len(text) <= MAX_TREE_BYTES // 4:  # 4 bytes a character at most: no need to encode
            return
        size = len(text) if len(text) > MAX_TREE_BYTES else len(text.encode("utf-8", "surrogatepass"))
    else:
        size = len(text)
    if size > MAX_TREE_BYTES:
        raise TreeLoadError(f"{source}: {size:,} bytes, over the limit of {MAX_TREE_BYTES:,} bytes a tree "
                            "(tms_ts.limits.MAX_TREE_BYTES)")


def task_id_problem(value: Any) -> str | None:
    """Why ``value`` is not a task id (None when it is one): an int in TASK_ID_MIN..TASK_ID_MAX (int32, positive)."""
    if isinstance(value, bool) or not isinstance(value, int):
        return f"task id {value!r} is not an integer"
    if not TASK_ID_MIN <= value <= TASK_ID_MAX:
        return (f"task id {value} is out of range {TASK_ID_MIN}..{TASK_ID_MAX} (the interface types carry int32: "
                "tms_msg/TaskIds, std_msgs/Int32)")
    return None


def json_depth_exceeds(text: str, limit: int = MAX_JSON_DEPTH) -> bool:
    """True when the JSON ``text`` nests deeper than ``limit`` (or may: unbalanced brackets counted as nesting).

    Without recursion and without a Python loop over the characters: strings are cut out, brackets kept, and
    innermost pairs removed one level per pass (``str.replace``), at most ``limit`` passes. Unmatched brackets
    left over count as levels too, so a text this passes nests at most ``limit`` deep (json.loads' C scanner
    recurses once a level).
    """
    import re

    # escapes out first (so an escaped quote is no quote), then every other piece between quotes is a string: linear,
    # where a regular expression for strings backtracks quadratically over unterminated ones
    outside = "".join(re.sub(r"\\.", "", text, flags=re.DOTALL).split('"')[0::2])
    brackets = re.sub(r"[^\[\]{}]+", "", outside).translate(_BRACKETS)
    passes = 0
    while brackets:
        shorter = brackets.replace("()", "")
        if shorter == brackets:
            break  # unmatched brackets only
        brackets, passes = shorter, passes + 1
        if passes > limit:
            return True
    return passes + len(brackets) > limit


_BRACKETS = str.maketrans("[{]}", "(())")
