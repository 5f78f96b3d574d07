"""tms_common.node.realtime_thread: SCHED_FIFO for the calling thread only, 0 leaves it, out of range refused."""

from __future__ import annotations

import logging
import os
import threading

import pytest

from tms_common.errors import ConfigError
from tms_common.node import realtime_thread

LOG = logging.getLogger("test_realtime_thread")


def _in_thread(fn):  # run fn in a fresh thread, return (result, policy after)
    out: dict = {}

    def run() -> None:
        out["result"] = fn()
        out["policy"] = os.sched_getscheduler(0)
        out["child"] = []
        child = threading.Thread(target=lambda: out["child"].append(os.sched_getscheduler(0)))
        child.start()
        child.join()

    t = threading.Thread(target=run)
    t.start()
    t.join()
    return out


def test_zero_leaves_the_thread_as_it_is():
    out = _in_thread(lambda: realtime_thread(0, "test", LOG))
    assert out["result"] is False and out["policy"] == os.SCHED_OTHER


def test_out_of_range_is_a_config_error_naming_who():
    with pytest.raises(ConfigError, match=r"manager under test: realtime_priority must be 0 \(off\) or 1-99, got 100"):
        realtime_thread(100, "manager under test", LOG)


def test_fifo_for_the_calling_thread_and_the_threads_it_starts():
    def can_fifo() -> bool:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        except OSError:
            return False
        return True

    if not _in_thread(can_fifo)["result"]:
        # without CAP_SYS_NICE the call is refused with a warning and normal scheduling
        out = _in_thread(lambda: realtime_thread(5, "test", LOG))
        assert out["result"] is False and out["policy"] == os.SCHED_OTHER
        pytest.skip("no CAP_SYS_NICE here: SCHED_FIFO refused (the warning path was checked)")
    out = _in_thread(lambda: realtime_thread(5, "test", LOG))
    assert out["result"] is True and out["policy"] == os.SCHED_FIFO and out["child"] == [os.SCHED_FIFO]
    assert os.sched_getscheduler(0) == os.SCHED_OTHER  # this thread (the test's) untouched
