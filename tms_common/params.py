"""Parameters read once, at start-up, declared read-only so ``ros2 param set`` refuses them.

Every parameter of the platform's nodes configures the node when it is built (a config file, a rate, a
machine name); none is read again. Declared writable, ``ros2 param set /node speed 2.0`` would report
success and change nothing; declared read-only, rclpy refuses it with "parameter is read-only" (a
launch file or ``--ros-args -p`` still sets it at start-up).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from rcl_interfaces.msg import ParameterDescriptor

from tms_common.errors import ConfigError

if TYPE_CHECKING:  # pragma: no cover
    from rclpy.node import Node
    from rclpy.parameter import Parameter

__all__ = ["declare_startup", "startup_parameters", "StartupParams"]


def declare_startup(node: Node, name: str, default: Any, description: str = "") -> Parameter:
    """``node.declare_parameter(name, default)`` with ``read_only=True`` (read once, when the node is built)."""
    return node.declare_parameter(name, default, ParameterDescriptor(
        description=description or "read at start-up", read_only=True))


def startup_parameters(node: Node) -> Callable[..., Parameter]:
    """``declare(name, default, description="")`` bound to ``node``: a read-only ``declare_parameter``."""
    return lambda name, default, description="": declare_startup(node, name, default, description)


class StartupParams:
    """Typed, bounded start-up parameters of one node: ``p.number("rate_hz", 20.0, lo=0.0, above=True)``.

    Each read declares the parameter read-only with its default (so the default is visible at the call) and checks
    it; a wrong value raises :class:`ConfigError` ``node /name: parameter key: problem, got value``, which
    :func:`tms_common.node.run_node` prints as one line and exits 2.
    """

    def __init__(self, node: Node) -> None:
        self.node = node

    def _error(self, name: str, problem: str, value: Any) -> ConfigError:
        return ConfigError(f"node {self.node.get_fully_qualified_name()}: parameter {name}: {problem}, got {value!r}")

    def value(self, name: str, default: Any, description: str = "") -> Any:
        """The parameter's value as declared (type from ``default``; rclpy refuses another type)."""
        return declare_startup(self.node, name, default, description).value

    def number(self, name: str, default: float, description: str = "", *, lo: float | None = None,
               hi: float | None = None, above: bool = False) -> float:
        """A finite number within ``[lo, hi]`` (``above``: strictly greater than ``lo``)."""
        value = float(self.value(name, float(default), description))
        if not math.isfinite(value):
            raise self._error(name, "must be a finite number", value)
        if lo is not None and (value <= lo if above else value < lo):
            raise self._error(name, f"must be {'>' if above else '>='} {lo:g}", value)
        if hi is not None and value > hi:
            raise self._error(name, f"must be <= {hi:g}", value)
        return value

    def integer(self, name: str, default: int, description: str = "", *, lo: int | None = None) -> int:
        value = int(self.value(name, int(default), description))
        if lo is not None and value < lo:
            raise self._error(name, f"must be >= {lo}", value)
        return value

    def text(self, name: str, default: str = "", description: str = "") -> str:
        """A string; empty when not given and the default is empty."""
        return str(self.value(name, str(default), description))
