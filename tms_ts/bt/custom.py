"""The global-blackboard and utility nodes of ROS2-TMS (reference §5), as the original's C++ nodes behave.

Global-blackboard nodes reach the DB through ``ctx.store`` (a tms_db store): documents in
``parameter`` looked up by ``record_name`` only. Local-blackboard nodes work on ``ctx.blackboard`` with
BehaviorTree.CPP 3.8.7's typing rules (:mod:`tms_ts.blackboard`). Every port is the original's
``InputPort<std::string>`` (key-naming ports too: ``key="X"`` names X) except SetLocalBlackboard's
``output_key`` (untyped).

=============================  ==========  =====================================================
node                           kind        behaviour
=============================  ==========  =====================================================
BlackboardValueReaderMongo     action      record field -> local key as bool/int/long/double/string;
                                           missing, other BSON type, or set() refused -> FAILURE
MongoValueWriter               action      text -> bool/double/int/str, ``$set`` + timestamps;
                                           record missing: retried 5 x 100 ms (RUNNING) -> FAILURE
ConditionalExpression          condition   the original's text substitution of local entries, then an
                                           ExprTk-compatible evaluation (tms_ts.expression)
ConditionalExpressionBool      condition   legacy: only bool entries are names; unknown -> FAILURE
KeepRunningUntilFlgup          decorator   child SUCCESS -> SUCCESS only when ``key`` holds bool true;
                                           any other type: error (the original throws)
SetLocalBlackboard             action      typed write ("true" -> bool, "12" -> int, ...); legacy
                                           port ``key`` is accepted in place of ``value``
SetLocalBlackboardWithCounter  action      "load_path_0" + counter "3" -> "load_path_3"
Counter                        action      counter read as text, + 1, written back as text
BlackboardValueChecker         condition   SUCCESS if ``key`` holds bool/int/double/string
WaitForClick                   action      non-blocking wait for a confirmation on a ROS topic
=============================  ==========  =====================================================
"""

from __future__ import annotations

import re
from typing import Any

from tms_db import RecordNotFound
from tms_ts.blackboard import (
    BOOL,
    DOUBLE,
    INT,
    MISSING,
    STRING,
    BlackboardError,
    ctype_of,
    mongo_typed_from_text,
    stoi_prefix,
    typed_from_text,
)
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


def _inputs(node: Any, *ports: str) -> tuple[str, ...] | None:
    """The original's ``getInput<std::string>`` of each port; None (and why, in feedback) when one fails."""
    try:
        return tuple(node.get_input(port) for port in ports)
    except TreeRuntimeError as exc:
        node.feedback_message = f"missing required input: {exc}"
        return None


def _never_set(node: Any, key: str) -> TreeRuntimeError:
    return TreeRuntimeError(
        f"{node.describe()}: blackboard key '{key}' was declared by a port but never set; the original reads its "
        "type (Any::type() of an empty entry: undefined behaviour in BehaviorTree.CPP 3.8)")


def _text_of(node: Any, key: str) -> Any:
    """The original's ``blackboard->get(key, std::string&)``: the entry cast to text (true -> "1"); MISSING if none."""
    try:
        return node.ctx.blackboard.cast(key, STRING)
    except (BlackboardError, ValueError) as exc:
        raise TreeRuntimeError(f"{node.describe()}: blackboard key '{key}': {exc}") from None


class BlackboardValueReaderMongo(ActionNode):
    """Copies field ``mongo_param_name`` of global record ``mongo_record_name`` into local key ``output_port``.

    As the original: a BSON string / int32 / int64 / double / bool becomes a std::string / int / long / double /
    bool entry (``blackboard->set``); another type is FAILURE; a set() BT.CPP refuses (the key was declared
    ``std::string`` by a ``{key}`` port and the field is a number, say) is caught and FAILURE, naming the rule.
    """

    PORTS = {
        "output_port": Port("key", description="local blackboard key to write"),
        "mongo_record_name": Port("str", description="record_name of the global-blackboard document"),
        "mongo_param_name": Port("str", description="field of that document"),
    }

    def _tick(self) -> Status:
        inputs = _inputs(self, "output_port", "mongo_record_name", "mongo_param_name")
        if inputs is None:
            return FAILURE
        key, record, field = inputs
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
        try:
            self.ctx.blackboard.set(key, value, ctype_of(value))
        except BlackboardError as exc:
            self.feedback_message = f"{record}.{field} = {value!r} -> blackboard key '{key}': {exc}"
            self.ctx.failures.append(f"{self.describe()}: {self.feedback_message}")
            return FAILURE
        self.feedback_message = f"{field}={value!r}"
        return SUCCESS


class MongoValueWriter(StatefulNode):
    """``$set`` field ``mongo_param_name`` of record ``mongo_record_name`` to ``input_value`` (typed text).

    A missing record is retried ``RETRIES`` times, ``RETRY_S`` apart, returning RUNNING in between
    (the original slept inside the tick), then FAILURE.
    """

    PORTS = {
        "input_value": Port("str", description="value as text: true/false->bool, '.'->double, int, else str"),
        "mongo_record_name": Port("str"),
        "mongo_param_name": Port("str"),
    }
    RETRIES = 5
    RETRY_S = 0.1

    def _attempt(self) -> Status:
        inputs = _inputs(self, "input_value", "mongo_record_name", "mongo_param_name")
        if inputs is None:
            return FAILURE
        text, record, field = inputs
        try:
            value = mongo_typed_from_text(text)
        except ValueError as exc:
            self.feedback_message = f"error converting input_value {text!r}: {exc}"
            return FAILURE
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


_WORD_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_STRING_COMPARISON_RE = re.compile(r'"([^"]*)"\s*(==|!=)\s*"([^"]*)"')
_RESERVED = frozenset({"and", "or", "true", "false"})


_SPLIT_CACHE: dict[str, tuple[tuple[bool, str], ...]] = {}


def _split_words(expr: str) -> tuple[tuple[bool, str], ...]:
    """The original's scan of the text: (True, word) for each word it looks up, (False, text) between (cached)."""
    parts = _SPLIT_CACHE.get(expr)
    if parts is None:
        out: list[tuple[bool, str]] = []
        pos, n, start = 0, len(expr), 0
        while pos < n:
            c = expr[pos]
            if c == '"' or not (c.isascii() and (c.isalpha() or c == "_")):
                pos += 1
                continue
            if start < pos:
                out.append((False, expr[start:pos]))
            word = _WORD_RE.match(expr, pos).group(0)  # type: ignore[union-attr]
            out.append((True, word))
            pos = start = pos + len(word)
        if start < n:
            out.append((False, expr[start:]))
        parts = tuple(out)
        if len(_SPLIT_CACHE) < 4096:
            _SPLIT_CACHE[expr] = parts
    return parts


class ConditionalExpression(ActionNode):
    """SUCCESS when the expression over local-blackboard entries is non-zero, else FAILURE; as the original.

    The original (``conditional_expression.hpp``) rewrites the text, then hands it to ExprTk:

    1. every word except ``and or true false`` (inside quotes too) is replaced by its entry: a string by the
       string in double quotes, a bool by ``true``/``false``, an int by its digits, a double by
       ``std::to_string`` (``%f``: 6 decimals); an entry of another type (long, unsigned) stays a name,
       which ExprTk does not know; a word that is no entry becomes ``""``;
    2. each ``"a" == "b"`` / ``"a" != "b"`` left is replaced by ``true``/``false``;
    3. ExprTk evaluates the rest (here :mod:`tms_ts.expression`, its operators); a double quote still there
       fails to parse. So a string entry compares only with a string: ``FLG == true`` over the text "true" is
       ``"true" == true``, FAILURE; ``FLG == "true"`` is SUCCESS. ``not`` is a word and becomes ``""``.

    A parse or evaluation error is FAILURE with the reason and the rewritten text in ``feedback_message``.
    """

    KIND = "Condition"
    PORTS = {"conditional_expression": Port("str")}

    def substitute(self, expr: str) -> str:
        """Steps 1 and 2: the text the original hands to ExprTk."""
        bb = self.ctx.blackboard
        out: list[str] = []
        for is_word, part in _split_words(expr):
            if not is_word or part in _RESERVED:
                out.append(part)
                continue
            entry = bb.get_any(part)
            if entry is None:
                out.append('""')
            elif entry.empty:
                raise _never_set(self, part)
            elif entry.vtype == STRING:
                out.append(f'"{entry.value}"')
            elif entry.vtype == BOOL:
                out.append("true" if entry.value else "false")
            elif entry.vtype == INT:
                out.append(str(entry.value))
            elif entry.vtype == DOUBLE:
                out.append(f"{entry.value:f}")
            else:
                out.append(part)
        text = "".join(out)
        while (m := _STRING_COMPARISON_RE.search(text)) is not None:
            a, op, b = m.groups()
            text = text[:m.start()] + ("true" if (a == b) == (op == "==") else "false") + text[m.end():]
        return text

    def _unknown(self, name: str) -> Any:
        entry = self.ctx.blackboard.get_any(name)
        why = f"blackboard key '{name}' holds a {entry.vtype}, which the original does not substitute (bool, int, " \
              "double and string only)" if entry is not None else f"'{name}' is no name ExprTk knows"
        raise ExpressionError(f"undefined symbol '{name}': {why}")

    def _tick(self) -> Status:
        inputs = _inputs(self, "conditional_expression")
        if inputs is None:
            return FAILURE
        text = self.substitute(inputs[0])
        try:
            result = compile_expression(text).evaluate(self._unknown)
        except ExpressionError as exc:
            self.feedback_message = f"{exc} (ExprTk input {text!r})"
            return FAILURE
        self.feedback_message = "true" if result else "false"
        return SUCCESS if result else FAILURE


class ConditionalExpressionBool(ConditionalExpression):
    """Legacy: only *bool* entries are names; any other or unknown name -> FAILURE."""

    PORTS = {"conditional_expression_bool": Port("str")}

    def _resolve(self, name: str) -> Any:
        value = self.ctx.blackboard.get(name)
        if not isinstance(value, bool):
            raise ExpressionError(
                f"'{name}' is not a bool blackboard entry (got {value if value is not MISSING else 'nothing'!r})"
            )
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
    """Child FAILURE -> FAILURE; child SUCCESS -> reset, then SUCCESS if ``key`` holds bool true, RUNNING if it is
    false or absent. Any other type is an error, as the original throws "Unsupported type for key [..]": the
    *string* "true" that BT.CPP 3.8's SetBlackboard writes into a key no typed port declared is refused (the
    original's manager then ends the task "canceled"; here the task ends FAILURE with this node's message).
    """

    PORTS = {"key": Port("key", description="local blackboard flag (bool)")}

    def _tick(self) -> Status:
        key = self.port_key("key")  # read before the child is ticked, as the original
        status = self.child.execute_tick()
        if status is RUNNING:
            return RUNNING
        self.halt_child()
        if status is FAILURE:
            return FAILURE
        entry = self.ctx.blackboard.get_any(key)
        if entry is None:
            return RUNNING
        if entry.empty:
            raise _never_set(self, key)
        if entry.vtype == BOOL:
            return SUCCESS if entry.value else RUNNING
        why = ""
        if entry.vtype == STRING:
            why = (" BehaviorTree.CPP 3.8 keeps text as text: SetBlackboard writes its value as a std::string, and "
                   "Blackboard::set() of a string into a key no typed port declared creates an untyped entry holding "
                   "the string (blackboard.h:110-117); it parses text into bool only for an entry a typed port "
                   "declared (blackboard.h:127-139). Write the flag with SetLocalBlackboard (\"true\" -> bool).")
        raise TreeRuntimeError(
            f"{self.describe()}: Unsupported type for key [{key}]: it holds {entry.vtype} {entry.value!r}, and the "
            f"original's KeepRunningUntilFlgup accepts only a bool (Any::type() == typeid(bool)).{why}")


class SetLocalBlackboard(ActionNode):
    """Writes ``value`` to ``output_key`` with a type: "true" -> bool, "-12" -> int, "1.5" -> double, else string.

    ``value`` is the original's ``InputPort<std::string>``: ``{other}`` reads entry other as text (a bool as
    "1", a double as "1.500000"), then types it. The write is BT.CPP's set(): into a key a ``{key}`` port
    declared ``std::string`` an int is refused. Legacy XML names the value port ``key``.
    """

    PORTS = {
        "value": Port("str", None, "value to write (text is typed)"),
        "key": Port("str", None, "legacy name of 'value'"),
        "output_key": Port("key", typed=False),
    }

    @classmethod
    def check_ports(cls, attrs: dict[str, str]) -> str | None:
        if "value" not in attrs and "key" not in attrs:
            return "needs port 'value' (or the legacy 'key')"
        return None

    def _tick(self) -> Status:
        output_key = self.port_key("output_key")
        text = self.get_input("value")
        if text is None:
            text = self.get_input("key")
        value, ctype = typed_from_text(text)
        self.bb_set(output_key, value, ctype)
        return SUCCESS


class SetLocalBlackboardWithCounter(ActionNode):
    """Replaces the trailing digits of the text at ``key`` by the text at ``counter_key`` ("load_path_0", "3" ->
    "load_path_3"); either entry absent -> FAILURE. Both are read as text (an int counter 3 -> "3")."""

    PORTS = {"key": Port("key"), "counter_key": Port("key")}
    _DIGITS = re.compile(r"\d+\Z")

    def _tick(self) -> Status:
        key, counter_key = self.port_key("key"), self.port_key("counter_key")
        base = _text_of(self, key)
        counter = _text_of(self, counter_key) if base is not MISSING else MISSING  # in the original's order
        if base is MISSING or counter is MISSING:
            missing = key if base is MISSING else counter_key
            self.feedback_message = f"blackboard key '{missing}' not set"
            return FAILURE
        self.bb_set(key, self._DIGITS.sub("", base) + counter, STRING)
        return SUCCESS


class Counter(ActionNode):
    """Reads ``key`` as text, parses it as the original does (``std::stoi``), adds one and writes it back *as text*.

    The write is BT.CPP's set() of a string: an entry set() made typed (an int read from the DB, say) refuses it.
    """

    PORTS = {"key": Port("key")}

    def _tick(self) -> Status:
        key = self.port_key("key")
        text = _text_of(self, key)
        if text is MISSING:
            self.feedback_message = f"blackboard key '{key}' not found"
            return FAILURE
        number = stoi_prefix(text)
        if number is None or not -(2**31) <= number < 2**31:
            self.feedback_message = f"blackboard key '{key}' = {text!r} is not an integer (std::stoi)"
            return FAILURE
        self.bb_set(key, str(number + 1), STRING)
        return SUCCESS


class BlackboardValueChecker(ActionNode):
    """SUCCESS when ``key`` holds a bool, int, double or string (the value goes to feedback); else FAILURE."""

    KIND = "Condition"
    PORTS = {"key": Port("key")}

    def _tick(self) -> Status:
        inputs = _inputs(self, "key")
        if inputs is None:
            return FAILURE
        key = inputs[0]
        entry = self.ctx.blackboard.get_any(key)
        if entry is None:
            self.feedback_message = f"no value found for key '{key}'"
            return FAILURE
        if entry.empty:
            raise _never_set(self, key)
        self.feedback_message = f"{key}={entry.value!r}"
        if entry.vtype not in (BOOL, INT, DOUBLE, STRING):
            self.feedback_message = f"unsupported type {entry.vtype} for key '{key}'"
            return FAILURE
        return SUCCESS


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
