"""Errors of the document store.

``StoreError`` is the base (a :class:`tms_common.errors.TmsError`); ``RecordNotFound`` is also a
``KeyError`` and ``ValidationError`` also a ``ValueError`` so generic handlers still work. Every
message names the record (or task id) and, where one is involved, the field.
"""

from __future__ import annotations

from tms_common.errors import TmsError

__all__ = [
    "StoreError",
    "RecordNotFound",
    "ValidationError",
    "InputRefusedError",
    "StorageFullError",
    "StorageReadOnlyError",
    "BlobTooLarge",
]


class StoreError(TmsError):
    """The store could not do what was asked (backend unreachable, corrupt file, duplicate task...)."""


class RecordNotFound(StoreError, KeyError):  # noqa: N818 - name fixed by the cross-package contract
    """No document matches; the message names the record (and model / field when known)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class ValidationError(StoreError, ValueError):
    """A document, field or task XML has the wrong shape; the message names record and field."""


class InputRefusedError(ValidationError):
    """A whole input (an import file, a restore directory) refused and nothing of it stored: ``problems`` holds one
    line per refused document, naming file and line (or document index) and why; the message is the summary."""

    def __init__(self, summary: str, problems: list[str]) -> None:
        super().__init__(summary)
        self.problems = list(problems)


class StorageFullError(StoreError):
    """The store's disk is full (ENOSPC / SQLITE_FULL); nothing of the write that met it was stored."""


class StorageReadOnlyError(StoreError):
    """The store's directory (or file system) cannot be written."""


class BlobTooLarge(ValidationError):  # noqa: N818 - name fixed by the cross-package contract
    """A blob over the store's ``max_blob_bytes``; the message names filename, size and limit; nothing stored."""

    def __init__(self, message: str, *, filename: str | None, size: int, limit: int) -> None:
        super().__init__(message)
        self.filename = filename
        self.size = size
        self.limit = limit
