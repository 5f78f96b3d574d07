"""``tms_db_writer``: the sensing writers' path into the store (the original TMS_SD/SS/SP writers).

* topic ``~/parameter_update`` (tms_msg/msg/ParameterUpdate): fire-and-forget ``set_fields``; a bad
  update (unknown record, malformed JSON, wrong shape) is logged naming record and field and dropped.
* service ``~/set_parameter`` (tms_msg/srv/SetParameter): the same with a reply (``success``, ``message``).

With the default node name: ``/tms_db_writer/parameter_update`` and ``/tms_db_writer/set_parameter``.
``fields_json`` is a JSON object (Extended JSON ``{"$date": ...}`` allowed); types are kept (true stays a
bool, 3 an int, 3.0 a float). Every write stamps ``timestamps``. Parameters: ``db_uri``, ``db_path``,
``topic_upsert`` (false: topic updates of unknown records are refused, as the original's ``update_one``).
"""

from __future__ import annotations

import sys
from typing import Any

from bson import json_util
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_db.errors import StoreError, ValidationError
from tms_db.nodes.common import declare_and_open
from tms_msg.msg import ParameterUpdate
from tms_msg.srv import SetParameter

__all__ = ["main", "TmsDbWriter", "apply_update"]


def apply_update(store: Any, model_name: str, record_name: str, fields_json: str, upsert: bool) -> dict:
    """Parse ``fields_json`` and set the fields; errors name the record (and field)."""
    try:
        fields = json_util.loads(fields_json) if fields_json.strip() else None
    except ValueError as exc:
        raise ValidationError(f"record {record_name!r}: fields_json is not valid JSON: {exc}") from None
    if not isinstance(fields, dict):
        raise ValidationError(f"record {record_name!r}: fields_json must be a JSON object, got {fields_json!r:.80}")
    return store.set_fields(record_name, fields, model_name=model_name or None, upsert=upsert)


class TmsDbWriter(Node):
    """Applies parameter updates from sensing to the store."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_writer", **kwargs)
        self.store = declare_and_open(self)
        self.topic_upsert = bool(declare_startup(self, "topic_upsert", False).value)
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(ParameterUpdate, "~/parameter_update", self._on_update, qos)
        self.create_service(SetParameter, "~/set_parameter", self._set_parameter)
        self.get_logger().info("tms_db_writer ready")

    def _on_update(self, msg) -> None:
        try:
            apply_update(self.store, msg.model_name, msg.record_name, msg.fields_json, self.topic_upsert)
        except StoreError as exc:
            self.get_logger().error(f"parameter_update dropped: {exc}")

    def _set_parameter(self, request, response):
        try:
            apply_update(self.store, request.model_name, request.record_name, request.fields_json, request.upsert)
        except StoreError as exc:
            response.success, response.message = False, str(exc)
            return response
        response.success, response.message = True, ""
        return response

    def destroy_node(self) -> None:
        self.store.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbWriter, args)


if __name__ == "__main__":
    sys.exit(main())
