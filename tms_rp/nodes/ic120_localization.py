"""``ic120_localization``: :mod:`tms_rp.nodes.tracked_localization` under its former executable and node name.

config/launch/paper_experiment.yaml runs it in the machine's namespace (``/<name>``), which names the machine as
for ``tracked_localization`` (the ``machine`` parameter, else the namespace).
"""

from __future__ import annotations

from typing import Any

from tms_common.node import run_node
from tms_rp.nodes.tracked_localization import TrackedLocalization

__all__ = ["main", "Ic120Localization", "NODE_NAME"]

#: the former node name, which is this module's (and its executable's) name
NODE_NAME = __name__.rpartition(".")[2]


class Ic120Localization(TrackedLocalization):
    """``tracked_localization`` named :data:`NODE_NAME`."""

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)


def main() -> int:
    return run_node(Ic120Localization)
