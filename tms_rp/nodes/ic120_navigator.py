"""``ic120_navigator``: :mod:`tms_rp.nodes.tracked_navigator` under its former name.

The same node, named ``ic120_navigator``, whose machine defaults to ``ic120`` when neither the ``machine``
parameter nor the namespace names one (the paper launch runs it in ``/ic120``).
"""

from __future__ import annotations

from typing import Any

from tms_common.node import run_node
from tms_rp.nodes.tracked_navigator import TrackedNavigator

__all__ = ["main", "Ic120Navigator"]


class Ic120Navigator(TrackedNavigator):
    default_machine = "ic120"

    def __init__(self, node_name: str = "ic120_navigator", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)


def main() -> int:
    return run_node(Ic120Navigator)
