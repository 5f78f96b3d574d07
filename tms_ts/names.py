"""The names a leaf turns into ROS names and DB look-ups, checked where they enter (issue 38).

A ``LeafNode<Machine>``'s ``model_name`` and ``subtask_name`` become the action ``/<model_name>/<subtask_name>`` and
the topics ``/<model_name>/subtask_outcome``, ``/<model_name>/lock`` and ``/<model_name>/emg_stop``; rclpy raises
``ValueError`` creating a client or publisher for a name ROS does not allow (a full-width underscore ``＿``, as one
of the original's task files has in ``d37pxi_24＿``; a space; a token starting with a digit), and inside the
manager's tick that ended the process. So both are checked by rclpy's own validator
(:func:`rclpy.validate_full_topic_name`, rcl's rules: ``/``-separated tokens of ``[A-Za-z0-9_]``, not starting
with a digit, no ``//``, within rmw's length) when the tree is loaded. ``record_name`` is no ROS name (it travels in
the goal and names a DB record): it must be printable text without surrounding spaces, at most
:data:`tms_ts.limits.MAX_NAME_CHARS` characters, and not empty for a subtask that reads a record. A ``{key}``
record_name is checked when the leaf reads it (:mod:`tms_ts.leaf`).

rclpy is imported when a name is first checked (its validator needs no ROS context), so importing this module
stays ROS-free.
"""

from __future__ import annotations

from tms_ts.limits import MAX_NAME_CHARS

__all__ = ["ros_name_problem", "leaf_names_problem", "record_name_problem"]

#: the longest name rcl derives from an action name (``<action>/_action/cancel_goal``): checked for rmw's length
_ACTION_SUFFIXES = ("/_action/cancel_goal", "/_action/get_result", "/_action/send_goal", "/_action/feedback",
                    "/_action/status")


def ros_name_problem(name: str) -> str | None:
    """Why the fully qualified ``name`` is no valid ROS topic / action name (None when it is), in one line."""
    from rclpy.exceptions import NameValidationException
    from rclpy.validate_full_topic_name import validate_full_topic_name

    try:
        validate_full_topic_name(name)
    except NameValidationException as exc:
        lines = str(exc).splitlines()
        reason = lines[0].rstrip(":") if lines else "invalid name"
        where = ""
        if len(lines) >= 3 and "^" in lines[2]:
            index = lines[2].index("^") - 3  # the caret line is indented 3 + index
            if 0 <= index < len(name):
                where = f" at character {index + 1} ({name[index]!r}, U+{ord(name[index]):04X})"
        return f"{reason}{where}"
    return None


def leaf_names_problem(model_name: str, subtask_name: str) -> str | None:
    """Why a leaf's ``model_name`` / ``subtask_name`` (leading and trailing ``/`` stripped) cannot name its action and
    machine topics, naming the port and its value; None when they can."""
    for port, value in (("model_name", model_name), ("subtask_name", subtask_name)):
        if not value:
            return f"port '{port}' must not be empty"
        if len(value) > MAX_NAME_CHARS:
            return f"port '{port}' is {len(value)} characters long, over the limit of {MAX_NAME_CHARS} (tms_ts.limits)"
    problem = ros_name_problem(f"/{model_name}")
    if problem:
        return f"port 'model_name' = {model_name!r} is no valid ROS name: {problem}"
    action = f"/{model_name}/{subtask_name}"
    problem = ros_name_problem(action)
    if problem:
        return f"port 'subtask_name' = {subtask_name!r}: action name {action!r} is no valid ROS name: {problem}"
    for suffix in _ACTION_SUFFIXES:
        problem = ros_name_problem(action + suffix)
        if problem:
            return f"action name {action!r}: its topic {action + suffix!r} is no valid ROS name: {problem}"
    return None


def record_name_problem(record_name: str, *, required: bool) -> str | None:
    """Why ``record_name`` cannot name a DB record (None when it can); empty is allowed unless ``required``."""
    if not isinstance(record_name, str):
        return f"port 'record_name' = {record_name!r} is not text"
    if not record_name:
        return "port 'record_name' is empty, and this subtask reads a record" if required else None
    if len(record_name) > MAX_NAME_CHARS:
        return (
            f"port 'record_name' is {len(record_name)} characters long, "
            f"over the limit of {MAX_NAME_CHARS} (tms_ts.limits)"
        )
    if record_name != record_name.strip():
        return f"port 'record_name' = {record_name!r} has leading or trailing spaces"
    if not record_name.isprintable():
        bad = next(c for c in record_name if not c.isprintable())
        return f"port 'record_name' = {record_name!r} holds a control character (U+{ord(bad):04X})"
    return None
