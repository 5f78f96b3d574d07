"""The machine-and-site model: what the site and each machine kind *are*, read once from config.

Below planning, control, the plant, sensing and the UI; it imports only tms_common, numpy, pinocchio,
pyproj and yaml.

* :mod:`tms_model.site`: :class:`~tms_model.site.Site` (points, mound, map origin, CRS) and the one
  map <-> plane <-> geodetic projector;
* :mod:`tms_model.geometry`: yaw/quaternion, angle wrap, planar poses;
* :mod:`tms_model.machines`: per machine kind an immutable description of ``config/machines/<kind>.yaml``;
* :mod:`tms_model.excavator`: kinematics of any excavator kind, arm targets and result codes.
"""
