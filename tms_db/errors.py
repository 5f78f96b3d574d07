"""Errors of the document store.

``StoreError`` is the base (a :class:`tms_common.errors.TmsError`); ``RecordNotFound`` is also a
``KeyError`` and ``ValidationError`` also a ``ValueError`` so generic handlers still work. Every
message names the record (or task id) and, where one is involved, the field.
"""

from __future__ import annotations

from tms_common.errors import TmsError

__all__ = ["StoreError", "RecordNotFound", "ValidationError"]


class StoreError(TmsError):
    """The store could not do what was asked (backend unreachable, corrupt file, duplicate task...)."""


class RecordNotFound(StoreError, KeyError):  # noqa: N818 - name fixed by the cross-package contract
    """No document matches; the message names the record (and model / field when known)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class ValidationError(StoreError, ValueError):
    """A document, field or task XML has the wrong shape; the message names record and field."""
