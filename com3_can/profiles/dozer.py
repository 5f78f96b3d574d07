"""Dozer profile (D37PXi): travel and blade lift on our COM3 extension (``dbc/dozer_com3.dbc``).

Commands: ``cmd_vel`` -> ``Velocity_Cmd`` centre + yaw rate (``velocity_mode`` 0), ``track_cmd`` VELOCITY ->
``Velocity_Cmd`` per track (``velocity_mode`` 1), as the crawler carrier's; ``blade_cmd`` (com3_msgs/JointCmd,
joint ``lift_joint``, d37pxi_description's name, URDF sign + = down): POSITION -> ``Blade_Cmd`` target angle within
the joint's limits (``blade_control_mode`` 1), VELOCITY -> target lift rate within its velocity limit (mode 2).
OPERA publishes no blade command topic for the D37PXi (its d37pxi_com3_ros is private), so ``blade_cmd`` is ours.
States: ``Track_Velocity`` -> odometry and joint states (``lift_joint`` from ``Blade_Angle``, track positions),
GNSS fix, IMU, as the carrier's.
"""

from __future__ import annotations

from collections.abc import Sequence

from com3_can.errors import Com3CommandError
from com3_can.outputs import Tx, finite
from com3_can.profiles.base import Core
from com3_can.profiles.crawler_carrier import TrackedProfile
from com3_can.signal_map import BLADE_ANGLE, BLADE_VELOCITY
from com3_can.signal_map import DOZER_BLADE as B
from com3_can.signal_map import DOZER_FRAMES as F
from tms_model.com3 import CONTROL_NAMES, POSITION, VELOCITY
from tms_model.machines import DOZER

__all__ = ["DozerProfile"]


class DozerProfile(TrackedProfile):
    machine_type = DOZER
    channels = {"travel": (F["travel_velocity"],), "blade": (F["blade"],)}
    topics = frozenset({"track_cmd", "cmd_vel", "blade_cmd"})
    setting_topic = "machine_setting"
    state_handlers = {
        F["track_velocity"]: "tracks",
        "Roll_Pitch_Angle": "roll_pitch",
        "GNSS_Altitude_Status": "gnss",
        "Machine_State": "machine_state",
    }

    def blade_cmd(self, core: Core, names: Sequence[str], control_type: int, position: Sequence[float],
                  velocity: Sequence[float], now: float) -> list[Tx]:
        topic = "blade_cmd"
        if list(names) != [B.joint]:
            raise Com3CommandError(f"{topic}: joint_name {list(names)}; expected [{B.joint!r}]")
        frame = core.codec.neutral(F["blade"])
        if control_type == POSITION:
            if len(position) != 1:
                raise Com3CommandError(f"{topic}: 1 joint name but {len(position)} position values")
            angle = finite(topic, f"{B.joint} position", position[0])
            lo, hi = core.config.blade_range
            if not lo <= angle <= hi:
                raise Com3CommandError(f"{topic}: {B.joint} angle {angle:g} rad outside [{lo:g}, {hi:g}] rad "
                                       f"(+ = down; config/machines/{self.machine}.yaml blade.lift_joint.position)")
            frame.update({B.target_angle_cmd: angle, B.mode_cmd: float(BLADE_ANGLE)})
        elif control_type == VELOCITY:
            if len(velocity) != 1:
                raise Com3CommandError(f"{topic}: 1 joint name but {len(velocity)} velocity values")
            rate = finite(topic, f"{B.joint} velocity", velocity[0])
            top = core.config.blade_velocity
            if abs(rate) > top:
                raise Com3CommandError(f"{topic}: {B.joint} velocity {rate:g} rad/s outside [-{top:g}, {top:g}] rad/s "
                                       f"(config/machines/{self.machine}.yaml blade.lift_joint.velocity)")
            frame.update({B.target_velocity_cmd: rate, B.mode_cmd: float(BLADE_VELOCITY)})
        else:
            raise Com3CommandError(f"{topic}: control_type {CONTROL_NAMES.get(control_type, control_type)} is not "
                                   "carried; use POSITION (0) or VELOCITY (1)")
        return core.accept(topic, "blade", {F["blade"]: frame}, now)

    def joints(self, core: Core) -> tuple[tuple[str, ...], tuple[float, ...], tuple[float, ...]]:
        blade = core.state.get(F["blade_angle"], {})
        return (B.joint,), (blade.get(B.angle, 0.0),), (blade.get(B.angular_velocity, 0.0),)
