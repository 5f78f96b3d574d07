"""Design surfaces in the store: a collection of ours, ``design``, beside the original's (no rclpy).

A design (what the ground of an area must look like when an excavation is done: a trench, a two-faced or an
S-curved embankment) is the flat mapping :meth:`tms_rp.excavation.design.Design.to_dict` gives. It is stored as an
environment-data document (:meth:`tms_db.store.Store.insert_data`, the original's ``Tmsdb`` shape) in the
collection ``design``, which the original does not have, so none of the original's collections or fields change::

    {"time": "<UTC ISO 8601, microseconds>", "type": "design", "id": 3040, "name": "<design name>",
     "msg": {<the design document: name, kind, frame, area, the kind's keys>}}

A design is never overwritten: :func:`put_design` adds a version, :func:`get_design` reads the newest one of a
name (by ``time``, then insertion), so the version a run used stays readable. The store knows nothing of the
kinds: it checks only that the document is a mapping whose ``name`` is a non-empty string; the meaning is checked
by ``Design.from_dict`` in ``tms-db design put`` / ``tms-db seed`` (``tms_db.cli``, above ``tms_rp``) and again by
the subtask that reads the design.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping
from typing import Any

from tms_db.errors import RecordNotFound, ValidationError

__all__ = ["DESIGN_COLLECTION", "DESIGN_ID", "put_design", "get_design", "list_designs"]

DESIGN_COLLECTION = "design"
#: the ``id`` of every design document (the original's environment data are keyed by a DATA_ID; 3040 is free there)
DESIGN_ID = 3040


def _name(doc: Any) -> str:
    if not isinstance(doc, Mapping):
        raise ValidationError(f"design document must be a mapping, got {type(doc).__name__}")
    name = doc.get("name")
    if not isinstance(name, str) or not name.strip():
        raise ValidationError(f"design document: field 'name' must be a non-empty string, got {name!r}")
    return name


def put_design(store: Any, doc: Mapping[str, Any], *, time: str | None = None) -> str:
    """Store a new version of the design ``doc`` (named by its ``name``); the new ``_id``. Nothing is stored when the
    newest stored version is the same document (a seed loaded twice adds nothing): its ``_id`` is returned."""
    name = _name(doc)
    found = store.find_data(DESIGN_COLLECTION, DESIGN_ID, name=name, latest_only=True)
    if found and found[0].get("msg") == dict(doc):
        return str(found[0]["_id"])
    stamp = time or _dt.datetime.now(_dt.UTC).isoformat(timespec="microseconds")
    return store.insert_data({"time": stamp, "type": DESIGN_COLLECTION, "id": DESIGN_ID, "name": name,
                              "msg": dict(doc)})


def get_design(store: Any, name: str) -> dict:
    """The newest stored version of design ``name`` (its document, ``msg``); RecordNotFound naming the design and
    the designs that are stored."""
    if not isinstance(name, str) or not name:
        raise ValidationError(f"design name must be a non-empty string, got {name!r}")
    found = store.find_data(DESIGN_COLLECTION, DESIGN_ID, name=name, latest_only=True)
    if not found:
        known = list_designs(store)
        raise RecordNotFound(f"design {name!r}: not in the store's collection {DESIGN_COLLECTION!r} (stored: "
                             f"{', '.join(repr(k) for k in known) if known else 'none'}; put one with "
                             "`tms-db design put FILE.yaml` or a seed's `designs`)")
    msg = found[0].get("msg")
    if not isinstance(msg, Mapping):
        raise ValidationError(f"design {name!r}: stored document {found[0].get('_id')} has no mapping in 'msg'")
    return dict(msg)


def list_designs(store: Any) -> list[str]:
    """The names of the stored designs, sorted."""
    return sorted({str(d.get("name")) for d in store.find_data(DESIGN_COLLECTION, DESIGN_ID)})
