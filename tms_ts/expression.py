"""A safe evaluator for ConditionalExpression strings with ExprTk's operators (no ``eval``, no attribute access).

The original node substitutes blackboard values into the text and hands it to ExprTk (tms_ts.bt.custom,
ConditionalExpression). Here the text is tokenised and parsed once into a small AST (:func:`compile_expression`),
then evaluated against a resolver for identifiers. The grammar is the part of ExprTk's that a substituted text can
hold, with ExprTk's precedence (checked against the ExprTk the original ships), lowest first::

    or:    and ( ("or" | "|") and )*
    and:   cmp ( ("and" | "&") cmp )*
    cmp:   sum ( ("==" | "=" | "!=" | "<>" | "<" | "<=" | ">" | ">=") sum )*     (chains: 1 < 2 == 1)
    sum:   prod ( ("+" | "-") prod )*
    prod:  unary ( ("*" | "/" | "%") unary )*
    unary: ("-" | "+") unary | power
    power: atom ( "^" unary )?                                                (-2^2 = -4, 2^3^2 = 512)
    atom:  number | 'string' | true | false | pi | epsilon | inf | identifier | "(" or ")" | not "(" or ")"

As in ExprTk: booleans are numbers (true = 1, false = 0), the result is true when non-zero (NaN too), ``x/0``
is inf and ``x%0`` NaN. Strings (single quotes) compare with strings and concatenate with ``+``; mixing a
string with a number is an :class:`ExpressionError`, as ExprTk refuses to compile it. What ExprTk does not
parse is refused too: double quotes, ``!``, ``&&``, ``||``, ``not`` without parentheses.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from tms_ts.errors import ExpressionError
from tms_ts.limits import MAX_EXPRESSION_PARENS, MAX_EXPRESSION_TOKENS

__all__ = ["Expression", "compile_expression", "evaluate"]

_TOKEN_RE = re.compile(
    r"""\s*(?:
        (?P<num>\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?
      | (?P<str>'[^']*')
      | (?P<op>==|!=|<>|<=|>=|[-+*/%^<>=()&|])
      | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
    )""",
    re.VERBOSE,
)
_WORD_OPS = {"and": "and", "or": "or", "not": "not", "true": "true", "false": "false"}
_CONSTANTS = {"pi": math.pi, "epsilon": 2.220446049250313e-16, "inf": math.inf}


@dataclass(frozen=True)
class _Tok:
    kind: str  # num | str | op | name | end
    text: str
    pos: int


def _tokenise(text: str) -> list[_Tok]:
    tokens: list[_Tok] = []
    pos = depth = 0
    while True:
        while pos < len(text) and text[pos].isspace():
            pos += 1
        if pos >= len(text):
            break
        m = _TOKEN_RE.match(text, pos)
        if m is None or m.end() == pos:
            hint = " (ExprTk has no double-quoted strings)" if text[pos] == '"' else ""
            raise ExpressionError(f"expression {text!r}: unexpected character {text[pos]!r} at position {pos}{hint}")
        kind = m.lastgroup or "op"
        tok = m.group(0).strip()
        if kind == "num":
            tok = m.group(0).strip()
        if kind == "name" and tok.lower() in _WORD_OPS:
            kind, tok = "op", tok.lower()
        tokens.append(_Tok(kind, tok, pos))
        pos = m.end()
        # parsing and evaluating recurse: bound the text before they run (tms_ts.limits)
        if len(tokens) > MAX_EXPRESSION_TOKENS:
            raise ExpressionError(f"expression {text[:80]!r}...: more than {MAX_EXPRESSION_TOKENS} tokens "
                                  "(tms_ts.limits.MAX_EXPRESSION_TOKENS)")
        if tok == "(":
            depth += 1
            if depth > MAX_EXPRESSION_PARENS:
                raise ExpressionError(
                    f"expression {text[:80]!r}...: parentheses nested deeper than "
                    f"{MAX_EXPRESSION_PARENS} at position {pos} (tms_ts.limits.MAX_EXPRESSION_PARENS)"
                )
        elif tok == ")":
            depth -= 1
    tokens.append(_Tok("end", "", len(text)))
    return tokens


# AST nodes are tuples: ("num", v) ("str", s) ("var", name) ("un", op, a) ("bin", op, a, b)


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.toks = _tokenise(text)
        self.i = 0

    def peek(self) -> _Tok:
        return self.toks[self.i]

    def take(self) -> _Tok:
        tok = self.toks[self.i]
        self.i += 1
        return tok

    def error(self, tok: _Tok, what: str) -> ExpressionError:
        shown = tok.text or "end of expression"
        return ExpressionError(f"expression {self.text!r}: {what} at position {tok.pos} ({shown!r})")

    def parse(self) -> tuple:
        if self.peek().kind == "end":
            raise self.error(self.peek(), "empty expression")
        node = self.or_()
        if self.peek().kind != "end":
            raise self.error(self.peek(), "unexpected token")
        return node

    def _is(self, *ops: str) -> bool:
        tok = self.peek()
        return tok.kind == "op" and tok.text in ops

    def or_(self) -> tuple:
        node = self.and_()
        while self._is("or", "|"):
            self.take()
            node = ("bin", "or", node, self.and_())
        return node

    def and_(self) -> tuple:
        node = self.cmp()
        while self._is("and", "&"):
            self.take()
            node = ("bin", "and", node, self.cmp())
        return node

    def cmp(self) -> tuple:
        node = self.sum()
        while self._is("==", "=", "!=", "<>", "<", "<=", ">", ">="):
            text = self.take().text
            op = {"=": "==", "<>": "!="}.get(text, text)
            node = ("bin", op, node, self.sum())
        return node

    def sum(self) -> tuple:
        node = self.prod()
        while self._is("+", "-"):
            op = self.take().text
            node = ("bin", op, node, self.prod())
        return node

    def prod(self) -> tuple:
        node = self.unary()
        while self._is("*", "/", "%"):
            op = self.take().text
            node = ("bin", op, node, self.unary())
        return node

    def unary(self) -> tuple:
        if self._is("-"):
            self.take()
            return ("un", "-", self.unary())
        if self._is("+"):
            self.take()
            return self.unary()
        return self.power()

    def power(self) -> tuple:
        node = self.atom()
        if self._is("^"):
            self.take()
            node = ("bin", "^", node, self.unary())
        return node

    def atom(self) -> tuple:
        tok = self.take()
        if tok.kind == "num":
            return ("num", float(tok.text))
        if tok.kind == "str":
            return ("str", tok.text[1:-1])
        if tok.kind == "name":
            if tok.text in _CONSTANTS:
                return ("num", _CONSTANTS[tok.text])
            return ("var", tok.text)
        if tok.kind == "op" and tok.text in ("true", "false"):
            return ("num", 1.0 if tok.text == "true" else 0.0)
        if tok.kind == "op" and tok.text == "not":
            if not self._is("("):
                raise self.error(self.peek(), "'not' is ExprTk's function: expected '(' after it")
            self.take()
            node = self.or_()
            if not self._is(")"):
                raise self.error(self.peek(), "missing ')'")
            self.take()
            return ("un", "not", node)
        if tok.kind == "op" and tok.text == "(":
            node = self.or_()
            if not self._is(")"):
                raise self.error(self.peek(), "missing ')'")
            self.take()
            return node
        raise self.error(tok, "expected a value")


class Expression:
    """A compiled expression; ``evaluate(resolve)`` looks identifiers up through ``resolve(name)``."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.ast = _Parser(text).parse()
        self.names = sorted(_names(self.ast))

    def evaluate(self, resolve: Callable[[str], Any]) -> bool:
        """True when the expression is non-zero; ExpressionError on a type mismatch or bad name."""
        value = self._eval(self.ast, resolve)
        if isinstance(value, str):
            raise ExpressionError(f"expression {self.text!r}: result is the string {value!r}, not a truth value")
        return value != 0.0

    def _eval(self, node: tuple, resolve: Callable[[str], Any]) -> float | str:
        kind = node[0]
        if kind == "num" or kind == "str":
            return node[1]
        if kind == "var":
            return _as_value(self.text, node[1], resolve(node[1]))
        if kind == "un":
            a = self._eval(node[2], resolve)
            if isinstance(a, str):
                raise ExpressionError(f"expression {self.text!r}: '{node[1]}' applied to the string {a!r}")
            return (0.0 if a != 0.0 else 1.0) if node[1] == "not" else -a
        op = node[1]
        if op == "and":
            a = self._truth(node[2], resolve)
            return 1.0 if a and self._truth(node[3], resolve) else 0.0
        if op == "or":
            a = self._truth(node[2], resolve)
            return 1.0 if a or self._truth(node[3], resolve) else 0.0
        a = self._eval(node[2], resolve)
        b = self._eval(node[3], resolve)
        if isinstance(a, str) != isinstance(b, str):
            raise ExpressionError(f"expression {self.text!r}: cannot apply '{op}' to {a!r} and {b!r}")
        if op == "==":
            return 1.0 if a == b else 0.0
        if op == "!=":
            return 1.0 if a != b else 0.0
        if op in ("<", "<=", ">", ">="):
            result = {"<": a < b, "<=": a <= b, ">": a > b, ">=": a >= b}[op]  # type: ignore[operator]
            return 1.0 if result else 0.0
        if isinstance(a, str):
            if op == "+":
                return a + b  # type: ignore[operator]
            raise ExpressionError(f"expression {self.text!r}: cannot apply '{op}' to strings")
        return _arith(op, a, b)  # type: ignore[arg-type]

    def _truth(self, node: tuple, resolve: Callable[[str], Any]) -> bool:
        v = self._eval(node, resolve)
        if isinstance(v, str):
            raise ExpressionError(f"expression {self.text!r}: the string {v!r} is not a truth value")
        return v != 0.0


def _arith(op: str, a: float, b: float) -> float:
    """IEEE arithmetic as ExprTk's doubles: x/0 = +-inf (0/0 NaN), x%0 = NaN (fmod), overflowing ^ = inf."""
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if op == "^":
        try:
            return math.pow(a, b)
        except OverflowError:
            return math.inf
        except ValueError:
            return math.nan
    if b == 0.0:
        if op == "%" or a == 0.0 or math.isnan(a):
            return math.nan
        return math.copysign(math.inf, a) * math.copysign(1.0, b)
    return a / b if op == "/" else math.fmod(a, b)


def _as_value(text: str, name: str, value: Any) -> float | str:
    if isinstance(value, bool):
        return 1.0 if value else 0.0
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):
        return value
    raise ExpressionError(f"expression {text!r}: '{name}' has unsupported type {type(value).__name__}")


def _names(node: tuple) -> set[str]:
    if node[0] == "var":
        return {node[1]}
    if node[0] in ("un",):
        return _names(node[2])
    if node[0] == "bin":
        return _names(node[2]) | _names(node[3])
    return set()


_CACHE: dict[str, Expression] = {}


def compile_expression(text: str) -> Expression:
    """Parse ``text`` once (cached); ExpressionError names the position of a syntax error."""
    expr = _CACHE.get(text)
    if expr is None:
        expr = Expression(text)
        if len(_CACHE) < 4096:
            _CACHE[text] = expr
    return expr


def evaluate(text: str, variables: dict[str, Any]) -> bool:
    """Evaluate ``text`` with ``variables``; an unknown name is an ExpressionError."""

    def resolve(name: str) -> Any:
        if name not in variables:
            raise ExpressionError(f"expression {text!r}: unknown name '{name}'")
        return variables[name]

    return compile_expression(text).evaluate(resolve)
