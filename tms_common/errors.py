"""Exception base of the platform.

Each package derives its own base from :class:`TmsError` (``Com3Error``, ``StoreError``...), so a
caller can catch one package's failures or all of them. Messages name the culprit (file and line,
record and field, node id, joint) and the value received.
"""

from __future__ import annotations


class TmsError(Exception):
    """Base of every error raised on purpose by the platform."""


class ConfigError(TmsError, ValueError):
    """A configuration file or parameter is wrong; the message names the file, line and key."""
