"""tms_rc: robot control.

The HEAP-style hierarchical QP arm controller for the ZX200 (hydraulic flow and joint limits first,
then collision avoidance, orientation, position, least motion) and the track and vessel controllers
of the IC120. Controllers publish COM3 joint commands to the com3_can converter.
"""
