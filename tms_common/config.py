"""YAML configuration loading that remembers where each value came from.

``load_yaml`` returns plain Python data plus a :class:`Where` locator, so validators can report
``file:line: key: problem`` instead of a bare KeyError.

Every YAML input (configuration files, seeds, ``tms-db param import``) is read under the same limits, checked on
the parser's event stream before anything is built (the composer recurses on depth, and aliases share what they
name, so an alias bomb of a few hundred bytes expands to millions of values once a consumer walks it):
:data:`MAX_YAML_DEPTH` nesting levels, :data:`MAX_YAML_ALIASES` aliases and :data:`MAX_YAML_NODES` values with
every alias expanded; a file of at most :data:`MAX_YAML_BYTES`. A file must be UTF-8; anything else is a ConfigError
naming the file and the byte offset.
The project's own configuration files use at most depth 5, 845 values and no alias.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from tms_common.errors import ConfigError

__all__ = ["Where", "load_yaml", "load_yaml_text", "read_utf8", "repo_root", "config_path", "data_path", "data_root",
           "MAX_YAML_DEPTH", "MAX_YAML_ALIASES", "MAX_YAML_NODES", "MAX_YAML_BYTES"]

#: nesting levels (mappings and sequences) a YAML document may have
MAX_YAML_DEPTH = 64
#: aliases (``*name``) a YAML document may use
MAX_YAML_ALIASES = 100
#: values (scalars, mappings, sequences) a YAML document may hold once every alias is expanded
MAX_YAML_NODES = 200_000
#: [bytes] the largest YAML file read (the parser is pure Python: 32 MiB take minutes already)
MAX_YAML_BYTES = 32 * 1024 * 1024


@dataclass(frozen=True)
class Where:
    """Source locations of a YAML document: ``line_of(path)`` for a key path like ``("nodes", 2, "name")``."""

    file: str
    lines: dict[tuple[Any, ...], int]

    def line_of(self, path: tuple[Any, ...]) -> int:
        """Line (1-based) of the deepest known prefix of ``path``."""
        for end in range(len(path), -1, -1):
            line = self.lines.get(tuple(path[:end]))
            if line is not None:
                return line
        return 1

    def error(self, path: tuple[Any, ...], message: str) -> ConfigError:
        """A ConfigError ``file:line: message`` for the value at ``path``."""
        return ConfigError(f"{self.file}:{self.line_of(path)}: {message}")


def _collect_lines(node: yaml.Node, path: tuple[Any, ...], lines: dict[tuple[Any, ...], int]) -> None:
    lines[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        for key_node, value_node in node.value:
            key = key_node.value
            lines[path + (key,)] = key_node.start_mark.line + 1
            _collect_lines(value_node, path + (key,), lines)
            lines[path + (key,)] = key_node.start_mark.line + 1
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            _collect_lines(item, path + (index,), lines)


def _check_limits(text: str, file: str) -> None:
    """Walk the parser's events (no recursion, nothing built) and refuse depth, alias count or expanded size past
    the limits, naming the line."""
    depth = aliases = total = 0
    anchored: dict[str, int] = {}  # anchor -> expanded values of what it names
    open_at: list[tuple[str | None, int]] = []  # per open collection: its anchor, ``total`` when it started
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        line = event.start_mark.line + 1 if event.start_mark is not None else 1
        if isinstance(event, yaml.AliasEvent):
            aliases += 1
            if aliases > MAX_YAML_ALIASES:
                raise ConfigError(f"{file}:{line}: more than {MAX_YAML_ALIASES} YAML aliases (limit MAX_YAML_ALIASES)")
            total += anchored.get(event.anchor, 1)
        elif isinstance(event, yaml.ScalarEvent):
            total += 1
            if event.anchor is not None:
                anchored[event.anchor] = 1
        elif isinstance(event, yaml.CollectionStartEvent):
            total += 1
            depth += 1
            if depth > MAX_YAML_DEPTH:
                raise ConfigError(
                    f"{file}:{line}: YAML nested deeper than {MAX_YAML_DEPTH} levels (limit MAX_YAML_DEPTH)"
                )
            open_at.append((event.anchor, total - 1))
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1
            anchor, start = open_at.pop()
            if anchor is not None:
                anchored[anchor] = total - start
        else:
            continue
        if total > MAX_YAML_NODES:
            raise ConfigError(f"{file}:{line}: YAML expands to more than {MAX_YAML_NODES} values with its aliases "
                              "expanded (limit MAX_YAML_NODES)")


def load_yaml_text(text: str, file: str = "<string>") -> tuple[Any, Where]:
    """Parse YAML text; a syntax error, or a document past the limits (depth, aliases, expanded size: module
    docstring), becomes a ConfigError naming ``file`` and the line."""
    try:
        _check_limits(text, file)
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else 1
        context = ""
        if exc.context and exc.context_mark is not None:
            context = f" ({exc.context} at line {exc.context_mark.line + 1})"
        raise ConfigError(f"{file}:{line}: malformed YAML: {exc.problem or exc}{context}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{file}: malformed YAML: {exc}") from None
    except RecursionError:  # a backstop: the depth limit above refuses such documents first
        raise ConfigError(f"{file}: YAML nested too deep to read") from None
    lines: dict[tuple[Any, ...], int] = {}
    if node is not None:
        _collect_lines(node, (), lines)
    return data, Where(file=file, lines=lines)


def read_utf8(path: str | Path, what: str = "", limit: int | None = None, limit_name: str = "MAX_YAML_BYTES") -> str:
    """A text file's content; one ConfigError naming the file for anything but readable UTF-8 (the byte offset
    and line of the first byte that is not UTF-8) or, with ``limit``, a file of more bytes (never read further)."""
    path = Path(path)
    label = f"{what} {path}" if what else str(path)
    try:
        with path.open("rb") as fh:
            data = fh.read() if limit is None else fh.read(limit + 1)
    except OSError as exc:
        raise ConfigError(f"{label}: cannot read: {exc.strerror or exc}") from None
    if limit is not None and len(data) > limit:
        raise ConfigError(f"{label}: more than {limit:,} bytes (limit {limit_name})")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ConfigError(
            f"{label}:{line}: not UTF-8 text: byte 0x{data[exc.start]:02x} at byte offset {exc.start}"
        ) from None


def load_yaml(path: str | Path) -> tuple[Any, Where]:
    """Read and parse a YAML file; a missing file, a file that is not UTF-8 or a syntax error names the file."""
    path = Path(path)
    return load_yaml_text(read_utf8(path, limit=MAX_YAML_BYTES), str(path))


def repo_root() -> Path:
    """The source checkout this module was imported from (for run outputs and files given relative to it)."""
    return Path(__file__).resolve().parent.parent


# The package whose ament share directory holds config/ and trees/ (scripts/register_ament.py puts them there).
DATA_PACKAGE = "tms_common"


@functools.lru_cache(maxsize=1)
def data_root() -> Path:
    """The directory that holds the project's ``config/`` and ``trees/``, found through the installed package.

    Searched in order: the ament share directory of ``tms_common`` (``<prefix>/share/tms_common``, found
    through ``AMENT_PREFIX_PATH`` as ``ros2 run`` finds executables), then the source checkout this module
    was imported from (an editable install or a plain clone). Never the current directory, so a node
    works from anywhere.

    Raises:
        ConfigError: neither holds ``config/``; the message lists every place searched.
    """
    searched: list[str] = []
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:
        searched.append("ament share directory (ament_index_python not importable)")
    else:
        try:
            share = Path(get_package_share_directory(DATA_PACKAGE))
        except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset
            prefixes = os.environ.get("AMENT_PREFIX_PATH", "")
            searched.append(
                f"ament share directory of {DATA_PACKAGE} (not registered under AMENT_PREFIX_PATH={prefixes!r})"
            )
        else:
            if (share / "config").is_dir():
                # resolved, so messages name the real file (the share entries link into the checkout)
                return (share / "config").resolve().parent
            searched.append(str(share / "config"))
    checkout = repo_root()
    if (checkout / "config").is_dir():
        return checkout
    searched.append(str(checkout / "config"))
    raise ConfigError(
        "project config/ not found; searched: " + "; ".join(searched) + " (run `make setup`, which registers it)"
    )


def config_path(*parts: str) -> Path:
    """Path of a file under the project's ``config/`` directory (see :func:`data_root`)."""
    return data_root().joinpath("config", *parts)


def data_path(*parts: str) -> Path:
    """Path under the project's data root, e.g. ``data_path("trees", "paper.xml")``."""
    return data_root().joinpath(*parts)
