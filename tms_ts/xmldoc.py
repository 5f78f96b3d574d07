"""A small XML reader that keeps the line and column of every element.

``xml.etree`` drops source positions, and the loader must name the position of a bad node, so this
module builds a minimal element tree with :mod:`xml.parsers.expat` (the standard library's parser;
no DTD or entity expansion beyond the XML built-ins). Task XML stored in the DB is one line long
(the original ``task_generator`` strips newlines), so the column matters as much as the line.

The tree is built without recursion (expat's callbacks push and pop a stack), and the limits of
:mod:`tms_ts.limits` are checked as it goes: the document's size before expat sees it, the nesting depth and the
number of elements at the element that crosses them (named by its line and column), so a hostile document is
refused before any recursive code walks it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.parsers import expat

from tms_ts.errors import TreeLoadError
from tms_ts.limits import MAX_TREE_DEPTH, MAX_TREE_NODES, check_tree_size

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
    """Parse ``text`` into an :class:`Element` tree; malformed XML, or XML over a limit of :mod:`tms_ts.limits`,
    raises TreeLoadError naming ``source`` and the position."""
    if not isinstance(text, str) or not text.strip():
        raise TreeLoadError(f"{source}: empty behavior-tree document")
    check_tree_size(text, source)
    parser = expat.ParserCreate()
    stack: list[Element] = []
    roots: list[Element] = []
    count = 0

    def start(tag: str, attrs: dict[str, str]) -> None:
        nonlocal count
        count += 1
        line, column = parser.CurrentLineNumber, parser.CurrentColumnNumber + 1
        if len(stack) >= MAX_TREE_DEPTH:
            raise TreeLoadError(
                f"{source}: <{tag}> (line {line}, column {column}) is nested {len(stack) + 1} deep, over "
                f"the limit of {MAX_TREE_DEPTH} nested elements (tms_ts.limits.MAX_TREE_DEPTH)"
            )
        if count > MAX_TREE_NODES:
            raise TreeLoadError(
                f"{source}: <{tag}> (line {line}, column {column}) is element {count:,}, over the limit "
                f"of {MAX_TREE_NODES:,} elements a document (tms_ts.limits.MAX_TREE_NODES)"
            )
        el = Element(tag, dict(attrs), line, column)
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
    except UnicodeEncodeError as exc:  # a lone surrogate (e.g. "\udc00" in a JSON string) is no XML character
        raise TreeLoadError(f"{source}: character {exc.start + 1} of the document is no Unicode character "
                            f"({exc.object[exc.start]!r}): {exc.reason}") from None
    return roots[0]
