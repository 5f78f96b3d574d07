"""``tms_db_writer``: the sensing writers' path into the store (the original TMS_SD/SS/SP writers).

* topic ``~/parameter_update`` (tms_msg/msg/ParameterUpdate): fire-and-forget ``set_fields``; a bad
  update (unknown record, malformed JSON, wrong shape) is logged naming record and field and dropped.
* service ``~/set_parameter`` (tms_msg/srv/SetParameter): the same with a reply (``success``, ``message``).
* topic ``/tms_db_data`` (tms_msg_db/msg/Tmsdb), the original's ``tms_db_writer``: ``{time, type, id, name, msg}``
  with ``msg`` JSON-decoded into the collection named by ``type`` (:func:`tms_db.boundary.data_document`); a ``msg``
  that is not JSON or a refused document is logged naming the topic and field, nothing stored.
* retention of those collections: every ``retention_period_s`` each one keeps its newest ``retention_max_count``
  documents (0: all) stored within ``retention_max_age_s`` (0: any age) (``Store.prune_data``).

With the default node name: ``/tms_db_writer/parameter_update`` and ``/tms_db_writer/set_parameter``.
``fields_json`` is a JSON object (Extended JSON ``{"$date": ...}`` allowed); types are kept (true stays a
bool, 3 an int, 3.0 a float). Every write stamps ``timestamps``. Parameters: ``db_uri``, ``db_path``,
``topic_upsert`` (false: topic updates of unknown records are refused, as the original's ``update_one``),
``retention_max_count`` (100000), ``retention_max_age_s`` (0.0), ``retention_period_s`` (10.0).
"""

from __future__ import annotations

import sys
from typing import Any

from bson import json_util
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_db.boundary import DATA_TOPIC, data_document
from tms_db.errors import StoreError, ValidationError
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_msg.msg import ParameterUpdate
from tms_msg.srv import SetParameter
from tms_msg_db.msg import Tmsdb

__all__ = ["main", "TmsDbWriter", "apply_update", "RETENTION_MAX_COUNT"]

#: documents kept per data collection by default: a machine's joints at 1 Hz for a day fit, the disk is bounded
RETENTION_MAX_COUNT = 100_000


def apply_update(store: Any, model_name: str, record_name: str, fields_json: str, upsert: bool) -> dict:
    """Parse ``fields_json`` and set the fields; errors name the record (and field)."""
    try:
        fields = json_util.loads(fields_json) if fields_json.strip() else None
    except ValueError as exc:
        raise ValidationError(f"record {record_name!r}: fields_json is not valid JSON: {exc}") from None
    if not isinstance(fields, dict):
        raise ValidationError(f"record {record_name!r}: fields_json must be a JSON object, got {fields_json!r:.80}")
    return store.set_fields(record_name, fields, model_name=model_name or None, upsert=upsert)


class TmsDbWriter(StoreOwner, Node):
    """Applies parameter updates from sensing to the store."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_writer", **kwargs)
        self.store = declare_and_open(self)
        self.topic_upsert = bool(declare_startup(self, "topic_upsert", False).value)
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(ParameterUpdate, "~/parameter_update", self._on_update, qos)
        self.create_service(SetParameter, "~/set_parameter", self._set_parameter)
        self.create_subscription(Tmsdb, DATA_TOPIC, self._on_data, qos)
        self.max_count = int(declare_startup(self, "retention_max_count", RETENTION_MAX_COUNT).value)
        self.max_age_s = float(declare_startup(self, "retention_max_age_s", 0.0).value)
        period = float(declare_startup(self, "retention_period_s", 10.0).value)
        if self.max_count < 0 or self.max_age_s < 0 or period <= 0:
            raise ValidationError(f"retention_max_count {self.max_count}, retention_max_age_s {self.max_age_s} must "
                                  f"be >= 0 and retention_period_s {period} > 0")
        if self.max_count or self.max_age_s:
            self.create_timer(period, self._prune)
        self.get_logger().info(f"tms_db_writer ready ({DATA_TOPIC}: keeps {self.max_count or 'all'} documents per "
                               f"type, {f'{self.max_age_s:g} s' if self.max_age_s else 'of any age'})")

    def _on_data(self, msg) -> None:
        try:
            self.store.insert_data(data_document(msg.time, msg.type, msg.id, msg.name, msg.msg))
        except StoreError as exc:
            self.get_logger().error(f"{DATA_TOPIC} dropped: {exc}")

    def _prune(self) -> None:
        try:
            for kind in self.store.data_types():
                removed = self.store.prune_data(kind, max_age_s=self.max_age_s or None,
                                                max_count=self.max_count or None)
                if removed:
                    self.get_logger().info(f"retention: removed {removed} documents of {kind!r}")
        except StoreError as exc:
            self.get_logger().error(f"retention: {exc}")

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


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbWriter, args)


if __name__ == "__main__":
    sys.exit(main())
