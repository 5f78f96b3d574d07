"""Localisation and navigation of every tracked machine (crawler carriers, excavators, bulldozers).

One stack, configured per machine kind (:mod:`config`: ``config/nav/<kind>_nav.yaml`` over the default
``config/nav/tracked_nav.yaml``, footprint and speed limits from the machine's description). Pure-Python
cores (no rclpy import; GNSS -> map is :mod:`tms_model.site`): :mod:`ekf` (filterpy EKF fusing track
odometry, GNSS and azimuth with Mahalanobis gating), :mod:`costmap` (Nav2 map_server PGM+YAML, inflation with
the machine's footprint), :mod:`planner` (coarse-to-fine Dijkstra on scipy.sparse graphs), :mod:`controller`
(regulated pure pursuit for a tracked vehicle, forward and reverse), :mod:`navigator` (the Nav2 navigate_*
semantics as a step function) and :mod:`rtk` (a machine whose converter gives a map-frame pose). Nodes live
in :mod:`tms_rp.nodes` (``tracked_localization``, ``tracked_navigator``).
"""
