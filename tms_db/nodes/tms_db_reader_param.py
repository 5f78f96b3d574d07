"""``tms_db_reader_param``: the original's ``tms_db_reader_param`` (node ``tms_db_param_reader``).

Service ``/tms_db_param_reader`` (tms_msg_db/srv/TmsdbGetData): the record ``name`` (or each of ``recordnames``) of
the parameter collection (``type`` ``parameter``); ``flgorparam`` ``param``: one Tmsdb per record, ``msg`` the JSON
of its ``x y z qx qy qz qw Release_Count``; ``flg``: one Tmsdb, ``msg`` every field but ``type`` and
``record_name`` (:func:`tms_db.boundary.param_replies`). Records not found are left out and logged by name.
Parameters: ``db_uri``, ``db_path``.
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node

from tms_common.node import run_node
from tms_db.boundary import PARAM_SERVICE, param_replies
from tms_db.errors import StoreError
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_msg_db.msg import Tmsdb
from tms_msg_db.srv import TmsdbGetData

__all__ = ["main", "TmsDbReaderParam"]


class TmsDbReaderParam(StoreOwner, Node):
    """Answers record look-ups as the original's param reader."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_param_reader", **kwargs)
        self.store = declare_and_open(self)
        self.create_service(TmsdbGetData, PARAM_SERVICE, self._get)
        self.get_logger().info(f"tms_db_reader_param ready: {PARAM_SERVICE}")

    def _get(self, request, response):
        try:
            found, problems = param_replies(self.store, request.type, request.flgorparam, request.name,
                                            list(request.recordnames))
        except StoreError as exc:
            found, problems = [], [str(exc)]
        for problem in problems:
            self.get_logger().warning(f"{PARAM_SERVICE}: {problem}")
        response.tmsdbs = [Tmsdb(**fields) for fields in found]
        return response


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbReaderParam, args)


if __name__ == "__main__":
    sys.exit(main())
