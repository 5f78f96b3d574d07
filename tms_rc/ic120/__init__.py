"""The former name of :mod:`tms_rc.carrier` (the vessel controller was IC120-only).

``tms_rc.ic120.vessel`` is ``tms_rc.carrier.vessel``.
"""

import importlib
import sys

vessel = importlib.import_module("tms_rc.carrier.vessel")
sys.modules[f"{__name__}.vessel"] = vessel
