"""``tms_db_reader``: the original's DB reader services, on the original's names and types.

* ``/tms_db_reader_task`` (tms_msg_db/srv/TmsdbGetTask): the task's ``task_sequence`` (the BehaviorTree
  XML); ``""`` when the task does not exist, as the original's ``tms_db_reader_task`` answers (its GUI
  button reads an empty task as "invalid task id").
* ``/tms_db_reader_parameter`` (tms_msg_db/srv/TmsdbGetParameter): one parameter record as parallel
  ``keys`` / ``values`` strings, as the original's ``tms_db_reader_parameter``: every field but ``_id``,
  ``model_name``, ``type`` and ``record_name``, an array field once per element under its key, each
  value as Python's ``str`` gives it (``True``, ``1.5``). An empty ``model_name`` looks the record up by
  ``record_name`` alone (a global-blackboard group). A missing record answers empty lists.

* ``/tms_db_reader`` (tms_msg_db/srv/TmsdbGetData), the original's ``tms_db_reader``: the documents of collection
  ``type`` with ``id`` (and ``name`` when not empty) as ``Tmsdb`` (``msg`` their JSON), ascending by ``time``, or
  only the newest when ``latest_only`` (:func:`tms_db.boundary.read_data`); a refused request is logged, empty.

The names are absolute, as the original's nodes (``tms_db_reader_task``, ``tms_db_reader_parameter``)
serve them from their own names. What is not found is logged naming the task id / record. Parameters:
``db_uri``, ``db_path``.
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node

from tms_common.node import run_node
from tms_db.boundary import DATA_SERVICE, read_data
from tms_db.errors import StoreError
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_msg_db.msg import Tmsdb
from tms_msg_db.srv import TmsdbGetData, TmsdbGetParameter, TmsdbGetTask

__all__ = ["main", "TmsDbReader", "TASK_SERVICE", "PARAMETER_SERVICE", "parameter_pairs"]

TASK_SERVICE = "/tms_db_reader_task"
PARAMETER_SERVICE = "/tms_db_reader_parameter"
#: Fields the original's parameter reader leaves out of its answer.
_NOT_ANSWERED = frozenset({"_id", "model_name", "type", "record_name"})


def parameter_pairs(doc: dict) -> tuple[list[str], list[str]]:
    """``keys`` / ``values`` of TmsdbGetParameter for a record (see the module docstring)."""
    keys: list[str] = []
    values: list[str] = []
    for key, value in doc.items():
        if key in _NOT_ANSWERED:
            continue
        items = value if isinstance(value, list | tuple) else (value,)
        keys.extend(key for _ in items)
        values.extend(str(item) for item in items)
    return keys, values


class TmsDbReader(StoreOwner, Node):
    """Answers task and parameter look-ups from the store."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_reader", **kwargs)
        self.store = declare_and_open(self)
        self.create_service(TmsdbGetTask, TASK_SERVICE, self._get_task)
        self.create_service(TmsdbGetParameter, PARAMETER_SERVICE, self._get_parameter)
        self.create_service(TmsdbGetData, DATA_SERVICE, self._get_data)
        self.get_logger().info(f"tms_db_reader ready: {TASK_SERVICE}, {PARAMETER_SERVICE}, {DATA_SERVICE}")

    def _get_task(self, request, response):
        try:
            response.task = str(self.store.get_task(request.task_id).get("task_sequence", ""))
        except StoreError as exc:
            self.get_logger().warning(f"{TASK_SERVICE}: {exc}")
            response.task = ""
        return response

    def _get_parameter(self, request, response):
        try:
            doc = self.store.get_parameter(request.model_name or None, request.record_name)
        except StoreError as exc:
            self.get_logger().warning(f"{PARAMETER_SERVICE}: {exc}")
            return response
        response.keys, response.values = parameter_pairs(doc)
        return response

    def _get_data(self, request, response):
        try:
            found = read_data(self.store, request.type, request.id, request.name, request.latest_only)
        except StoreError as exc:
            self.get_logger().warning(f"{DATA_SERVICE}: {exc}")
            return response
        response.tmsdbs = [Tmsdb(**fields) for fields in found]
        return response


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbReader, args)


if __name__ == "__main__":
    sys.exit(main())
