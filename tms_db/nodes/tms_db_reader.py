"""``tms_db_reader``: services ``~/get_task`` (tms_msg/srv/GetTask) and ``~/get_parameter`` (GetParameter).

With the default node name these are ``/tms_db_reader/get_task`` and ``/tms_db_reader/get_parameter``.
A missing task or record is not an error of the service: the reply has ``found: false`` and a
``message`` naming the task id / record. Parameters: ``db_uri``, ``db_path``.
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node

from tms_common.node import run_node
from tms_db.errors import StoreError
from tms_db.nodes.common import declare_and_open, document_json, flatten
from tms_msg.srv import GetParameter, GetTask

__all__ = ["main", "TmsDbReader"]


class TmsDbReader(Node):
    """Answers task and parameter look-ups from the store."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_reader", **kwargs)
        self.store = declare_and_open(self)
        self.create_service(GetTask, "~/get_task", self._get_task)
        self.create_service(GetParameter, "~/get_parameter", self._get_parameter)
        self.get_logger().info("tms_db_reader ready")

    def _get_task(self, request, response):  # noqa: ANN001, ANN202
        try:
            doc = self.store.get_task(request.task_id)
        except StoreError as exc:
            response.found, response.task, response.message = False, "", str(exc)
            return response
        response.found, response.task = True, doc.get("task_sequence", "")
        return response

    def _get_parameter(self, request, response):  # noqa: ANN001, ANN202
        try:
            doc = self.store.get_parameter(request.model_name or None, request.record_name)
        except StoreError as exc:
            response.found, response.message = False, str(exc)
            return response
        response.keys, response.values = flatten(doc)
        response.document_json = document_json(doc)
        response.found = True
        return response

    def destroy_node(self) -> None:
        self.store.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbReader, args)


if __name__ == "__main__":
    sys.exit(main())
