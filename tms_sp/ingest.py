"""The sensing PC's path into the DB, as the original's ``tms_sp`` updaters write it (no rclpy).

The original (irvs/ros2_tms_for_construction, package ``tms_sp_sensing``) runs one small node per
``/tms_sp_<subtask>`` topic (``sensing_msgs/<Subtask>``) and one on ``/Flgs`` (``sensing_msgs/Flgs202508``).
Each message updates one record of the ``parameter`` collection by one rule, which
:class:`SensingWriter` implements once for every topic and for our own sensing (:mod:`tms_sp.processor`):

* the record is the one with the message's ``record_name``, ``type: "dynamic"`` and, except on
  ``/Flgs``, the message's ``model_name``; a missing or non-dynamic record is refused, named;
* each field of the record whose lower-case name is a field of the message takes the message's value
  (``SENSING_LOADED_FLG`` <- ``sensing_loaded_flg``, ``x`` <- ``x``); the bookkeeping fields
  (``_id``, ``model_name``, ``type``, ``record_name``, ``description``, ``timestamps``) never do;
* a field named in the message's ``keep_val_flgs`` keeps its value (the flags message carries every
  flag, and a sensing PC lists the ones it does not measure);
* a message field the record lacks is not written: the record's shape is the seed's. Our own
  sensing writes with ``strict=True``, where such a field is an error naming it instead.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from tms_sp.errors import SensingError

__all__ = ["SensingTopic", "SENSING_TOPICS", "FLAGS_TOPIC", "SensingWriter", "sensed_fields", "message_values"]

#: Record fields a message never sets.
BOOKKEEPING = frozenset({"_id", "model_name", "type", "record_name", "description", "timestamps"})
#: Message fields that address the record or steer the update, not values.
ADDRESS_FIELDS = frozenset({"model_name", "record_name", "keep_val_flgs"})
DYNAMIC = "dynamic"


@dataclass(frozen=True)
class SensingTopic:
    """One of the original's sensing topics: its name, its ``sensing_msgs/msg`` type, how its record is found."""

    topic: str
    type_name: str
    by_model: bool = True  # False: by record_name alone (the flags group)


def _updater(subtask: str, type_name: str) -> SensingTopic:
    return SensingTopic(f"/tms_sp_{subtask}", type_name)


FLAGS_TOPIC = SensingTopic("/Flgs", "Flgs202508", by_model=False)
#: The original's sensing topics that write the DB, one per updater node of its tms_sp_sensing (its newest main).
SENSING_TOPICS: tuple[SensingTopic, ...] = (
    _updater("change_pose", "ChangePose"),
    _updater("excavate_simple", "ExcavateSimple"),
    _updater("release_simple", "ReleaseSimple"),
    _updater("release_soil", "ReleaseSoil"),
    _updater("release_angle", "ReleaseAngle"),
    _updater("follow_waypoints", "FollowWaypoints"),
    _updater("follow_waypoints_deg", "FollowWaypointsDeg"),
    _updater("navigate_anywhere", "NavigateAnywhere"),
    _updater("navigate_anywhere_deg", "NavigateAnywhereDeg"),
    _updater("navigate_through_poses", "NavigateThroughPoses"),
    _updater("navigate_through_poses_deg", "NavigateThroughPosesDeg"),
    _updater("dig_cycle", "DigCycle"),
    _updater("dig_locations", "DigLocations"),
    _updater("release_locations", "ReleaseLocations"),
    FLAGS_TOPIC,
)


def _plain(field: str, value: Any) -> Any:
    """A message field's value as a DB value: numbers, bools, strings, and arrays of them."""
    if hasattr(value, "tolist"):  # array.array (sequence fields), numpy arrays and scalars
        value = value.tolist()
    if isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, list | tuple):
        return [_plain(field, v) for v in value]
    raise SensingError(
        f"message field {field!r}: a {type(value).__name__} is not a DB value (numbers, bools, strings, arrays)"
    )


def message_values(fields: Mapping[str, Any]) -> dict[str, Any]:
    """The value fields of a message (name -> value), without its address fields, as DB values."""
    return {name: _plain(name, value) for name, value in fields.items() if name not in ADDRESS_FIELDS}


def sensed_fields(record: Mapping[str, Any], values: Mapping[str, Any], keep: Iterable[str] = ()) -> dict[str, Any]:
    """The record fields the values set: the original's case-insensitive match, bookkeeping and ``keep`` excluded."""
    by_lower: dict[str, Any] = {}
    for name, value in values.items():
        by_lower[name.lower()] = value
    kept = set(keep)
    return {key: by_lower[key.lower()] for key in record
            if key not in BOOKKEEPING and key not in kept and key.lower() in by_lower}


class SensingWriter:
    """Writes sensed values into dynamic records of a tms_db store by the original's rule (module docstring)."""

    def __init__(self, store: Any) -> None:
        self.store = store

    def record(self, record_name: str, model_name: str | None = None) -> dict:
        """The dynamic record the values go to; SensingError naming it when missing or not dynamic."""
        where = f"record ({model_name or '*'}, {record_name})"
        try:
            doc = (
                self.store.get_parameter(model_name, record_name) if model_name else self.store.get_record(record_name)
            )
        except KeyError as exc:
            raise SensingError(f"{where} not in the DB: seed it first ({exc})") from None
        if doc.get("type") != DYNAMIC:
            raise SensingError(f"{where} has type {doc.get('type')!r}: sensing only writes '{DYNAMIC}' records")
        return doc

    def write(self, record_name: str, values: Mapping[str, Any], *, model_name: str | None = None,
              keep: Iterable[str] = (), strict: bool = False) -> dict[str, Any]:
        """Set the record's fields that ``values`` name; returns what was set (empty: nothing matched)."""
        doc = self.record(record_name, model_name)
        fields = sensed_fields(doc, values, keep)
        if strict:
            known = {key.lower() for key in doc}
            unknown = sorted(name for name in values if name.lower() not in known or name in BOOKKEEPING)
            if unknown:
                raise SensingError(f"record ({model_name or '*'}, {record_name}) has no field(s) {unknown}: "
                                   "add them to the seed")
        if fields:
            self.store.set_fields(record_name, fields, model_name=model_name)
        return fields

    def write_message(self, topic: SensingTopic, fields: Mapping[str, Any]) -> dict[str, Any]:
        """One message of ``topic`` (its fields by name, as ``get_fields_and_field_types`` lists them)."""
        record_name = fields.get("record_name")
        if not isinstance(record_name, str) or not record_name:
            raise SensingError(f"{topic.topic}: message without a record_name")
        model_name = fields.get("model_name") if topic.by_model else None
        if topic.by_model and (not isinstance(model_name, str) or not model_name):
            raise SensingError(f"{topic.topic}: message for record {record_name!r} without a model_name")
        keep = list(fields.get("keep_val_flgs") or ())
        return self.write(record_name, message_values(fields), model_name=model_name, keep=keep)
