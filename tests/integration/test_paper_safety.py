"""Safety of the paper stack: cancel mid-excavation, and a subtask server killed mid-task.

Issue 9 "What must be shown":

* Cancel mid-excavation: both machines at rest within 0.5 s of simulated time, tasks CANCELED, no
  motion afterwards. A stop through the proportional command path cannot do that (the plant's
  hydraulic dead times are 0.31-0.93 s per joint), so a cancel engages the hydraulic lock: tms_ts
  publishes ``/<model>/lock``, the converter sends ``Pilot_Cutoff_Cmd`` (com3_can/pilot_cutoff.py),
  the plant vents the pilot line after the solenoid delay and the spools centre
  (config/machines/*.yaml ``pilot_cutoff``).
* A subtask server killed (SIGKILL) mid-task: that task ends FAILURE naming the lost server, its
  machine's emg_stop is latched (it comes to rest), the other task is cancelled by the manager's
  lost-server policy (tms_ts/README.md), nothing moves afterwards.

The unit tests at the top check the same parts without ROS (plant over CAN, the converter's
cut-off frames, the leaf's lost-server rule). The two integration tests start the stack node by
node (``tests/integration/safety_stack.py``) with the plant at 1x real time: the stop chain (cancel ->
manager -> converter -> bus) runs on wall time, as on a real machine, so simulated and wall time
agree and the 0.5 s criterion is not flattered by an accelerated plant.
"""

from __future__ import annotations

import signal
import time

import can
import pytest

from tests.integration.safety_stack import (
    IC120_TASK,
    REST_BASE,
    REST_JOINT,
    ZX200_TASK,
    Probe,
    max_speed,
    rest_time,
    speeds,
    start_stack,
    wait_servers,
)

RUNNING, SUCCESS, FAILURE, CANCELED = 1, 2, 3, 4
STACK_SPEED = 1.0
REST_LIMIT_S = 0.5  # the criterion [s simulated]; never loosened here
QUIET_S = 3.0  # [s simulated] of no motion checked after rest


# ---------------------------------------------------------------------------------------------------
# unit level (no ROS)
# ---------------------------------------------------------------------------------------------------
def _plant_io():
    from sim_bridge.can_io import PlantCanIO
    from sim_bridge.plant import Plant

    plant = Plant()
    buses = {m: can.Bus(interface="virtual", channel=f"safety-unit-{m}-{id(plant)}") for m in ("zx200", "ic120")}
    peers = {m: can.Bus(interface="virtual", channel=f"safety-unit-{m}-{id(plant)}") for m in ("zx200", "ic120")}
    return plant, PlantCanIO(plant, buses, watchdog_s=5.0), buses, peers


def _run(plant, io, seconds: float) -> None:
    for _ in range(round(seconds / plant.spec.dt)):
        io.poll()
        io.watchdog()
        plant.step()


def test_pilot_cutoff_frame_stops_both_machines_within_its_solenoid_and_spool_time() -> None:
    from com3_can.pilot_cutoff import CutoffSender

    plant, io, buses, peers = _plant_io()
    try:
        zx, ic = plant.excavator, plant.carrier
        zx.set_front_velocity({"swing_joint": 0.5, "arm_joint": 0.3, "bucket_joint": 0.4, "boom_joint": 0.0})
        ic.set_centre_velocity(1.0, 0.0)
        _run(plant, io, 3.0)
        assert max(abs(v) for v in zx.front.v) > 0.29 and ic.base.vl > 0.9
        sender = CutoffSender()
        t0 = plant.time
        for m in ("zx200", "ic120"):
            peers[m].send(can.Message(arbitration_id=sender.frame_id, data=CutoffSender().set("lock", True, 0.0),
                                      is_extended_id=True))
        rest = None
        while plant.time - t0 < 2.0:
            _run(plant, io, plant.spec.dt)
            moving = max([abs(v) for v in zx.front.v] + [abs(zx.base.vl), abs(ic.base.vl), abs(ic.base.vr)])
            if moving < REST_JOINT and rest is None:
                rest = plant.time - t0
        d = plant.spec.description(plant.spec.excavator)
        c = d.pilot_cutoff
        # what the lock can do with inertia: the solenoid, the spools centring, then the swing braked by its relief
        # torque and its parking brake (the tracks stop within that)
        w = 0.5
        inertia = plant.drives.mass[0]  # the swing's inertia at this pose (sim_bridge.physics)
        brake = w * inertia / (d.cylinders.swing.relief_torque + d.cylinders.swing.brake_torque)
        budget = c.solenoid_delay + 3 * c.front_time_constant + brake + 0.1
        assert rest is not None and rest < budget, (rest, budget)
        # no faster than the solenoid delay: the model does not stop instantly
        assert rest > c.solenoid_delay
        print(f"pilot cut-off in the plant alone: at rest {rest:.3f} s after the frame (budget {budget:.3f} s: "
              f"solenoid {c.solenoid_delay} s, swing 0.5 rad/s braked in {brake:.3f} s; tracks 1 m/s)")
        # commands while locked are ignored; the state frame reports the lock
        swing = zx.front.names.index("swing_joint")
        q_locked = zx.front.q[swing]
        zx.set_front_velocity({"swing_joint": 0.5})
        _run(plant, io, 1.0)
        # the brake holds the upper body: no more than the oil columns' settling (< 1 mrad)
        assert abs(zx.front.q[swing] - q_locked) < 1e-3 and abs(zx.front.v[swing]) < 1e-3
        state = io.machine_state(io.sides["zx200"])
        assert state["pilot_shutoff_valve_state"] == 0.0 and state["lock_cmd_state"] == 1.0
        # release: new commands move the machine again, through the normal dead time
        peers["zx200"].send(can.Message(arbitration_id=sender.frame_id, data=bytes(8), is_extended_id=True))
        _run(plant, io, 0.05)
        zx.set_front_velocity({"swing_joint": 0.5})
        _run(plant, io, 2.0)
        assert zx.front.v[zx.front.names.index("swing_joint")] > 0.4
        assert io.machine_state(io.sides["zx200"])["pilot_shutoff_valve_state"] == 1.0
    finally:
        for b in (*buses.values(), *peers.values()):
            b.shutdown()


def test_cutoff_sender_is_silent_until_first_lock_then_cyclic() -> None:
    from com3_can.pilot_cutoff import CutoffSender

    s = CutoffSender()
    assert s.due(0.0) is None and s.set("lock", False, 0.0) is None  # never locked: no frame at all
    frame = s.set("lock", True, 1.0)
    assert frame is not None and s.codec.decode(s.frame_id, frame)[1]["pilot_cutoff_cmd"] == 1
    assert s.due(1.05) is None and s.due(1.11) is not None  # 100 ms cycle
    assert s.set("emg_stop", True, 1.2) is None  # still engaged: no change frame
    assert s.set("lock", False, 1.3) is None and s.engaged  # emg_stop keeps it engaged
    released = s.set("emg_stop", False, 1.4)
    assert released is not None and s.codec.decode(s.frame_id, released)[1]["pilot_cutoff_cmd"] == 0


class _Goal:
    def __init__(self) -> None:
        self.state, self.error_code, self.message, self.feedback = "pending", 0, "", ""
        self.canceled = False

    def cancel(self) -> None:
        self.canceled = True


class _Port:
    """RosPort with the optional ``lock``: records locks and emergency stops."""

    def __init__(self) -> None:
        self.ready = True
        self.goals: list[_Goal] = []
        self.calls: list[tuple] = []

    def subtask_server_ready(self, model_name: str, subtask_name: str) -> bool:
        return self.ready

    def send_subtask_goal(self, model_name: str, subtask_name: str, record_name: str) -> _Goal:
        self.goals.append(_Goal())
        return self.goals[-1]

    def emergency_stop(self, model_name: str, reason: str) -> None:
        self.calls.append(("emg", model_name, reason))

    def lock(self, model_name: str, engaged: bool, reason: str) -> None:
        self.calls.append(("lock", model_name, engaged))

    def confirm_seq(self) -> int:
        return 0

    def confirmations(self, since: int) -> list:
        return []


def _run_task(port: _Port, clock: list[float]):
    from tms_ts.bt.core import TreeContext
    from tms_ts.loader import load_tree
    from tms_ts.task import TaskRun

    ctx = TreeContext(ros=port, clock=lambda: clock[0], task_id=7, server_lost_s=2.0)
    xml = ('<root main_tree_to_execute="M"><BehaviorTree ID="M"><Action ID="LeafNodeZx200" model_name="zx200" '
           'subtask_name="subtask_zx200_excavate_simple" record_name="dig"/></BehaviorTree></root>')
    return TaskRun(7, load_tree(xml, ctx), clock=lambda: clock[0])


def test_cancel_locks_the_driven_machine_and_the_next_goal_releases_it() -> None:
    port, clock = _Port(), [0.0]
    run = _run_task(port, clock)
    run.step()
    run.step()
    assert ("lock", "zx200", False) in port.calls  # the goal releases any lock first
    port.goals[-1].state = "accepted"
    run.step()
    port.calls.clear()
    run.cancel("test cancel")
    assert port.calls[0] == ("lock", "zx200", True) and port.goals[-1].canceled
    port.goals[-1].state = "canceled"
    run.step()
    assert run.state == "canceled"


def test_lost_server_fails_the_task_naming_it_and_latches_emg_stop() -> None:
    port, clock = _Port(), [0.0]
    run = _run_task(port, clock)
    run.step()
    run.step()
    port.goals[-1].state = "accepted"
    run.step()
    port.ready = False  # the server process died
    for _ in range(10):
        clock[0] += 0.5
        run.step()
    assert run.state == "failure", run.state
    assert "subtask server /zx200/subtask_zx200_excavate_simple lost" in run.message, run.message
    assert run.ctx.lost_servers == ["/zx200/subtask_zx200_excavate_simple"]
    assert [c[:2] for c in port.calls if c[0] == "emg"] == [("emg", "zx200")]
    # a silent heartbeat (the process died, the graph still lists it) counts as lost as well
    port3, clock3 = _Port(), [0.0]
    port3.subtask_server_alive = lambda model: False  # type: ignore[attr-defined]
    run3 = _run_task(port3, clock3)
    run3.step()
    run3.step()
    port3.goals[-1].state = "accepted"
    for _ in range(10):
        clock3[0] += 0.5
        run3.step()
    assert run3.state == "failure" and "lost" in run3.message, run3.message
    # a short graph hiccup (< server_lost_s) does not fail a task
    port2, clock2 = _Port(), [0.0]
    run2 = _run_task(port2, clock2)
    run2.step()
    run2.step()
    port2.goals[-1].state = "accepted"
    port2.ready = False
    clock2[0] += 1.5
    run2.step()
    port2.ready = True
    clock2[0] += 1.5
    run2.step()
    assert run2.state == "running" and not port2.calls[1:]


# ---------------------------------------------------------------------------------------------------
# integration: the stack, real processes
# ---------------------------------------------------------------------------------------------------
def _state_name(st: tuple[int, str] | None) -> str:
    if st is None:
        return "none"
    return {RUNNING: "RUNNING", SUCCESS: "SUCCESS", FAILURE: "FAILURE", CANCELED: "CANCELED"}.get(st[0], str(st[0]))


def _tail(stack: dict, n: int = 15) -> str:
    return "\n".join(f"--- {k}\n" + "\n".join(p.output.splitlines()[-n:]) for k, p in stack.items())


def _bring_up(procs, domain, ros_node, tmp_path):
    stack = start_stack(procs, domain, tmp_path, STACK_SPEED)
    # before the probe's spin thread starts: destroying an action client while another thread adds it
    # to the executor's wait set kills that thread (rclpy: "action client pointer is invalid")
    missing = wait_servers(ros_node, 150.0)
    assert not missing, f"action servers not up: {missing}\n{_tail(stack)}"
    probe = Probe(ros_node)
    assert probe.wait(lambda: len(probe.series()) > 10, 60.0), "no /sim/truth"
    return stack, probe


def _wait_digging_while_ic120_drives(probe: Probe, stack: dict, timeout: float) -> None:
    def ready() -> bool:
        s = probe.series()
        if len(s) < 3:
            return False
        sp = speeds(s[-3], s[-1])
        return probe.digging() and sp["ic_base"] > 0.05 and sp["zx_joint"] > REST_JOINT

    ok = probe.wait(ready, timeout)
    assert ok, (f"the ZX200 never dug while the IC120 drove within {timeout:g} s: tasks "
                f"{_state_name(probe.task(ZX200_TASK))}/{_state_name(probe.task(IC120_TASK))}, bucket "
                f"{probe.bucket:.3f} m3\n{_tail(stack)}")


def _wait_quiet(probe: Probe, seconds: float, timeout: float) -> float:
    start = probe.clock
    assert probe.wait(lambda: probe.clock >= start + seconds, timeout), "simulated time stopped"
    return probe.clock


def _wait_rest_then_quiet(probe: Probe, since: float, timeout: float = 60.0) -> float:
    """Simulated time once both machines have been at rest (since ``since``) for QUIET_S, or after ``timeout`` wall
    seconds (the caller's asserts then name what moved). A killed server's task fails only once its loss is seen, and
    the machines work on until the stop it triggers: on the physical plant, with the bucket in the soil, that rest
    came 6.5-9.9 s simulated after the kill."""
    def quiet() -> bool:
        rest = rest_time(probe.series(), since)
        return rest is not None and probe.clock >= since + rest + QUIET_S + 0.2

    probe.wait(quiet, timeout)
    return probe.clock


@pytest.mark.integration
@pytest.mark.timeout(360)
def test_cancel_mid_excavation_both_machines_rest_within_half_a_second(procs, domain, ros_node, tmp_path):
    stack, probe = _bring_up(procs, domain, ros_node, tmp_path)
    try:
        probe.start(ZX200_TASK, IC120_TASK)
        _wait_digging_while_ic120_drives(probe, stack, 180.0)
        t_cancel, wall_cancel = probe.clock, time.monotonic()
        probe.cancel(ZX200_TASK)
        probe.cancel(IC120_TASK)

        both = lambda: all(_state_name(probe.task(t)) == "CANCELED" for t in (ZX200_TASK, IC120_TASK))  # noqa: E731
        assert probe.wait(both, 60.0), (f"tasks not CANCELED: {probe.task(ZX200_TASK)} {probe.task(IC120_TASK)}"
                                        f"\n{_tail(stack)}")
        wall_canceled = time.monotonic() - wall_cancel
        t_end = _wait_quiet(probe, QUIET_S + 1.0, 60.0)
        series = probe.series()
        before = max_speed(series, t_cancel - 0.5, t_cancel)
        rest = rest_time(series, t_cancel)
        rest_wall = None
        if rest is not None:
            first = next(s for s in series if s.t >= t_cancel + rest - 1e-6)
            rest_wall = first.wall - wall_cancel
        after = max_speed(series, t_cancel + (rest or 0.0), t_end)
        print(f"\ncancel mid-excavation: speeds before {({k: round(v, 3) for k, v in before.items()})}; "
              f"at rest {rest} s simulated ({rest_wall} s wall) after the cancel; tasks CANCELED "
              f"{wall_canceled:.2f} s wall after; max speeds during {t_end - t_cancel - (rest or 0):.1f} s "
              f"after rest {({k: round(v, 4) for k, v in after.items()})}; plant at {STACK_SPEED:g}x "
              f"(ran at {(t_end - t_cancel) / (time.monotonic() - wall_cancel):.2f}x); messages "
              f"{probe.task(ZX200_TASK)[1]!r} / {probe.task(IC120_TASK)[1]!r}")
        for label in ("zx200/excavator_arm_controller", "zx200/zx200_planner", "subtasks_zx200", "tms_ts_manager"):
            lines = [
                ln
                for ln in stack[label].output.splitlines()
                if any(w in ln.lower() for w in ("cancel", "stop", "lock"))
            ]
            print(f"  {label}: " + " | ".join(lines[-4:]))
        assert before["zx_joint"] > REST_JOINT and before["ic_base"] > 0.05, before  # both were moving
        assert rest is not None, "the machines did not come to rest"
        assert rest <= REST_LIMIT_S, f"at rest {rest:.3f} s after the cancel (criterion {REST_LIMIT_S} s)"
        assert max(after["zx_joint"], after["ic_joint"], after["zx_yaw"], after["ic_yaw"]) < REST_JOINT, after
        assert max(after["zx_base"], after["ic_base"]) < REST_BASE, after
        assert "canceled" in probe.task(ZX200_TASK)[1], probe.task(ZX200_TASK)
    finally:
        probe.close()


@pytest.mark.integration
@pytest.mark.timeout(360)
def test_subtask_server_killed_mid_task_fails_it_stops_both_machines(procs, domain, ros_node, tmp_path):
    stack, probe = _bring_up(procs, domain, ros_node, tmp_path)
    try:
        probe.start(ZX200_TASK, IC120_TASK)
        _wait_digging_while_ic120_drives(probe, stack, 180.0)
        t_kill, wall_kill = probe.clock, time.monotonic()
        stack["subtasks_zx200"].signal(signal.SIGKILL)

        failed = lambda: _state_name(probe.task(ZX200_TASK)) == "FAILURE"  # noqa: E731
        assert probe.wait(failed, 90.0), f"ZX200 task did not fail: {probe.task(ZX200_TASK)}\n{_tail(stack)}"
        wall_failed, t_failed = time.monotonic() - wall_kill, probe.clock
        message = probe.task(ZX200_TASK)[1]
        assert "subtask server /zx200/subtask_zx200_excavate_simple lost" in message, message
        assert "emg_stop latched" in message, message

        other = lambda: _state_name(probe.task(IC120_TASK)) == "CANCELED"  # noqa: E731
        assert probe.wait(other, 60.0), f"IC120 task not stopped: {probe.task(IC120_TASK)}\n{_tail(stack)}"
        assert "stopped by policy: task 91 lost /zx200/subtask_zx200_excavate_simple" in probe.task(IC120_TASK)[1]
        wall_other = time.monotonic() - wall_kill

        t_end = _wait_rest_then_quiet(probe, t_kill)
        series = probe.series()
        rest = rest_time(series, t_kill)
        after = max_speed(series, t_kill + (rest or 0.0), t_end)
        print(f"\nsubtask server SIGKILL: ZX200 task FAILURE {wall_failed:.2f} s wall ({t_failed - t_kill:.2f} s sim) "
              f"after the kill: {message!r}; IC120 task CANCELED by policy {wall_other:.2f} s wall after; "
              f"both at rest {rest} s simulated after the kill; max speeds over the last "
              f"{t_end - t_kill - (rest or 0):.1f} s {({k: round(v, 4) for k, v in after.items()})}")
        assert rest is not None, "the machines did not come to rest"
        assert t_kill + rest <= t_end - QUIET_S, "not quiet for the checked span"
        assert max(after["zx_joint"], after["ic_joint"], after["zx_yaw"], after["ic_yaw"]) < REST_JOINT, after
        assert max(after["zx_base"], after["ic_base"]) < REST_BASE, after
        # the ZX200 converter latched emg_stop: it refuses motion commands until an operator clears it
        assert stack["zx200/com3_bridge"].wait_for("emg_stop latched", 10.0), _tail(stack)
    finally:
        probe.close()


@pytest.mark.integration
@pytest.mark.timeout(360)
def test_planning_server_killed_mid_task_fails_it_stops_both_machines(procs, domain, ros_node, tmp_path):
    """SIGKILL of the ZX200 planner: the subtask server notices (ROS graph, no heartbeat: ~20 s of DDS
    lease), latches emg_stop and aborts naming it; the task fails and the other task is stopped."""
    stack, probe = _bring_up(procs, domain, ros_node, tmp_path)
    try:
        probe.start(ZX200_TASK, IC120_TASK)
        _wait_digging_while_ic120_drives(probe, stack, 180.0)
        t_kill, wall_kill = probe.clock, time.monotonic()
        stack["zx200/zx200_planner"].signal(signal.SIGKILL)

        failed = lambda: _state_name(probe.task(ZX200_TASK)) == "FAILURE"  # noqa: E731
        assert probe.wait(failed, 120.0), f"ZX200 task did not fail: {probe.task(ZX200_TASK)}\n{_tail(stack)}"
        wall_failed = time.monotonic() - wall_kill
        message = probe.task(ZX200_TASK)[1]
        assert "planning server /zx200/tms_rp_zx200_excavate_simple lost" in message, message
        other = lambda: _state_name(probe.task(IC120_TASK)) == "CANCELED"  # noqa: E731
        assert probe.wait(other, 60.0), f"IC120 task not stopped: {probe.task(IC120_TASK)}\n{_tail(stack)}"
        assert "stopped by policy: task 91 lost /zx200/tms_rp_zx200_excavate_simple" in probe.task(IC120_TASK)[1]

        t_end = _wait_rest_then_quiet(probe, t_kill)
        series = probe.series()
        rest = rest_time(series, t_kill)
        after = max_speed(series, t_kill + (rest or 0.0), t_end)
        print(f"\nplanner SIGKILL: ZX200 task FAILURE {wall_failed:.2f} s wall after the kill: {message!r}; "
              f"IC120 task {probe.task(IC120_TASK)[1]!r}; both at rest {rest} s simulated after the kill; "
              f"max speeds over the last {t_end - t_kill - (rest or 0):.1f} s "
              f"{({k: round(v, 4) for k, v in after.items()})}")
        assert rest is not None and t_kill + rest <= t_end - QUIET_S, "not at rest for the checked span"
        assert max(after["zx_joint"], after["ic_joint"], after["zx_yaw"], after["ic_yaw"]) < REST_JOINT, after
        assert max(after["zx_base"], after["ic_base"]) < REST_BASE, after
        assert stack["zx200/com3_bridge"].wait_for("emg_stop latched", 10.0), _tail(stack)
    finally:
        probe.close()


def test_planning_server_loss_counts_as_lost_by_its_code_or_by_what_the_leaf_sees() -> None:
    from tms_msg.msg import SubtaskOutcome

    # the subtask server's typed code; the text is for people only (any words do)
    port, clock = _Port(), [0.0]
    run = _run_task(port, clock)
    run.step()
    run.step()
    port.goals[-1].state, port.goals[-1].error_code = "aborted", SubtaskOutcome.SERVER_LOST
    port.goals[-1].message = "whatever the server says"
    run.step()
    assert run.state == "failure" and "SERVER_LOST: whatever the server says" in run.message, run.message
    assert run.ctx.lost_servers == ["/zx200/tms_rp_zx200_excavate_simple"]
    # no code (a result type that carries none): the leaf saw the planning server during the goal, and now not
    port1, clock1 = _Port(), [0.0]
    planning = [True]
    port1.planning_server_ready = lambda model, subtask: planning[0]  # type: ignore[attr-defined]
    run1 = _run_task(port1, clock1)
    run1.step()
    run1.step()
    port1.goals[-1].state = "accepted"
    run1.step()
    planning[0] = False
    port1.goals[-1].state, port1.goals[-1].feedback = "aborted", "the reason, in the last feedback"
    run1.step()
    assert run1.state == "failure" and "the reason, in the last feedback" in run1.message, run1.message
    assert run1.ctx.lost_servers == ["/zx200/tms_rp_zx200_excavate_simple"]
    # an ordinary abort is not a lost server (no stop policy for the other tasks), whatever its text says
    port2, clock2 = _Port(), [0.0]
    port2.planning_server_ready = lambda model, subtask: True  # type: ignore[attr-defined]
    run2 = _run_task(port2, clock2)
    run2.step()
    run2.step()
    port2.goals[-1].state = "accepted"
    run2.step()
    port2.goals[-1].state, port2.goals[-1].error_code = "aborted", SubtaskOutcome.PLANNING_FAILED
    port2.goals[-1].message = "planning server /zx200/tms_rp_zx200_excavate_simple lost while running"
    run2.step()
    assert run2.state == "failure" and run2.ctx.lost_servers == []
