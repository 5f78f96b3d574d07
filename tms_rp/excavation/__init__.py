"""Free-form excavation to a design surface: the design as data and the pass planner (pure Python, no rclpy).

* :mod:`tms_rp.excavation.design`: :class:`~tms_rp.excavation.design.Design` (trench, two-faced embankment,
  S-curved embankment) from and to its DB document, sampled on a terrain grid, and the surface error metrics;
* :mod:`tms_rp.excavation.planner`: :class:`~tms_rp.excavation.planner.PassPlanner`, the next cut and its dump
  place from the sensed terrain, or the reason to stop.
"""
