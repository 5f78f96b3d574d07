"""StoreOwner: a node's store is closed when the node is destroyed, and the node is destroyed even if closing fails."""

from __future__ import annotations

import pytest

from tms_db import StoreOwner, open_store
from tms_db.errors import StoreError


class _Base:
    """Stands in for rclpy's Node: only the destroy_node chain is under test."""

    def __init__(self) -> None:
        self.destroyed = False

    def destroy_node(self) -> None:
        self.destroyed = True


class _Owner(StoreOwner, _Base):
    pass


class _FailingStore:
    def close(self) -> None:
        raise StoreError("close failed")


def test_destroy_closes_a_real_store(tmp_path) -> None:
    node = _Owner()
    store = open_store(path=str(tmp_path / "db"))
    closed = []
    real_close = store.close
    store.close = lambda: (closed.append(True), real_close())  # type: ignore[method-assign]
    node.store = store
    node.destroy_node()
    assert closed == [True] and node.destroyed


def test_destroy_runs_when_close_raises() -> None:
    node = _Owner()
    node.store = _FailingStore()  # type: ignore[assignment]
    with pytest.raises(StoreError, match="close failed"):
        node.destroy_node()
    assert node.destroyed


def test_destroy_without_a_store() -> None:
    node = _Owner()  # its constructor failed before opening the store
    node.destroy_node()
    assert node.destroyed
