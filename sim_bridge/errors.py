"""Exceptions of the plant.

``SimError`` is the package base; ``SimConfigError`` (also a :class:`~tms_common.errors.ConfigError`)
names the file, line and key of a bad machine or plant YAML value.
"""

from __future__ import annotations

from tms_common.errors import ConfigError, TmsError


class SimError(TmsError):
    """Base of every error raised on purpose by sim_bridge."""


class SimConfigError(SimError, ConfigError):
    """A machine/plant YAML value is missing or wrong; the message is ``file:line: key.path: problem``."""


class ReplayError(SimError):
    """A recorded truth log cannot be replayed (missing file, bad record); the message names the file and line."""
