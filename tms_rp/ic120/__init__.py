"""The former name of :mod:`tms_rp.tracked` (the navigation and localisation stack was IC120-only).

Every module of :mod:`tms_rp.tracked` is reachable under this name too (``tms_rp.ic120.controller`` is
``tms_rp.tracked.controller``), so code and benchmarks written against the old name keep working.
"""

import importlib
import sys

for _name in ("config", "controller", "costmap", "ekf", "errors", "mapgen", "navigator", "planner"):
    _module = importlib.import_module(f"tms_rp.tracked.{_name}")
    sys.modules[f"{__name__}.{_name}"] = _module
    globals()[_name] = _module
del _name, _module
