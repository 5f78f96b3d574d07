"""IC120 control: the vessel (dump body) angle controller behind ``set_dump_angle``.

The track commands of the IC120 come from the navigator's controller (tms_rp.ic120.controller), which
already applies the machine's speed and acceleration limits; the vessel is positioned here.
"""
