"""Crawler-carrier control: the vessel (dump body) and, where the carrier has one, the vessel's swing.

The track commands come from the navigator's controller (tms_rp.tracked.controller), which already applies
the machine's speed and acceleration limits; the vessel angle and the swing angle are positioned here
(:mod:`vessel`, behind ``set_dump_angle``, ``vessel_target_pos`` and ``set_swing_angle``).
"""
