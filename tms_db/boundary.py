"""The original's DB boundary without ROS: its messages as documents and back, and what its writers and readers do.

The original ROS2-TMS for Construction (``tms_db/tms_db_manager``) reaches its MongoDB through more than tasks and
parameters; this module holds the semantics of those nodes over our :class:`tms_db.store.Store`, on plain values
(the nodes in :mod:`tms_db.nodes` copy message fields in and out):

* ``tms_db_data`` (``Tmsdb``): a document ``{time, type, id, name, msg}`` with ``msg`` JSON-decoded, in the
  collection named by ``type`` (:func:`data_document`); ``tms_db_reader`` (``TmsdbGetData``) answers documents of
  ``{id}`` (and ``{name}`` when given), ascending by ``time``, or only the newest (:func:`read_data`).
* ``tms_db_param_data`` (``TmsdbQuery``): ``pose`` / ``joint`` write a record, ``pose_query`` sets (``over_write``)
  or appends to the waypoint arrays of an existing one (:func:`apply_query`).
* ``tms_db_param_reader`` (``TmsdbGetData`` with ``flgorparam``): a record's pose arrays (``param``) or all its
  fields (``flg``) as JSON (:func:`param_replies`).
* ``tms_db_gridfs_data`` (``TmsdbGridFS``): a file read from disk (``static``, ``mesh``, ``dem``) or a point cloud
  (``dynamic``, its bytes as comma-separated decimal text as the original stores them) into a blob
  (:func:`put_gridfs`); ``tms_db_reader_gridfs`` (``TmsdbGridFS`` action) reads them back (:func:`read_file_blob`,
  :func:`read_clouds`).
* ``tms_db_collision`` (``TmsdbCollision``): a mesh file into a ``collision_object_<stem>`` record
  (:func:`collision_record`).

Every refusal is a :class:`tms_db.errors.StoreError` naming the field (and record or file); nothing is stored then.
"""

from __future__ import annotations

import ast
import datetime as _dt
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tms_db.errors import BlobTooLarge, RecordNotFound, StoreError, ValidationError
from tms_db.store import Store, param_filter_text

__all__ = [
    "DATA_TOPIC", "PARAM_TOPIC", "GRIDFS_TOPIC", "COLLISION_TOPIC", "DATA_SERVICE", "PARAM_SERVICE", "GRIDFS_ACTION",
    "FILE_TYPES", "CLOUD_TYPE", "POSE_FIELDS", "JOINT_FIELDS", "COLLISION_POSE", "Cloud", "PointFieldSpec",
    "data_document", "data_reply", "read_data", "apply_query", "param_replies", "put_gridfs", "read_file_blob",
    "read_clouds", "encode_cloud_data", "decode_cloud_data", "field_repr", "parse_field_repr", "collision_record",
    "write_collision", "to_json",
]

#: Names as the original's nodes use them (relative names of un-namespaced nodes: absolute here).
DATA_TOPIC = "/tms_db_data"
PARAM_TOPIC = "/tms_db_param_data"
GRIDFS_TOPIC = "/tms_db_gridfs_data"
COLLISION_TOPIC = "/tms_db_collision"
DATA_SERVICE = "/tms_db_reader"
PARAM_SERVICE = "/tms_db_param_reader"
GRIDFS_ACTION = "/tms_db_reader_gridfs"

#: GridFS types stored from a file named by ``filename`` (the original's save_static_terrain / _mesh / _dem)
FILE_TYPES = ("static", "mesh", "dem")
#: GridFS type stored from the message's point cloud
CLOUD_TYPE = "dynamic"
#: Waypoint fields of a ``pose_query`` and those the ``param`` reader answers (with ``Release_Count``)
POSE_FIELDS = ("x", "y", "z", "qx", "qy", "qz", "qw")
#: A ZX200 ``joint`` query's fields, from ``add_joints.position[0..4]`` in this order (the original's)
JOINT_FIELDS = ("swing_joint", "boom_joint", "arm_joint", "bucket_joint", "bucket_end_joint")
#: Pose a new collision-object record gets (the original's writer: x 8 m ahead, identity orientation)
COLLISION_POSE = {"x": 8.0, "y": 0.0, "z": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0}
_PARAM_ANSWER = (*POSE_FIELDS, "Release_Count")
_FLG_HIDDEN = ("type", "record_name")


def to_json(value: Any) -> str:
    """``json.dumps`` of a stored value; what JSON lacks becomes text (ObjectId, a date as ISO 8601, bytes as
    their length) instead of the original's exception."""
    def other(v: Any) -> Any:
        if isinstance(v, _dt.datetime | _dt.date):
            return v.isoformat()
        if isinstance(v, bytes | bytearray | memoryview):
            return f"<{len(v)} bytes>"
        return str(v)
    return json.dumps(value, default=other, ensure_ascii=False)


# ---- tms_db_data / tms_db_reader ---------------------------------------------------------------------------------
def data_document(time: str, kind: str, ident: int, name: str, msg: str) -> dict:
    """The document the original's writer stores for a ``Tmsdb``; ValidationError naming field ``msg`` when it is
    not JSON (the store checks the rest when it inserts)."""
    try:
        decoded = json.loads(msg, parse_constant=_no_constant)
    except ValueError as exc:
        raise ValidationError(f"Tmsdb type {kind!r} id {ident} name {name!r}: field 'msg' is not JSON: {exc}") from None
    return {"time": time, "type": kind, "id": ident, "name": name, "msg": decoded}


def _no_constant(token: str) -> Any:
    raise ValueError(f"{token} is not a JSON number")


def data_reply(doc: Mapping[str, Any]) -> dict:
    """``Tmsdb`` fields of a stored document (``msg`` back to JSON text), as the original's ``allocate_tmsdb``."""
    ident = doc.get("id", 0)
    return {"time": str(doc.get("time", "")), "type": str(doc.get("type", "")),
            "id": ident if isinstance(ident, int) and not isinstance(ident, bool) else 0,
            "name": str(doc.get("name", "")), "msg": to_json(doc.get("msg"))}


def read_data(store: Store, kind: str, ident: int, name: str, latest_only: bool) -> list[dict]:
    """``TmsdbGetData`` at ``tms_db_reader``: ``Tmsdb`` field dicts, ascending by time, or only the newest."""
    return [data_reply(d) for d in store.find_data(kind, ident, name=name, latest_only=latest_only)]


# ---- tms_db_param_data ------------------------------------------------------------------------------------------
def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValidationError(f"{where}: must be a finite number, got {value!r}")
    return float(value)


def apply_query(store: Store, kind: str, writemode: str, record_name: str, vehicle_name: str,
                pose: Mapping[str, float], joints: Sequence[float]) -> dict:
    """A ``TmsdbQuery``'s write; returns the record written.

    * ``pose``: the record ``{model_name, record_name, x, y, qx, qy, qz, qw}`` (``pose`` from ``add_path.pose``),
      replacing one with the same names (the original inserts another document that its readers, taking the
      first, never see).
    * ``joint``: ``{model_name, record_name, type: static, trajectory: 1, swing_joint .. bucket_end_joint}`` from
      ``add_joints.position[0..4]`` (at least five positions).
    * ``pose_query``: the existing record (``vehicle_name`` + ``record_name``; an empty ``vehicle_name``: by
      record alone) gets ``x y z qx qy qz qw``: ``writemode`` ``over_write`` sets each to a one-element array,
      any other appends the values (the original ``$push``-es one-element arrays, nesting them; we append the
      numbers the waypoint readers expect) with :meth:`~tms_db.store.Store.append_fields`, atomic per record in both
      backends: concurrent appenders never lose a waypoint. RecordNotFound naming the record when it does not
      exist; ValidationError naming the field when one holds something other than an array.
    """
    if not isinstance(record_name, str) or not record_name:
        raise ValidationError(f"type {kind!r}: field 'record_name' must be a non-empty string")
    where = f"record {record_name!r}" + (f" (vehicle {vehicle_name!r})" if vehicle_name else "")
    if kind == "pose":
        doc: dict[str, Any] = {"model_name": vehicle_name, "record_name": record_name}
        for key in ("x", "y", "qw", "qx", "qy", "qz"):
            doc[key] = _number(f"{where}: field 'add_path.pose.{_pose_path(key)}'", pose[key])
        store.upsert_parameter(doc)
        return doc
    if kind == "joint":
        if len(joints) < len(JOINT_FIELDS):
            raise ValidationError(f"{where}: field 'add_joints.position': {len(joints)} values, a joint record needs "
                                  f"{len(JOINT_FIELDS)} ({', '.join(JOINT_FIELDS)})")
        doc = {"model_name": vehicle_name, "record_name": record_name, "type": "static", "trajectory": 1}
        for i, key in enumerate(JOINT_FIELDS):
            doc[key] = _number(f"{where}: field 'add_joints.position[{i}]'", joints[i])
        store.upsert_parameter(doc)
        return doc
    if kind == "pose_query":
        values = {k: _number(f"{where}: field 'add_path.pose.{_pose_path(k)}'", pose[k]) for k in POSE_FIELDS}
        if writemode == "over_write":
            store.get_parameter(vehicle_name or None, record_name)  # RecordNotFound names the record
            return store.set_fields(record_name, {k: [v] for k, v in values.items()}, model_name=vehicle_name or None)
        try:  # one atomic append per record (RecordNotFound names the record)
            return store.append_fields(record_name, values, model_name=vehicle_name or None)
        except ValidationError as exc:  # the store names the record its way; this module's messages name the vehicle
            prefix = param_filter_text(record_name, vehicle_name or None)
            if str(exc).startswith(prefix + ":"):
                raise ValidationError(where + str(exc)[len(prefix):]) from None
            raise
    raise ValidationError(f"{where}: field 'type': {kind!r} is not a query type (pose, joint, pose_query)")


def _pose_path(key: str) -> str:
    return f"position.{key}" if key in ("x", "y", "z") else f"orientation.{key[1]}"


# ---- tms_db_param_reader ------------------------------------------------------------------------------------------
def _param_reply(doc: Mapping[str, Any]) -> dict:
    return {"time": "", "type": str(doc.get("type", "")), "id": 0, "name": str(doc.get("record_name", "")),
            "msg": to_json({k: doc.get(k, []) for k in _PARAM_ANSWER})}


def _flg_reply(doc: Mapping[str, Any]) -> dict:
    return {"time": "", "type": str(doc.get("type", "")), "id": 0, "name": str(doc.get("record_name", "")),
            "msg": to_json({k: v for k, v in doc.items() if k not in _FLG_HIDDEN})}


def param_replies(store: Store, collection: str, flgorparam: str, name: str,
                  recordnames: Iterable[str]) -> tuple[list[dict], list[str]]:
    """``TmsdbGetData`` at ``tms_db_param_reader``: (``Tmsdb`` field dicts, problems to log).

    The record ``name`` (or else each of ``recordnames``, in their order) of the parameter collection. ``param``:
    one ``Tmsdb`` per record, ``msg`` the JSON of its ``x y z qx qy qz qw Release_Count`` (``[]`` when absent);
    ``flg``: one ``Tmsdb`` for ``name`` (or the first of ``recordnames``), ``msg`` every field but ``type`` and
    ``record_name`` (``_id`` as text). A record not found is left out and named in the problems.
    """
    if collection not in ("parameter", ""):
        return [], [f"type {collection!r}: the param reader reads records of the 'parameter' collection"]
    if flgorparam not in ("param", "flg"):
        return [], [f"field 'flgorparam': {flgorparam!r} is neither 'param' nor 'flg'"]
    names = [name] if name else list(recordnames)
    if not names:
        return [], ["neither field 'name' nor 'recordnames' names a record"]
    docs, problems = [], []
    for record in names:
        try:
            docs.append(store.get_record(record))
        except RecordNotFound:
            problems.append(f"record {record!r} not found in 'parameter'")
    if flgorparam == "flg":
        return [_flg_reply(d) for d in docs[:1]], problems
    return [_param_reply(d) for d in docs], problems


# ---- tms_db_gridfs_data / tms_db_reader_gridfs -------------------------------------------------------------------
@dataclass(frozen=True)
class PointFieldSpec:
    """A ``sensor_msgs/PointField``."""

    name: str
    offset: int
    datatype: int
    count: int


@dataclass(frozen=True)
class Cloud:
    """A ``sensor_msgs/PointCloud2`` without its header (the original's reader sets frame ``map``)."""

    height: int = 0
    width: int = 0
    fields: tuple[PointFieldSpec, ...] = ()
    is_bigendian: bool = False
    point_step: int = 0
    row_step: int = 0
    data: bytes = b""
    is_dense: bool = False
    time: str = ""


_DIGITS = [str(i).encode() for i in range(256)]


def encode_cloud_data(data: bytes) -> bytes:
    """The original's blob of a cloud: its bytes as comma-separated decimals (``','.join(str(i) ...)``)."""
    return b",".join([_DIGITS[b] for b in data])


def decode_cloud_data(blob: bytes, where: str) -> bytes:
    """The bytes of :func:`encode_cloud_data`'s text; ValidationError naming ``where`` when it is not that."""
    if not blob:
        return b""
    try:
        values = np.fromstring(blob, dtype=np.int64, sep=",")  # text mode: one pass, no list of 10^7 objects
    except ValueError as exc:
        raise ValidationError(f"{where}: data is not comma-separated bytes: {exc}") from None
    if values.size != blob.count(b",") + 1:
        raise ValidationError(f"{where}: data is not comma-separated bytes ({values.size} numbers read)")
    if values.size and (values.min() < 0 or values.max() > 255):
        raise ValidationError(f"{where}: data holds a value outside 0..255")
    return values.astype(np.uint8).tobytes()


def field_repr(f: PointFieldSpec) -> str:
    """``repr()`` of a PointField as the original stores it (its reader ``eval``-s it; :func:`parse_field_repr`
    reads it without evaluating anything)."""
    return f"sensor_msgs.msg.PointField(name={f.name!r}, offset={f.offset}, datatype={f.datatype}, count={f.count})"


def parse_field_repr(text: Any, where: str) -> PointFieldSpec:
    """A PointField from its stored ``repr``: only the call ``[sensor_msgs.msg.]PointField(k=literal, ...)``."""
    try:
        node = ast.parse(str(text), mode="eval").body
    except SyntaxError:
        node = None
    name = getattr(getattr(node, "func", None), "attr", None) or getattr(getattr(node, "func", None), "id", None)
    if not isinstance(node, ast.Call) or name != "PointField" or node.args:
        raise ValidationError(f"{where}: field 'fields': {text!r:.80} is not a PointField")
    try:
        kw = {k.arg: ast.literal_eval(k.value) for k in node.keywords}
        return PointFieldSpec(name=str(kw.get("name", "")), offset=int(kw.get("offset", 0)),
                              datatype=int(kw.get("datatype", 0)), count=int(kw.get("count", 0)))
    except (ValueError, TypeError) as exc:
        raise ValidationError(f"{where}: field 'fields': {text!r:.80}: {exc}") from None


def _put(store: Store, kind: str, field: str, data: bytes, **fields: Any) -> str:
    """``put_blob``; a BlobTooLarge names the message's type and field too."""
    try:
        return store.put_blob(data, **fields)
    except BlobTooLarge as exc:
        raise BlobTooLarge(f"type {kind!r}: field {field!r}: {exc}", filename=exc.filename, size=exc.size,
                           limit=exc.limit) from None


def put_gridfs(store: Store, kind: str, ident: int, time: str, filename: str, cloud: Cloud | None, *,
               remove_file: bool = True) -> str:
    """A ``TmsdbGridFS`` message's write; the blob's id.

    ``static`` / ``mesh`` / ``dem``: the file ``filename`` (read on this host) as a blob with ``filename``, ``time``,
    ``type``, ``id``; then the file is removed when ``remove_file`` (the original's hand-off). ``dynamic``: the
    cloud's bytes as the original's text with its ``height width is_bigendian point_step row_step fields
    is_dense`` (``fields`` as PointField reprs), no filename. A missing file, a blob over the store's limit
    (BlobTooLarge) or another type: an error naming it, nothing stored and the file left where it was.
    """
    if kind in FILE_TYPES:
        if not filename:
            raise ValidationError(f"type {kind!r}: field 'filename' is empty (the file to store)")
        try:
            data = Path(filename).read_bytes()
        except OSError as exc:
            raise StoreError(f"type {kind!r}: field 'filename': cannot read {filename!r}: "
                             f"{exc.strerror or exc}") from None
        file_id = _put(store, kind, "filename", data, filename=filename, time=time, type=kind, id=ident)
        if remove_file:
            try:
                os.remove(filename)
            except OSError as exc:  # stored: a file that stays is not worth losing the write over
                raise StoreError(f"type {kind!r}: stored {filename!r} as blob {file_id} but could not remove the "
                                 f"file: {exc.strerror or exc}") from None
        return file_id
    if kind == CLOUD_TYPE:
        if cloud is None:
            raise ValidationError("type 'dynamic': field 'pointcloud2' is missing")
        return _put(store, kind, "pointcloud2", encode_cloud_data(cloud.data), filename=None, time=time, type=kind,
                    id=ident, height=cloud.height, width=cloud.width, is_bigendian=cloud.is_bigendian,
                    point_step=cloud.point_step, row_step=cloud.row_step,
                    fields=[field_repr(f) for f in cloud.fields], is_dense=cloud.is_dense)
    raise ValidationError(f"field 'type': {kind!r} is not a GridFS type ({', '.join(FILE_TYPES)}, {CLOUD_TYPE})")


def read_file_blob(store: Store, kind: str, filename: str) -> tuple[dict, bytes]:
    """The newest (by ``time``) blob of ``type`` and ``filename``: (file document, bytes); RecordNotFound naming
    them (the original's reader polls until one appears; ours answers)."""
    found = store.find_blobs({"type": kind, "filename": filename}, latest_only=True)
    if not found:
        raise RecordNotFound(f"no {kind!r} blob with filename {filename!r}")
    return found[0], store.get_blob(found[0]["_id"])


def _cloud(meta: Mapping[str, Any], data: bytes) -> Cloud:
    where = f"blob {meta.get('_id')} (time {meta.get('time')!r})"
    try:
        return Cloud(height=int(meta.get("height", 0)), width=int(meta.get("width", 0)),
                     fields=tuple(parse_field_repr(f, where) for f in meta.get("fields") or ()),
                     is_bigendian=bool(meta.get("is_bigendian", False)), point_step=int(meta.get("point_step", 0)),
                     row_step=int(meta.get("row_step", 0)), data=decode_cloud_data(data, where),
                     is_dense=bool(meta.get("is_dense", False)), time=str(meta.get("time", "")))
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ValidationError):
            raise
        raise ValidationError(f"{where}: {exc}") from None


def read_clouds(store: Store, kind: str, latest_only: bool) -> list[Cloud]:
    """The ``dynamic`` clouds of ``type`` (the original filters on type alone), ascending by time, or the newest."""
    return [_cloud(meta, store.get_blob(meta["_id"]))
            for meta in store.find_blobs({"type": kind}, latest_only=latest_only)]


# ---- tms_db_collision ---------------------------------------------------------------------------------------------
def collision_record(model_name: str, kind: str, filepath: str, data: bytes,
                     existing: Mapping[str, Any] | None) -> dict:
    """The record ``collision_object_<file stem>`` holding the mesh bytes in ``data``: a new one at
    :data:`COLLISION_POSE` (the original's initial pose), an existing one keeps its pose and other fields."""
    record = "collision_object_" + os.path.splitext(os.path.basename(filepath))[0]
    doc: dict[str, Any] = dict(existing) if existing is not None else {**COLLISION_POSE}
    doc.pop("_id", None)
    doc.update(model_name=model_name, type=kind, record_name=record, data=bytes(data))
    return doc


def write_collision(store: Store, model_name: str, kind: str, filepath: str) -> dict:
    """A ``TmsdbCollision``: read ``filepath`` and store its record (:func:`collision_record`); the file stays."""
    if not filepath:
        raise ValidationError("field 'filepath' is empty (the mesh file to store)")
    try:
        data = Path(filepath).read_bytes()
    except OSError as exc:
        raise StoreError(f"field 'filepath': cannot read {filepath!r}: {exc.strerror or exc}") from None
    stem = "collision_object_" + os.path.splitext(os.path.basename(filepath))[0]
    try:
        existing = store.get_parameter(model_name or None, stem)
    except RecordNotFound:
        existing = None
    doc = collision_record(model_name, kind, filepath, data, existing)
    store.upsert_parameter(doc)
    return doc
