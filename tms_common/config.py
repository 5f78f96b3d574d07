"""YAML configuration loading that remembers where each value came from.

``load_yaml`` returns plain Python data plus a :class:`Where` locator, so validators can report
``file:line: key: problem`` instead of a bare KeyError.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from tms_common.errors import ConfigError

__all__ = ["Where", "load_yaml", "load_yaml_text", "repo_root", "config_path", "data_path", "data_root"]


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


def load_yaml_text(text: str, file: str = "<string>") -> tuple[Any, Where]:
    """Parse YAML text; a syntax error becomes a ConfigError naming ``file`` and the line."""
    try:
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
    lines: dict[tuple[Any, ...], int] = {}
    if node is not None:
        _collect_lines(node, (), lines)
    return data, Where(file=file, lines=lines)


def load_yaml(path: str | Path) -> tuple[Any, Where]:
    """Read and parse a YAML file; a missing file or a syntax error names the file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    return load_yaml_text(text, str(path))


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
            searched.append(f"ament share directory of {DATA_PACKAGE} (not registered under AMENT_PREFIX_PATH={prefixes!r})")
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
