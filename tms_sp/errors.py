"""Errors of the sensing processors."""

from __future__ import annotations

from tms_common.errors import TmsError

__all__ = ["SensingError"]


class SensingError(TmsError):
    """Sensor data cannot be turned into a target or flag (empty cloud, nothing in the region...).

    The message names the sensor/region and the count or value that was wrong.
    """
