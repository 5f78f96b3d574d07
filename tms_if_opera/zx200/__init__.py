"""ZX200 planning action servers (contract [D]): ``zx200_planner`` in :mod:`tms_if_opera.zx200.node`."""
