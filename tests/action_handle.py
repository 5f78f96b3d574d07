"""A transparent proxy of an rclpy action-client handle (``ActionClient._client_handle``).

Tests subclass it to override one call (delay a send, drop a response) and so force a middleware race
deterministically; everything else passes through to the real handle.
"""

from __future__ import annotations

from typing import Any


class ClientHandleProxy:
    """Forwards every attribute and the context-manager protocol to the wrapped handle."""

    def __init__(self, inner: Any) -> None:
        self._inner = inner

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    def __enter__(self) -> Any:
        return self._inner.__enter__()

    def __exit__(self, *exc: Any) -> Any:
        return self._inner.__exit__(*exc)
