"""Parameters shared by every DB-using node: ``db_uri`` and ``db_path`` (contract [C])."""

from __future__ import annotations

import json
from typing import Any

from bson import json_util

from tms_common.params import declare_startup
from tms_db.store import Store, open_store

__all__ = ["declare_and_open", "document_json", "flatten"]

_RELAXED = json_util.JSONOptions(json_mode=json_util.JSONMode.RELAXED, tz_aware=True)


def declare_and_open(node: Any) -> Store:
    """Declare ``db_uri`` / ``db_path`` on ``node`` and open the store they name."""
    uri = declare_startup(node, "db_uri", "").value
    path = declare_startup(node, "db_path", "").value
    store = open_store(uri=uri or None, path=path or None)
    node.get_logger().info(f"document store: {store!r}")
    return store


def document_json(doc: dict) -> str:
    """A document as relaxed MongoDB Extended JSON (plain numbers and booleans, ``$date``/``$oid`` wrappers)."""
    return json_util.dumps(doc, json_options=_RELAXED)


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(json.loads(json_util.dumps(value, json_options=_RELAXED)))


def flatten(doc: dict) -> tuple[list[str], list[str]]:
    """``keys``/``values`` of GetParameter: one pair per scalar, the key repeated per array element; no ``_id``."""
    keys: list[str] = []
    values: list[str] = []
    for key, value in doc.items():
        if key == "_id":
            continue
        if isinstance(value, list | tuple):
            for item in value:
                keys.append(key)
                values.append(_text(item))
        else:
            keys.append(key)
            values.append(_text(value))
    return keys, values
