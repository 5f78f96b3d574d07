"""``ic120_localization``: :mod:`tms_rp.nodes.tracked_localization` under its former name.

The same node, named ``ic120_localization``, whose machine defaults to ``ic120`` when neither the ``machine``
parameter nor the namespace names one (the paper launch runs it in ``/ic120``).
"""

from __future__ import annotations

from typing import Any

from tms_common.node import run_node
from tms_rp.nodes.tracked_localization import TrackedLocalization

__all__ = ["main", "Ic120Localization"]


class Ic120Localization(TrackedLocalization):
    default_machine = "ic120"

    def __init__(self, node_name: str = "ic120_localization", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)


def main() -> int:
    return run_node(Ic120Localization)
