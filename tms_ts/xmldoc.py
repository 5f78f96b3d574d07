"""A small XML reader that keeps the line and column of every element.

``xml.etree`` drops source positions, and the loader must name the position of a bad node, so this
module builds a minimal element tree with :mod:`xml.parsers.expat` (the standard library's parser;
no DTD or entity expansion beyond the XML built-ins). Task XML stored in the DB is one line long
(the original ``task_generator`` strips newlines), so the column matters as much as the line.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.parsers import expat

from tms_ts.errors import TreeLoadError

__all__ = ["Element", "parse_xml"]


@dataclass
class Element:
    """One XML element: tag, attributes in document order, children and 1-based line/column."""

    tag: str
    attrib: dict[str, str]
    line: int
    column: int
    children: list[Element] = field(default_factory=list)

    @property
    def where(self) -> str:
        return f"line {self.line}, column {self.column}"


def parse_xml(text: str, source: str = "<xml>") -> Element:
    """Parse ``text`` into an :class:`Element` tree; malformed XML raises TreeLoadError with the position."""
    if not isinstance(text, str) or not text.strip():
        raise TreeLoadError(f"{source}: empty behavior-tree document")
    parser = expat.ParserCreate()
    stack: list[Element] = []
    roots: list[Element] = []

    def start(tag: str, attrs: dict[str, str]) -> None:
        el = Element(tag, dict(attrs), parser.CurrentLineNumber, parser.CurrentColumnNumber + 1)
        if stack:
            stack[-1].children.append(el)
        else:
            roots.append(el)
        stack.append(el)

    def end(_tag: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        raise TreeLoadError(
            f"{source}: malformed XML at line {exc.lineno}, column {exc.offset + 1}: {expat.ErrorString(exc.code)}"
        ) from None
    return roots[0]
