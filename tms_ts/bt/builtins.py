"""The BehaviorTree.CPP 3.8 built-in node vocabulary, with its semantics (reference §6).

Controls: Sequence, SequenceStar (v4: SequenceWithMemory), ReactiveSequence, Fallback, ReactiveFallback,
Parallel, IfThenElse, WhileDoElse. Decorators: Inverter, ForceSuccess, ForceFailure, Repeat,
RetryUntilSuccessful, KeepRunningUntilFailure, Delay, Timeout. Actions: AlwaysSuccess, AlwaysFailure,
SetBlackboard, Sleep (v4). SubTree is built by the loader (:mod:`tms_ts.loader`).

Each ``_tick`` follows the corresponding BT.CPP 3.8 ``tick()``; comments name where Python differs.
The one intended difference: Repeat/RetryUntilSuccessful loop inside one tick while the child finishes
synchronously, but at most ``ctx.sync_loop_budget`` times per tick, then return RUNNING, so an endless
synchronous loop cannot make the scheduler deaf to cancel and emergency stop.
"""

from __future__ import annotations

from tms_ts.blackboard import STRING, BlackboardError
from tms_ts.bt.core import (
    FAILURE,
    IDLE,
    RUNNING,
    SUCCESS,
    ActionNode,
    ControlNode,
    DecoratorNode,
    Port,
    StatefulNode,
    Status,
)
from tms_ts.errors import TreeRuntimeError

__all__ = ["BUILTINS"]


def _idle_error(node: ControlNode | DecoratorNode) -> TreeRuntimeError:
    return TreeRuntimeError(f"{node.describe()}: a child returned IDLE")


# ---------------------------------------------------------------------------------------------
# controls
# ---------------------------------------------------------------------------------------------
class _MemoryWalk(ControlNode):
    """Ticks children in order, remembering the RUNNING child, until one returns ``STOP_ON``.

    Sequence stops on FAILURE and Fallback on SUCCESS; a child returning the other outcome lets the walk
    go on to the next child, and when every child has, the walk returns that outcome (``GO_ON``).
    """

    STOP_ON: Status
    GO_ON: Status

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.index = 0

    def _reset(self) -> None:
        super()._reset()
        self.index = 0

    def _stopped(self) -> None:
        """The walk ended on ``STOP_ON``: halt and start from child 0 next time."""
        self.halt_children()
        self.index = 0

    def _tick(self) -> Status:
        children = self.children
        while self.index < len(children):
            status = children[self.index].execute_tick()
            if status is RUNNING:
                return RUNNING
            if status is self.STOP_ON:
                self._stopped()
                return status
            if status is not self.GO_ON:
                raise _idle_error(self)
            self.index += 1
        self.halt_children()
        self.index = 0
        return self.GO_ON


class Sequence(_MemoryWalk):
    """Ticks children in order, remembering the RUNNING child; any FAILURE resets to child 0."""

    STOP_ON, GO_ON = FAILURE, SUCCESS


class SequenceStar(Sequence):
    """Sequence with memory: a FAILURE does not reset the index; the failed child is retried next tick."""

    def _stopped(self) -> None:
        self.halt_children(self.index)


class Fallback(_MemoryWalk):
    """Ticks children in order until one succeeds, remembering the RUNNING child."""

    STOP_ON, GO_ON = SUCCESS, FAILURE


class _ReactiveWalk(ControlNode):
    """Re-ticks from child 0 every tick until one returns ``STOP_ON``; a RUNNING child halts the ones after it."""

    STOP_ON: Status
    GO_ON: Status

    def _tick(self) -> Status:
        for i, child in enumerate(self.children):
            status = child.execute_tick()
            if status is RUNNING:
                self.halt_children(i + 1)
                return RUNNING
            if status is self.STOP_ON:
                self.halt_children()
                return status
            if status is not self.GO_ON:
                raise _idle_error(self)
        self.halt_children()
        return self.GO_ON


class ReactiveSequence(_ReactiveWalk):
    """Re-ticks from child 0 every tick; a RUNNING child halts the children after it; FAILURE stops."""

    STOP_ON, GO_ON = FAILURE, SUCCESS


class ReactiveFallback(_ReactiveWalk):
    """Re-ticks from child 0 every tick; a RUNNING child halts the children after it; SUCCESS stops."""

    STOP_ON, GO_ON = SUCCESS, FAILURE


class Parallel(ControlNode):
    """Ticks every unfinished child each tick; SUCCESS/FAILURE when the thresholds are met.

    A negative threshold t means ``children + t + 1`` (-1 = all). Finished children are skipped
    (keeping their status) until the Parallel completes; then every child is halted.
    """

    PORTS = {
        "success_threshold": Port("int", description="children that must succeed (<0: n+t+1)"),
        "failure_threshold": Port("int", 1, "children that must fail (<0: n+t+1)"),
    }

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.skip: set[int] = set()

    def _reset(self) -> None:
        super()._reset()
        self.skip = set()

    def _threshold(self, port: str) -> int:
        value = self.get_input(port)
        n = len(self.children)
        return max(n + value + 1, 0) if value < 0 else value

    def _tick(self) -> Status:
        success_t = self._threshold("success_threshold")
        failure_t = self._threshold("failure_threshold")
        n = len(self.children)
        if n < success_t:
            raise TreeRuntimeError(
                f"{self.describe()}: {n} children < success_threshold {success_t}; can never succeed"
            )
        if n < failure_t:
            raise TreeRuntimeError(f"{self.describe()}: {n} children < failure_threshold {failure_t}; can never fail")
        successes = failures = 0
        for i, child in enumerate(self.children):
            skipped = i in self.skip
            status = child.status if skipped else child.execute_tick()
            if status is SUCCESS:
                self.skip.add(i)
                successes += 1
                if successes == success_t:
                    self.skip = set()
                    self.halt_children()
                    return SUCCESS
            elif status is FAILURE:
                self.skip.add(i)
                failures += 1
                if failures > n - success_t or failures == failure_t:
                    self.skip = set()
                    self.halt_children()
                    return FAILURE
            elif status is not RUNNING:
                raise _idle_error(self)
        return RUNNING


class IfThenElse(ControlNode):
    """Condition (child 0) ticked once, then the chosen branch until it finishes (2 children + false -> FAILURE)."""

    CHILDREN = (2, 3)

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.branch = 0

    def _reset(self) -> None:
        super()._reset()
        self.branch = 0

    def _tick(self) -> Status:
        if self.branch == 0:
            cond = self.children[0].execute_tick()
            if cond is RUNNING:
                return RUNNING
            if cond is SUCCESS:
                self.branch = 1
            elif cond is FAILURE:
                if len(self.children) == 3:
                    self.branch = 2
                else:
                    return FAILURE
            else:
                raise _idle_error(self)
        status = self.children[self.branch].execute_tick()
        if status is RUNNING:
            return RUNNING
        self.halt_children()
        self.branch = 0
        return status


class WhileDoElse(ControlNode):
    """Condition re-ticked every tick; runs child 1 while it succeeds, child 2 otherwise, halting the other."""

    CHILDREN = (3, 3)

    def _tick(self) -> Status:
        cond = self.children[0].execute_tick()
        if cond is RUNNING:
            return RUNNING
        if cond is SUCCESS:
            self.halt_child(2)
            status = self.children[1].execute_tick()
        elif cond is FAILURE:
            self.halt_child(1)
            status = self.children[2].execute_tick()
        else:
            raise _idle_error(self)
        if status is RUNNING:
            return RUNNING
        self.halt_children()
        return status


# ---------------------------------------------------------------------------------------------
# decorators
# ---------------------------------------------------------------------------------------------
class _MapOutcome(DecoratorNode):
    """Passes RUNNING through; once the child finishes, halts it and returns ``_outcome(status)``."""

    def _outcome(self, status: Status) -> Status:
        raise NotImplementedError

    def _tick(self) -> Status:
        status = self.child.execute_tick()
        if status is RUNNING:
            return RUNNING
        self.halt_child()
        if status is not SUCCESS and status is not FAILURE:
            raise _idle_error(self)
        return self._outcome(status)


class Inverter(_MapOutcome):
    """SUCCESS <-> FAILURE; RUNNING stays RUNNING."""

    def _outcome(self, status: Status) -> Status:
        return FAILURE if status is SUCCESS else SUCCESS


class ForceSuccess(_MapOutcome):
    """FAILURE -> SUCCESS once the child finishes."""

    def _outcome(self, status: Status) -> Status:
        return SUCCESS


class ForceFailure(_MapOutcome):
    """SUCCESS -> FAILURE once the child finishes."""

    def _outcome(self, status: Status) -> Status:
        return FAILURE


class KeepRunningUntilFailure(_MapOutcome):
    """Child SUCCESS -> reset child, RUNNING; child FAILURE -> FAILURE."""

    def _outcome(self, status: Status) -> Status:
        return RUNNING if status is SUCCESS else FAILURE


class _CountedLoop(DecoratorNode):
    """Re-ticks the child while it returns ``GO_ON``, at most ``COUNT_PORT`` times (-1 = forever).

    The child's other outcome ends the loop with that outcome; running out of rounds ends it with
    ``GO_ON``. Loops inside one tick while the child finishes synchronously (up to ``sync_loop_budget``).
    """

    COUNT_PORT: str
    GO_ON: Status

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.count = 0

    def _reset(self) -> None:
        super()._reset()
        self.count = 0

    def _tick(self) -> Status:
        rounds = self.get_input(self.COUNT_PORT)
        budget = self.ctx.sync_loop_budget
        while self.count < rounds or rounds == -1:
            status = self.child.execute_tick()
            if status is RUNNING:
                return RUNNING
            self.halt_child()
            if status is self.GO_ON:
                self.count += 1
                budget -= 1
                if budget <= 0 and (self.count < rounds or rounds == -1):
                    return RUNNING
            elif status is SUCCESS or status is FAILURE:
                self.count = 0
                return status
            else:
                raise _idle_error(self)
        self.count = 0
        return self.GO_ON


class Repeat(_CountedLoop):
    """Ticks the child ``num_cycles`` times (-1 = forever) while it succeeds; a FAILURE ends it FAILURE."""

    PORTS = {"num_cycles": Port("int", description="repetitions, -1 = forever")}
    COUNT_PORT, GO_ON = "num_cycles", SUCCESS


class RetryUntilSuccessful(_CountedLoop):
    """Re-ticks a failing child up to ``num_attempts`` times (-1 = forever); SUCCESS ends it SUCCESS."""

    PORTS = {"num_attempts": Port("int", description="attempts, -1 = forever")}
    COUNT_PORT, GO_ON = "num_attempts", FAILURE


class Delay(DecoratorNode):
    """RUNNING until ``delay_msec`` has passed since the first tick, then ticks the child."""

    PORTS = {"delay_msec": Port("unsigned", description="delay before the child is ticked [ms]")}

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.deadline: float | None = None

    def _reset(self) -> None:
        super()._reset()
        self.deadline = None

    def _tick(self) -> Status:
        now = self.ctx.task_time()
        if self.deadline is None:
            msec = self.get_input("delay_msec")
            if msec < 0:
                raise TreeRuntimeError(f"{self.describe()}: delay_msec must be >= 0, got {msec}")
            self.deadline = now + msec / 1000.0
        if now < self.deadline:
            self.feedback_message = f"waiting {self.deadline - now:.2f} s"
            return RUNNING
        status = self.child.execute_tick()
        if status is not RUNNING:
            self.deadline = None
            self.halt_child()
        return status


class Timeout(DecoratorNode):
    """Halts the child and returns FAILURE if it is still RUNNING ``msec`` after the first tick."""

    PORTS = {"msec": Port("unsigned", description="time limit [ms]")}

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.deadline: float | None = None

    def _reset(self) -> None:
        super()._reset()
        self.deadline = None

    def _tick(self) -> Status:
        now = self.ctx.task_time()
        if self.deadline is None:
            self.deadline = now + self.get_input("msec") / 1000.0
        elif now >= self.deadline:
            self.halt_child()
            self.deadline = None
            self.feedback_message = "timed out"
            return FAILURE
        status = self.child.execute_tick()
        if status is not RUNNING:
            self.deadline = None
            self.halt_child()
        return status


# ---------------------------------------------------------------------------------------------
# actions
# ---------------------------------------------------------------------------------------------
class AlwaysSuccess(ActionNode):
    def _tick(self) -> Status:
        return SUCCESS


class AlwaysFailure(ActionNode):
    def _tick(self) -> Status:
        return FAILURE


class SetBlackboard(ActionNode):
    """BT.CPP 3.8.7's SetBlackboard (``actions/set_blackboard_node.h``): ``value`` written as a *string*.

    ``output_key`` is read with ``getInput<std::string>`` (``X`` names X; ``{X}`` names the entry whose name X
    holds). A literal ``value`` is ``blackboard->set(output_key, std::string)``: a new key becomes an untyped
    string entry (so ``value="true"`` is the text "true", which KeepRunningUntilFlgup refuses), an entry a typed
    port declared gets the text parsed (``"true"`` -> bool), an entry set() made typed refuses it. ``value="{src}"``
    copies entry src of this blackboard as it is (value and C++ type, no type check), creating ``output_key``
    with src's port information when it does not exist.
    """

    PORTS = {"value": Port("any", typed=False), "output_key": Port("key", typed=False)}

    def _tick(self) -> Status:
        output_key = self.port_key("output_key")
        is_key, raw = self._ports["value"]
        if not is_key:
            self.bb_set(output_key, raw, STRING)
            return SUCCESS
        bb = self.ctx.blackboard
        src = bb.local_entry(raw)
        if src is None:
            raise TreeRuntimeError(f"{self.describe()}: value '{{{raw}}}': no entry '{raw}' on this blackboard "
                                   "(BT.CPP 3.8: \"Can't find the port referred by [value]\")")
        dst = bb.local_entry(output_key)
        if dst is None:
            try:
                dst = bb.create_entry(output_key, src.port_type, src.converter)
            except BlackboardError as exc:
                raise TreeRuntimeError(f"{self.describe()}: blackboard key '{output_key}': {exc}") from None
        dst.value, dst.vtype = src.value, src.vtype
        return SUCCESS


class Sleep(StatefulNode):
    """v4 action: RUNNING for ``msec``, then SUCCESS."""

    PORTS = {"msec": Port("unsigned")}

    def on_start(self) -> Status:
        self.deadline = self.ctx.task_time() + self.get_input("msec") / 1000.0
        return self.on_running()

    def on_running(self) -> Status:
        return SUCCESS if self.ctx.task_time() >= self.deadline else RUNNING


#: BT.CPP id -> class (v3 and v4 spellings)
BUILTINS: dict[str, type] = {
    "Sequence": Sequence,
    "SequenceStar": SequenceStar,
    "SequenceWithMemory": SequenceStar,
    "ReactiveSequence": ReactiveSequence,
    "Fallback": Fallback,
    "ReactiveFallback": ReactiveFallback,
    "Parallel": Parallel,
    "IfThenElse": IfThenElse,
    "WhileDoElse": WhileDoElse,
    "Inverter": Inverter,
    "ForceSuccess": ForceSuccess,
    "ForceFailure": ForceFailure,
    "KeepRunningUntilFailure": KeepRunningUntilFailure,
    "Repeat": Repeat,
    "RetryUntilSuccessful": RetryUntilSuccessful,
    "RetryUntilSuccesful": RetryUntilSuccessful,  # BT.CPP 3.x registered this misspelling too
    "Delay": Delay,
    "Timeout": Timeout,
    "AlwaysSuccess": AlwaysSuccess,
    "AlwaysFailure": AlwaysFailure,
    "SetBlackboard": SetBlackboard,
    "Sleep": Sleep,
}

__all__ += [cls.__name__ for cls in set(BUILTINS.values())]
_ = IDLE  # re-exported name used by tests
