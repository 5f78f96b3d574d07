"""Exception tree of com3_can.

Everything com3_can raises on purpose derives from :class:`Com3Error` (itself a ``TmsError``), in
python-can / cantools phases: encode, decode, bus (init/operation) and ROS command validation.
Messages name the frame, the signal, the range expected and the value received.
"""

from __future__ import annotations

from tms_common.errors import TmsError

__all__ = ["Com3Error", "Com3EncodeError", "Com3DecodeError", "Com3BusError", "Com3CommandError"]


class Com3Error(TmsError):
    """Base of every error raised on purpose by com3_can."""


class Com3EncodeError(Com3Error, ValueError):
    """A frame cannot be encoded: unknown frame or signal, missing signal, value out of the DBC range."""


class Com3DecodeError(Com3Error, ValueError):
    """A received frame is not a valid COM3 frame: unknown id, wrong DLC, or a value outside its DBC range.

    ``reason`` is one of ``unknown_id``, ``bad_dlc``, ``out_of_range``, ``garbage`` (diagnostic counter keys).
    """

    def __init__(self, message: str, *, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class Com3BusError(Com3Error, OSError):
    """A CAN backend cannot be opened or used (e.g. SocketCAN absent from the kernel)."""


class Com3CommandError(Com3Error, ValueError):
    """A ROS command was rejected (unknown joint, NaN, value outside the COM3 range...); never wrapped or clipped."""
