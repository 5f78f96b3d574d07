"""``ic120_vessel``: :mod:`tms_rc.nodes.vessel_controller` under its former name.

The same node, named ``ic120_vessel``, whose machine defaults to ``ic120`` when neither the ``machine``
parameter nor the namespace names one (the paper launch runs it in ``/ic120``).
"""

from __future__ import annotations

from typing import Any

from tms_common.node import run_node
from tms_rc.nodes.vessel_controller import VesselControllerNode

__all__ = ["main", "Ic120Vessel"]


class Ic120Vessel(VesselControllerNode):
    default_machine = "ic120"

    def __init__(self, node_name: str = "ic120_vessel", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)


def main() -> int:
    return run_node(Ic120Vessel)
