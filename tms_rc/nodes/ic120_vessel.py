"""``ic120_vessel``: :mod:`tms_rc.nodes.vessel_controller` under its former executable and node name.

config/launch/paper_experiment.yaml runs it in the machine's namespace (``/<name>``), which names the machine as
for ``vessel_controller`` (the ``machine`` parameter, else the namespace).
"""

from __future__ import annotations

from typing import Any

from tms_common.node import run_node
from tms_rc.nodes.vessel_controller import VesselControllerNode

__all__ = ["main", "Ic120Vessel", "NODE_NAME"]

#: the former node name, which is this module's (and its executable's) name
NODE_NAME = __name__.rpartition(".")[2]


class Ic120Vessel(VesselControllerNode):
    """``vessel_controller`` named :data:`NODE_NAME`."""

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)


def main() -> int:
    return run_node(Ic120Vessel)
