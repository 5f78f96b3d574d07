"""The global-blackboard and utility nodes of ROS2-TMS (reference §5), BT.CPP-compatible ports.

Global-blackboard nodes reach the DB through ``ctx.store`` (a tms_db store): documents in
``parameter`` looked up by ``record_name`` only. Local-blackboard nodes work on ``ctx.blackboard``.

=============================  ==========  =====================================================
node                           kind        behaviour
=============================  ==========  =====================================================
BlackboardValueReaderMongo     action      record field -> local key, type kept; missing -> FAILURE
MongoValueWriter               action      text -> bool/float/int/str, ``$set`` + timestamps;
                                           record missing: retried 5 x 100 ms (RUNNING) -> FAILURE
ConditionalExpression          condition   identifiers = local entries (unknown -> ''), safe eval
ConditionalExpressionBool      condition   legacy: only bool entries are names; unknown -> FAILURE
KeepRunningUntilFlgup          decorator   child SUCCESS -> SUCCESS only when bool ``key`` is true
SetLocalBlackboard             action      typed write ("true" -> bool, "12" -> int, ...); legacy
                                           port ``key`` is accepted in place of ``value``
SetLocalBlackboardWithCounter  action      "load_path_0" + counter "3" -> "load_path_3"
Counter                        action      string counter + 1, written back as string
BlackboardValueChecker         condition   SUCCESS if ``key`` holds int/float/bool/str
WaitForClick                   action      non-blocking wait for a confirmation on a ROS topic
=============================  ==========  =====================================================
"""

from __future__ import annotations

import re
from typing import Any

from tms_ts.blackboard import MISSING, mongo_typed_from_text, to_text, typed_from_text
from tms_ts.bt.core import FAILURE, RUNNING, SUCCESS, ActionNode, DecoratorNode, Port, StatefulNode, Status
from tms_ts.errors import ExpressionError, TreeRuntimeError
from tms_ts.expression import compile_expression

__all__ = ["CUSTOM_NODES", "SCALAR_TYPES"]

#: value types a blackboard entry read from the DB may have (BSON string/int32/int64/double/bool)
SCALAR_TYPES = (bool, int, float, str)


def _store(node: Any) -> Any:
    store = node.ctx.store
    if store is None:
        raise TreeRuntimeError(f"{node.describe()}: no database store configured for this task")
    return store


class BlackboardValueReaderMongo(ActionNode):
    """Copies field ``mongo_param_name`` of global record ``mongo_record_name`` into local key ``output_port``."""

    PORTS = {
        "output_port": Port("key", description="local blackboard key to write"),
        "mongo_record_name": Port("str", description="record_name of the global-blackboard document"),
        "mongo_param_name": Port("str", description="field of that document"),
    }

    def _tick(self) -> Status:
        from tms_db.errors import RecordNotFound

        record = self.get_input("mongo_record_name")
        field = self.get_input("mongo_param_name")
        try:
            doc = _store(self).get_record(record)
        except RecordNotFound:
            self.feedback_message = f"global-blackboard record '{record}' not found"
            return FAILURE
        value = doc.get(field, MISSING)
        if value is MISSING:
            self.feedback_message = f"record '{record}' has no field '{field}'"
            return FAILURE
        if not isinstance(value, SCALAR_TYPES):
            self.feedback_message = f"record '{record}' field '{field}' has unsupported type {type(value).__name__}"
            return FAILURE
        self.set_output("output_port", value)
        self.feedback_message = f"{field}={value!r}"
        return SUCCESS


class MongoValueWriter(StatefulNode):
    """``$set`` field ``mongo_param_name`` of record ``mongo_record_name`` to ``input_value`` (typed text).

    A missing record is retried ``RETRIES`` times, ``RETRY_S`` apart, returning RUNNING in between
    (the original slept inside the tick), then FAILURE.
    """

    PORTS = {
        "input_value": Port("any", description="value; text converted true/false->bool, '.'->float, int, str"),
        "mongo_record_name": Port("str"),
        "mongo_param_name": Port("str"),
    }
    RETRIES = 5
    RETRY_S = 0.1

    def _value(self) -> Any:
        value = self.get_input("input_value")
        return mongo_typed_from_text(value) if isinstance(value, str) else value

    def _attempt(self) -> Status:
        from tms_db.errors import RecordNotFound

        record = self.get_input("mongo_record_name")
        field = self.get_input("mongo_param_name")
        value = self._value()
        try:
            _store(self).set_fields(record, {field: value})
        except RecordNotFound:
            self.attempts += 1
            if self.attempts >= self.RETRIES:
                self.feedback_message = f"global-blackboard record '{record}' not found after {self.attempts} attempts"
                return FAILURE
            self.next_try = self.ctx.clock() + self.RETRY_S
            return RUNNING
        self.feedback_message = f"{record}.{field}={value!r}"
        return SUCCESS

    def on_start(self) -> Status:
        self.attempts = 0
        return self._attempt()

    def on_running(self) -> Status:
        if self.ctx.clock() < self.next_try:
            return RUNNING
        return self._attempt()


class ConditionalExpression(ActionNode):
    """SUCCESS when the expression over local-blackboard entries is non-zero, else FAILURE.

    Unknown identifiers are the empty string (as the original substituted ``''``); a syntax or type
    error is FAILURE with the reason in ``feedback_message``.
    """

    KIND = "Condition"
    PORTS = {"conditional_expression": Port("str")}

    def _resolve(self, name: str) -> Any:
        value = self.ctx.blackboard.get(name)
        return "" if value is MISSING else value

    def _tick(self) -> Status:
        try:
            expr = compile_expression(self.get_input("conditional_expression"))
            result = expr.evaluate(self._resolve)
        except ExpressionError as exc:
            self.feedback_message = str(exc)
            return FAILURE
        self.feedback_message = "true" if result else "false"
        return SUCCESS if result else FAILURE


class ConditionalExpressionBool(ConditionalExpression):
    """Legacy: only *bool* entries are names; any other or unknown name -> FAILURE."""

    PORTS = {"conditional_expression_bool": Port("str")}

    def _resolve(self, name: str) -> Any:
        value = self.ctx.blackboard.get(name)
        if not isinstance(value, bool):
            raise ExpressionError(f"'{name}' is not a bool blackboard entry (got {value if value is not MISSING else 'nothing'!r})")
        return value

    def _tick(self) -> Status:
        try:
            expr = compile_expression(self.get_input("conditional_expression_bool"))
            result = expr.evaluate(self._resolve)
        except ExpressionError as exc:
            self.feedback_message = str(exc)
            return FAILURE
        return SUCCESS if result else FAILURE


class KeepRunningUntilFlgup(DecoratorNode):
    """Child FAILURE -> FAILURE; child SUCCESS -> reset, SUCCESS only if bool ``key`` is true else RUNNING.

    A non-bool value at ``key`` (e.g. the *string* "true" written by SetBlackboard) is an error, as
    in the original ("Unsupported type"), which ends the task.
    """

    PORTS = {"key": Port("key", description="local blackboard flag (bool)")}

    def _tick(self) -> Status:
        status = self.child.execute_tick()
        if status is RUNNING:
            return RUNNING
        if status is FAILURE:
            self.halt_child()
            return FAILURE
        self.halt_child()
        key = self.port_key("key")
        value = self.ctx.blackboard.get(key)
        if value is MISSING or value is False:
            return RUNNING
        if value is True:
            return SUCCESS
        raise TreeRuntimeError(
            f"{self.describe()}: flag '{key}' must be a bool, got {type(value).__name__} {value!r} (Unsupported type)"
        )


class SetLocalBlackboard(ActionNode):
    """Writes ``value`` to ``output_key`` with a type: "true" -> bool, "-12" -> int, "1.5" -> float, else str.

    ``{other}`` copies the other entry with its type. Legacy XML names the value port ``key``.
    """

    PORTS = {
        "value": Port("any", None, "value to write (text is typed)"),
        "key": Port("any", None, "legacy name of 'value'"),
        "output_key": Port("key"),
    }

    @classmethod
    def check_ports(cls, attrs: dict[str, str]) -> str | None:
        if "value" not in attrs and "key" not in attrs:
            return "needs port 'value' (or the legacy 'key')"
        return None

    def _tick(self) -> Status:
        value = self.get_input("value")
        if value is None:
            value = self.get_input("key")
        self.set_output("output_key", typed_from_text(value) if isinstance(value, str) else value)
        return SUCCESS


class SetLocalBlackboardWithCounter(ActionNode):
    """Replaces the trailing digits of the string at ``key`` by the counter string at ``counter_key``."""

    PORTS = {"key": Port("key"), "counter_key": Port("key")}
    _DIGITS = re.compile(r"\d+$")

    def _tick(self) -> Status:
        key, counter_key = self.port_key("key"), self.port_key("counter_key")
        base, counter = self.ctx.blackboard.get(key), self.ctx.blackboard.get(counter_key)
        if base is MISSING or counter is MISSING:
            missing = key if base is MISSING else counter_key
            self.feedback_message = f"blackboard key '{missing}' not set"
            return FAILURE
        self.ctx.blackboard.set(key, self._DIGITS.sub("", to_text(base)) + to_text(counter))
        return SUCCESS


class Counter(ActionNode):
    """Parses the value at ``key`` as an integer, adds one and writes it back *as a string*."""

    PORTS = {"key": Port("key")}

    def _tick(self) -> Status:
        key = self.port_key("key")
        value = self.ctx.blackboard.get(key)
        try:
            number = int(to_text(value).strip()) if value is not MISSING else None
        except ValueError:
            number = None
        if number is None:
            self.feedback_message = f"blackboard key '{key}' = {value if value is not MISSING else 'nothing'!r} is not an integer"
            return FAILURE
        self.ctx.blackboard.set(key, str(number + 1))
        return SUCCESS


class BlackboardValueChecker(ActionNode):
    """SUCCESS when ``key`` holds an int, float, bool or string (the value goes to feedback)."""

    KIND = "Condition"
    PORTS = {"key": Port("key")}

    def _tick(self) -> Status:
        value = self.ctx.blackboard.get(self.port_key("key"))
        self.feedback_message = f"{self.port_key('key')}={value if value is not MISSING else 'nothing'!r}"
        return SUCCESS if isinstance(value, SCALAR_TYPES) else FAILURE


class WaitForClick(StatefulNode):
    """Non-blocking wait for a confirmation on the manager's confirm topic (default ``/tms_ts/confirm``).

    The prompt (``window_title: button_info``) goes to ``feedback_message`` and so to
    ``/tms_ts/status``. A ``std_msgs/String`` received after the node started decides: "yes" / "y" /
    "ok" / "true" -> SUCCESS, anything else ("no") -> FAILURE. ``"<task_id>:yes"`` answers only that
    task; a bare answer applies to every waiting WaitForClick. The original opened a blocking zenity
    dialog inside the tick.
    """

    PORTS = {
        "button_info": Port("str", "Press Yes to continue"),
        "window_title": Port("str", "Confirm"),
    }
    YES = frozenset({"yes", "y", "ok", "true", "1"})

    def on_start(self) -> Status:
        ros = self.ctx.ros
        if ros is None:
            raise TreeRuntimeError(f"{self.describe()}: WaitForClick needs the ROS side (confirm topic)")
        self.since = ros.confirm_seq()
        self.feedback_message = f"{self.get_input('window_title')}: {self.get_input('button_info')}"
        return self.on_running()

    def on_running(self) -> Status:
        for seq, text in self.ctx.ros.confirmations(self.since):
            self.since = seq
            answer = text.strip()
            if ":" in answer:
                target, _, answer = answer.partition(":")
                if target.strip() != str(self.ctx.task_id):
                    continue
            ok = answer.strip().lower() in self.YES
            self.feedback_message = f"answered {answer.strip()!r}"
            return SUCCESS if ok else FAILURE
        return RUNNING


CUSTOM_NODES: dict[str, type] = {
    "BlackboardValueReaderMongo": BlackboardValueReaderMongo,
    "MongoValueWriter": MongoValueWriter,
    "ConditionalExpression": ConditionalExpression,
    "ConditionalExpressionBool": ConditionalExpressionBool,
    "KeepRunningUntilFlgup": KeepRunningUntilFlgup,
    "SetLocalBlackboard": SetLocalBlackboard,
    "SetLocalBlackboardWithCounter": SetLocalBlackboardWithCounter,
    "Counter": Counter,
    "BlackboardValueChecker": BlackboardValueChecker,
    "WaitForClick": WaitForClick,
    "wait_for_click": WaitForClick,
}
