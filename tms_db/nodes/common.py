"""Parameters shared by every DB-using node: ``db_uri`` and ``db_path`` (contract [C])."""

from __future__ import annotations

from typing import Any

from tms_common.params import declare_startup
from tms_db.backend import open_store
from tms_db.store import Store

__all__ = ["StoreOwner", "declare_and_open"]


def declare_and_open(node: Any, **options: Any) -> Store:
    """Declare ``db_uri`` / ``db_path`` on ``node`` and open the store they name (``options``: :func:`open_store`'s)."""
    uri = declare_startup(node, "db_uri", "").value
    path = declare_startup(node, "db_path", "").value
    store = open_store(uri=uri or None, path=path or None, **options)
    node.get_logger().info(f"document store: {store!r}")
    return store


class StoreOwner:
    """Mixin for a node that owns ``self.store`` (from :func:`declare_and_open`): closes it when the node is destroyed.

    Listed before ``Node`` in the bases (``class X(StoreOwner, Node)``), so ``super()`` reaches ``Node``'s
    ``destroy_node``, which runs even when closing the store raises.
    """

    store: Store

    def destroy_node(self) -> None:
        try:
            store = getattr(self, "store", None)  # a constructor that failed before opening it
            if store is not None:
                store.close()
        finally:
            super().destroy_node()  # type: ignore[misc]
