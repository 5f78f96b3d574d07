"""Parameters read once, at start-up, declared read-only so ``ros2 param set`` refuses them.

Every parameter of the platform's nodes configures the node when it is built (a config file, a rate, a
machine name); none is read again. Declared writable, ``ros2 param set /node speed 2.0`` would report
success and change nothing; declared read-only, rclpy refuses it with "parameter is read-only" (a
launch file or ``--ros-args -p`` still sets it at start-up).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from rclpy.node import Node
    from rclpy.parameter import Parameter

__all__ = ["declare_startup", "startup_parameters"]


def declare_startup(node: Node, name: str, default: Any, description: str = "") -> Parameter:
    """``node.declare_parameter(name, default)`` with ``read_only=True`` (read once, when the node is built)."""
    from rcl_interfaces.msg import ParameterDescriptor

    return node.declare_parameter(name, default, ParameterDescriptor(
        description=description or "read at start-up", read_only=True))


def startup_parameters(node: Node) -> Callable[..., Parameter]:
    """``declare(name, default, description="")`` bound to ``node``: a read-only ``declare_parameter``."""
    return lambda name, default, description="": declare_startup(node, name, default, description)
