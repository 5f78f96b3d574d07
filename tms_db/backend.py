"""``open_store``: the backend a URI names.

``open_store(uri="mongodb://...")`` -> :class:`tms_db.mongo.MongoStore` (pymongo, a real MongoDB);
``open_store()`` / ``open_store(path=DIR)`` -> :class:`tms_db.embedded.EmbeddedStore` (SQLite in WAL mode
under ``DIR``, default ``$TMS_DB_PATH`` else ``~/.local/share/tms/db``). A module of its own: both backends
build on :mod:`tms_db.store`, so the function that picks one cannot live there.
"""

from __future__ import annotations

import inspect
import os
from pathlib import Path
from typing import Any

from tms_db.embedded import EmbeddedStore
from tms_db.errors import StoreError
from tms_db.mongo import MongoStore
from tms_db.store import Store, default_path

__all__ = ["open_store"]


def open_store(uri: str | None = None, path: str | os.PathLike | None = None, **options: Any) -> Store:
    """Open the store: ``mongodb://`` / ``mongodb+srv://`` URIs via pymongo, otherwise the embedded store.

    ``path`` (embedded only) is a directory, created if missing; default :func:`tms_db.store.default_path`.
    ``options`` go to the backend (MongoDB: ``database=``, default the URI's database else ``rostmsdb``, and
    ``timeout_s=``, how long a call waits for the server, default :data:`tms_db.mongo.SERVER_TIMEOUT_S`; embedded:
    ``synchronous=``, ``busy_timeout_s=``), except ``max_blob_bytes`` (both backends: the largest blob ``put_blob``
    stores, default 64 MiB). An option the chosen backend does not take: StoreError naming it and the backend.
    """
    max_blob = options.pop("max_blob_bytes", None)
    if max_blob is not None and (isinstance(max_blob, bool) or not isinstance(max_blob, int) or max_blob < 0):
        raise StoreError(f"max_blob_bytes {max_blob!r}: must be an integer >= 0")
    store = _open(uri, path, options)
    if max_blob is not None:
        store.max_blob_bytes = max_blob
    return store


def _check_options(backend: type, options: dict[str, Any]) -> None:
    taken = [n for n, p in inspect.signature(backend.__init__).parameters.items() if p.kind is p.KEYWORD_ONLY]
    unknown = sorted(set(options) - set(taken))
    if unknown:
        raise StoreError(f"open_store: option(s) {', '.join(unknown)} not taken by {backend.__name__} "
                         f"(it takes {', '.join(taken) or 'none'}, and max_blob_bytes)")


def _open(uri: str | None, path: str | os.PathLike | None, options: dict[str, Any]) -> Store:
    if uri and uri.startswith(("mongodb://", "mongodb+srv://")):
        _check_options(MongoStore, options)
    elif options and (not uri or uri.startswith("file:")):
        _check_options(EmbeddedStore, options)
    if uri:
        if uri.startswith(("mongodb://", "mongodb+srv://")):
            return MongoStore(uri, **options)
        if uri.startswith("file:"):
            path = uri.removeprefix("file://").removeprefix("file:")
        else:
            raise StoreError(
                f"db uri {uri!r}: unsupported scheme; use mongodb://... or leave it empty for the embedded store"
            )
    return EmbeddedStore(Path(path).expanduser() if path else default_path(), **options)
