"""BehaviorTree.CPP XML (v3 / Groot-1 and v4) -> a tree of BT.CPP-semantics py_trees behaviours.

Accepted documents::

    <root main_tree_to_execute="BehaviorTree">                 <!-- v3 / Groot 1 -->
      <BehaviorTree ID="BehaviorTree"> <Sequence> <Action ID="LeafNodeZx200" .../> ... </BehaviorTree>
      <TreeNodesModel> ... </TreeNodesModel>                     <!-- palette: ignored -->
    </root>
    <root BTCPP_format="4" main_tree_to_execute="Main">        <!-- v4 -->
      <BehaviorTree ID="Main"> <Sequence> <LeafNodeZx200 .../> ... </BehaviorTree>
    </root>

In both, a node is either its own tag (``<Sequence>``) or a family tag with an ``ID`` (``<Action
ID="X">``, ``<Condition>``, ``<Control>``, ``<Decorator>``). ``<SubTree ID="T"/>`` inlines tree T:
with ``__shared_blackboard="true"`` (v3) / ``_autoremap="true"`` (v4) it shares the parent's
blackboard, otherwise each other attribute remaps a subtree key (``key="{parent_key}"``) or sets it
to a literal. Without ``main_tree_to_execute`` the document must hold exactly one BehaviorTree.

Task parameters: a task document may carry initial blackboard entries (field ``blackboard``, e.g.
``{machine: ic120_1}``; :func:`load_tree`'s ``blackboard``), set before the tree is built, so one tree serves
every machine of a kind. A port a node reads once when it is built (``LITERAL_PORTS``: a leaf's ``model_name``
and ``subtask_name``, fixed for the run as the original's leaf constructor reads them) may be a ``{key}`` of
these entries: it is resolved here, at load; a key the task does not set is a TreeLoadError naming the task, the
key, the node and its line. Other ``{key}`` ports read the blackboard at every tick as before, so
``input_value="{machine}"`` writes the parameter to the DB.

Everything is checked before anything runs: malformed XML, unknown node ids, unknown or missing
ports, literals of the wrong type, child counts, unknown or recursive subtrees, a leaf's names (ROS names for
``model_name`` / ``subtask_name``, :mod:`tms_ts.names`), and the limits of :mod:`tms_ts.limits` (size, depth and
elements of the document while it is parsed, without recursion; depth and nodes of the built tree, SubTrees
inlined, as it is built, so the build's recursion stops at ``MAX_TREE_DEPTH`` levels). Each error is a
:class:`TreeLoadError` naming the node id and its line/column. :func:`check_tree` is the same load without ROS and
DB (``tms-db task add`` refuses what the manager would refuse at start).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from typing import Any

from tms_ts.blackboard import MISSING, Blackboard, BlackboardError
from tms_ts.bt.builtins import BUILTINS
from tms_ts.bt.core import IDLE, RUNNING, BtNode, Status, TreeContext, convert
from tms_ts.bt.custom import CUSTOM_NODES
from tms_ts.errors import TreeLoadError
from tms_ts.leaf import LeafNode
from tms_ts.limits import MAX_TREE_DEPTH, MAX_TREE_NODES
from tms_ts.xmldoc import Element, parse_xml

__all__ = ["Tree", "load_tree", "check_tree", "check_task_blackboard", "node_class", "register_node", "known_ids"]

_FAMILY_TAGS = frozenset({"Action", "Condition", "Control", "Decorator"})
_SUBTREE_TAGS = frozenset({"SubTree", "SubTreePlus"})
_KEY_RE = re.compile(r"^\{([^{}]+)\}$")

_REGISTRY: dict[str, type[BtNode]] = {}


def register_node(node_id: str, cls: type[BtNode]) -> None:
    """Add a node type; a duplicate id is refused (plugins must never silently replace built-ins)."""
    if node_id in _REGISTRY and _REGISTRY[node_id] is not cls:
        raise ValueError(f"node id {node_id!r} is already registered as {_REGISTRY[node_id].__name__}")
    _REGISTRY[node_id] = cls


for _id, _cls in {**BUILTINS, **CUSTOM_NODES}.items():
    register_node(_id, _cls)


def node_class(node_id: str) -> type[BtNode] | None:
    """The class for ``node_id``; every ``LeafNode<Machine>`` id is :class:`LeafNode`."""
    cls = _REGISTRY.get(node_id)
    if cls is None and node_id.startswith("LeafNode") and len(node_id) > len("LeafNode"):
        return LeafNode
    return cls


def known_ids() -> list[str]:
    return sorted(_REGISTRY) + ["LeafNode<Machine>"]


class Tree:
    """A built task tree: ``tick()`` once per scheduler period, ``halt()`` to stop it."""

    def __init__(self, root: BtNode, ctx: TreeContext, source: str) -> None:
        self.root = root
        self.ctx = ctx
        self.source = source
        self.nodes = list(root.iter_nodes())

    @property
    def status(self) -> Status:
        return self.root.status

    @property
    def leaves(self) -> list[LeafNode]:
        return self.ctx.leaves

    def tick(self) -> Status:
        """One BT.CPP ``tickRoot``."""
        return self.root.execute_tick()

    def halt(self) -> None:
        """Halt every running node (leaves request cancels; see :func:`tms_ts.leaf.poll_stops`)."""
        self.root.halt()

    def running_leaves(self) -> list[str]:
        """``ID 'name'`` of every action (no children) currently RUNNING."""
        return [n.describe() for n in self.nodes if not n.children and n.status is RUNNING]

    def snapshot(self) -> str:
        """One line per node: indentation, id, name and status letter (I/R/S/F), for display."""
        letters = {IDLE: "I", RUNNING: "R", Status.SUCCESS: "S", Status.FAILURE: "F"}
        lines: list[str] = []

        def walk(node: BtNode, depth: int) -> None:
            name = f" '{node.name}'" if node.name != node.node_id else ""
            lines.append(f"{'  ' * depth}{node.node_id}{name} [{letters.get(node.status, '?')}]")
            for child in node.children:
                walk(child, depth + 1)

        walk(self.root, 0)
        return "\n".join(lines)


def _describe(el: Element, node_id: str) -> str:
    name = el.attrib.get("name")
    return f"{node_id} '{name}'" if name and name != node_id else node_id


class _Builder:
    def __init__(self, doc: Element, source: str, v4: bool) -> None:
        self.source = source
        self.v4 = v4
        self.nodes = 0  # nodes built so far (SubTrees inlined): MAX_TREE_NODES
        self.trees: dict[str, Element] = {}
        for child in doc.children:
            if child.tag == "BehaviorTree":
                tree_id = child.attrib.get("ID")
                if not tree_id:
                    if (
                        "main_tree_to_execute" in doc.attrib
                        or len([c for c in doc.children if c.tag == "BehaviorTree"]) > 1
                    ):
                        raise self.error(child, "BehaviorTree", "has no ID")
                    tree_id = "__main__"
                if tree_id in self.trees:
                    raise self.error(child, f"BehaviorTree '{tree_id}'", "defined twice")
                if len(child.children) != 1:
                    raise self.error(
                        child, f"BehaviorTree '{tree_id}'", f"must have exactly 1 root node, has {len(child.children)}"
                    )
                self.trees[tree_id] = child
            elif child.tag == "TreeNodesModel":
                continue
            elif child.tag == "include":
                raise self.error(child, "include", "<include> is not supported; put every tree in one document")
            else:
                raise self.error(child, child.tag, "unexpected element under <root>")

    def error(self, el: Element, what: str, problem: str) -> TreeLoadError:
        return TreeLoadError(f"{self.source}: {what} ({el.where}): {problem}")

    def build(self, el: Element, ctx: TreeContext, stack: tuple[str, ...], depth: int = 1) -> BtNode:
        """Node ``el`` and its children; ``depth`` counts the built tree's levels (the root node is 1)."""
        self.nodes += 1
        if depth > MAX_TREE_DEPTH:
            via = f" (SubTrees {' -> '.join(stack)})" if len(stack) > 1 else ""
            raise self.error(
                el,
                el.attrib.get("ID", el.tag),
                f"the built tree is {depth} levels deep here{via}, over the "
                f"limit of {MAX_TREE_DEPTH} (tms_ts.limits.MAX_TREE_DEPTH)",
            )
        if self.nodes > MAX_TREE_NODES:
            via = f" (SubTrees {' -> '.join(stack)})" if len(stack) > 1 else ""
            raise self.error(
                el,
                el.attrib.get("ID", el.tag),
                f"the built tree has {self.nodes:,} nodes here{via}, over "
                f"the limit of {MAX_TREE_NODES:,} (tms_ts.limits.MAX_TREE_NODES)",
            )
        tag = el.tag
        attrs = dict(el.attrib)
        if tag in _FAMILY_TAGS or tag in _SUBTREE_TAGS:
            node_id = attrs.pop("ID", None)
            if not node_id:
                raise self.error(el, tag, "has no ID attribute")
        else:
            node_id = tag
            if "ID" in attrs and not self.v4:
                attrs.pop("ID")
        if tag in _SUBTREE_TAGS:
            self.nodes -= 1  # a SubTree is no node of its own: its body's root takes its place
            return self.subtree(el, node_id, attrs, ctx, stack, depth)
        cls = node_class(node_id)
        if cls is None:
            raise self.error(el, node_id, "unknown node ID")
        name = attrs.pop("name", node_id)
        where = f"{self.source} {el.where}" if self.source != "<xml>" else el.where
        resolved: dict[str, str] = {}  # literal port -> the task parameter it was read from
        for port in getattr(cls, "LITERAL_PORTS", ()):
            m = _KEY_RE.match(attrs.get(port, ""))
            if m:
                resolved[port] = m.group(1)
                value = self.load_time_value(el, node_id, port, m.group(1), ctx)
                self.declare(el, node_id, cls, port, m.group(1), ctx)
                attrs[port] = value
        ports: dict[str, tuple[bool, Any]] = {}
        for port, raw in attrs.items():
            spec = cls.PORTS.get(port)
            if spec is None:
                allowed = ", ".join(sorted(cls.PORTS)) or "none"
                raise self.error(el, _describe(el, node_id), f"unknown port '{port}' (ports of {node_id}: {allowed})")
            m = _KEY_RE.match(raw)
            if m:
                ports[port] = (True, m.group(1))
                self.declare(el, node_id, cls, port, m.group(1), ctx)
            elif spec.type == "key":
                ports[port] = (False, raw)
            else:
                try:
                    ports[port] = (False, convert(raw, spec.type))
                except ValueError as exc:
                    raise self.error(el, _describe(el, node_id), f"port '{port}': {exc}") from None
        for port, spec in cls.PORTS.items():
            if spec.required and port not in ports:
                raise self.error(el, _describe(el, node_id), f"missing required port '{port}'")
        check: Callable[[dict[str, str]], str | None] | None = getattr(cls, "check_ports", None)
        if check is not None:
            problem = check(attrs)
            if problem:
                if resolved:
                    problem += (
                        " (read from task parameter "
                        + ", ".join(f"'{k}' by port '{p}'" for p, k in resolved.items())
                        + ")"
                    )
                raise self.error(el, _describe(el, node_id), problem)
        lo, hi = cls.CHILDREN
        n = len(el.children)
        if n < lo or (hi is not None and n > hi):
            want = f"{lo}" if lo == hi else (f"{lo}..{hi}" if hi is not None else f"at least {lo}")
            raise self.error(el, _describe(el, node_id), f"needs {want} children, has {n}")
        node = cls(name, node_id=node_id, ports=ports, ctx=ctx, where=where)
        for child_el in el.children:
            child = self.build(child_el, ctx, stack, depth + 1)
            child.parent = node
            node.children.append(child)
        return node

    def declare(self, el: Element, node_id: str, cls: type[BtNode], port: str, key: str, ctx: TreeContext) -> None:
        """BT.CPP creates the entry of a ``{key}`` port with the port's type when it builds the node; a key two
        ports declare with different types is refused there (tms_ts.blackboard, "Declared at load")."""
        try:
            ctx.blackboard.declare(key, cls.PORTS[port].cpp_type)
        except BlackboardError as exc:
            raise self.error(el, _describe(el, node_id), f"port '{port}' = '{{{key}}}': {exc}") from None

    def load_time_value(self, el: Element, node_id: str, port: str, key: str, ctx: TreeContext) -> str:
        """The text of blackboard entry ``key`` for a port read once at load (a task parameter)."""
        value = ctx.blackboard.get(key)
        if value is MISSING:
            raise self.error(el, _describe(el, node_id),
                             f"port '{port}' reads blackboard key '{key}' when the tree is loaded, and the task sets "
                             f"no such entry (the task document's field 'blackboard', e.g. {{{key}: ...}})")
        if isinstance(value, bool) or not isinstance(value, str | int | float):
            raise self.error(el, _describe(el, node_id),
                             f"port '{port}' reads blackboard key '{key}' = {value!r}: expected a name (text)")
        return str(value)

    def subtree(self, el: Element, tree_id: str, attrs: dict[str, str], ctx: TreeContext, stack: tuple[str, ...],
                depth: int) -> BtNode:
        if tree_id not in self.trees:
            raise self.error(el, f"SubTree '{tree_id}'", f"no BehaviorTree with ID '{tree_id}' in the document")
        if tree_id in stack:
            raise self.error(el, f"SubTree '{tree_id}'", f"recursive subtree ({' -> '.join(stack + (tree_id,))})")
        attrs.pop("name", None)
        shared = attrs.pop("__shared_blackboard", attrs.pop("_autoremap", attrs.pop("__autoremap", "false")))
        if str(shared).lower() == "true":
            sub_ctx = ctx
        else:
            remap: dict[str, str] = {}
            literals: dict[str, Any] = {}
            for key, raw in attrs.items():
                m = _KEY_RE.match(raw)
                if m:
                    remap[key] = m.group(1)
                else:
                    literals[key] = raw
            bb = Blackboard(parent=ctx.blackboard, remap=remap)
            for key, value in literals.items():
                bb.set(key, value)
            sub_ctx = ctx.child(bb)
        body = self.trees[tree_id]
        return self.build(body.children[0], sub_ctx, stack + (tree_id,), depth)

    def main(self, doc: Element, ctx: TreeContext) -> BtNode:
        if not self.trees:
            raise self.error(doc, "root", "the document has no <BehaviorTree>")
        main_id = doc.attrib.get("main_tree_to_execute")
        if main_id is None:
            if len(self.trees) != 1:
                raise self.error(doc, "root", f"main_tree_to_execute is missing and there are {len(self.trees)} trees")
            main_id = next(iter(self.trees))
        if main_id not in self.trees:
            raise self.error(
                doc, "root", f"main_tree_to_execute='{main_id}' names no BehaviorTree (have: {', '.join(self.trees)})"
            )
        body = self.trees[main_id]
        return self.build(body.children[0], ctx, (main_id,))


def check_task_blackboard(entries: Any, source: str = "<xml>") -> dict[str, Any]:
    """A task's initial blackboard entries (its document's ``blackboard``): names -> bool/int/float/str.

    TreeLoadError naming the task (``source``) and the key otherwise.
    """
    if entries is None:
        return {}
    if not isinstance(entries, Mapping):
        raise TreeLoadError(f"{source}: field 'blackboard' must be a mapping of key: value, got {entries!r}")
    checked: dict[str, Any] = {}
    for key, value in entries.items():
        if not isinstance(key, str) or not key.strip() or "{" in key or "}" in key:
            raise TreeLoadError(f"{source}: field 'blackboard': key {key!r} must be a non-empty name without braces")
        if not isinstance(value, bool | int | float | str):
            raise TreeLoadError(f"{source}: field 'blackboard': key '{key}' = {value!r} must be a bool, number or text")
        checked[key] = value
    return checked


def load_tree(xml: str, ctx: TreeContext | None = None, *, source: str = "<xml>",
              blackboard: Mapping[str, Any] | None = None) -> Tree:
    """Build the main tree of a BT.CPP v3/v4 document; TreeLoadError names the culprit node.

    ``blackboard``: the task's initial entries (its parameters, :func:`check_task_blackboard`), set on the
    tree's blackboard before the nodes are built. The limits of :mod:`tms_ts.limits` hold for every document.
    """
    entries = check_task_blackboard(blackboard, source)
    doc = parse_xml(xml, source)
    if doc.tag != "root":
        raise TreeLoadError(f"{source}: document element is <{doc.tag}> ({doc.where}), expected <root>")
    fmt = doc.attrib.get("BTCPP_format")
    if fmt not in (None, "3", "4"):
        raise TreeLoadError(f"{source}: root ({doc.where}): unsupported BTCPP_format={fmt!r} (3 or 4)")
    ctx = ctx if ctx is not None else TreeContext()
    for key, value in entries.items():
        ctx.blackboard.set(key, value)
    builder = _Builder(doc, source, v4=fmt == "4")
    try:
        root = builder.main(doc, ctx)
    except RecursionError:  # pragma: no cover - the depth limit stops the build long before; never a crash though
        raise TreeLoadError(f"{source}: the tree nests too deep to build (tms_ts.limits.MAX_TREE_DEPTH)") from None
    return Tree(root, ctx, source)


def check_tree(xml: str, *, source: str = "<xml>", blackboard: Mapping[str, Any] | None = None) -> Tree:
    """Load ``xml`` exactly as the manager does at start, without ROS or a DB: TreeLoadError for what it would refuse.

    ``tms-db task add`` runs this on the user's own file before anything is stored, so its errors name that file's
    lines and columns (the store keeps a one-line form). Nothing runs; the tree returned is for inspection.
    """
    return load_tree(xml, TreeContext(), source=source, blackboard=blackboard)
