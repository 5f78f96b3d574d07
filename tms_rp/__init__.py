"""tms_rp: robot planning.

ZX200 motion planning (joint, pose and position-with-theta_w targets, excavate and release motions)
and IC120 navigation: GNSS to plane coordinates, EKF localisation, a global planner on a costmap, a
local controller for a tracked vehicle and goal checking, behind Nav2-named actions.
"""
