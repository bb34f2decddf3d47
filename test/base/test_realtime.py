"""base/realtime.py and the station program's own priority (docs/node.md, station_priority).

The station sets SCHED_FIFO on its main thread before it starts any thread, so every thread
it ever starts inherits the policy: nothing raises it from outside while its threads start
others (the race a re-listing loop used to chase).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from ssi_bridge.base.realtime import fifo_permitted, thread_policies
from ssi_bridge.base.udp_bus import derive_channel


def _without_fifo_rights() -> None:
    """preexec: no CAP_SYS_NICE after exec (root drops it from its bounding set), rtprio 0."""
    import ctypes
    import resource

    pr_capbset_drop, cap_sys_nice = 24, 23
    ctypes.CDLL(None).prctl(pr_capbset_drop, cap_sys_nice, 0, 0, 0)  # fails harmlessly: no root
    resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))


def _station(name: str, priority: int, preexec=None) -> subprocess.Popen:
    proc = subprocess.Popen(
        [sys.executable, "-m", "ssi_bridge.sim.program", "--interface", "udp_multicast",
         "--channel", derive_channel(f"rt_{name}_{os.getpid()}"), "--priority", str(priority)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=preexec)
    assert proc.stdout is not None
    line = proc.stdout.readline().decode()
    assert line.startswith("station ready"), (line, proc.stderr.read().decode()[-2000:])
    return proc


def _stop(proc: subprocess.Popen) -> str:
    proc.send_signal(signal.SIGTERM)
    _out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err.decode()[-2000:]
    return err.decode()


@pytest.mark.skipif(not fifo_permitted(7),
                    reason="SCHED_FIFO not permitted here (no CAP_SYS_NICE)")
def test_every_thread_of_a_station_runs_at_its_priority():
    proc = _station("fifo", 7)
    try:
        for _ in range(5):
            assert thread_policies(proc.pid) == {(os.SCHED_FIFO, 7)}, thread_policies(proc.pid)
    finally:
        _stop(proc)


def test_without_the_right_the_station_runs_normally_and_says_so_once():
    proc = _station("normal", 7, preexec=_without_fifo_rights)
    try:
        assert thread_policies(proc.pid) == {(os.SCHED_OTHER, 0)}
    finally:
        err = _stop(proc)
    assert err.count("SCHED_FIFO 7 not permitted") == 1, err


def test_priority_0_is_normal_scheduling_without_a_word():
    proc = _station("zero", 0)
    try:
        assert thread_policies(proc.pid) == {(os.SCHED_OTHER, 0)}
    finally:
        err = _stop(proc)
    assert "not permitted" not in err


def test_fifo_permitted_leaves_every_thread_as_it_was():
    before = thread_policies(os.getpid())
    fifo_permitted(7)
    assert thread_policies(os.getpid()) == before  # the probe thread has ended, nothing raised


def _in_a_thread(job):
    """``job()``'s result, run in a new thread at normal scheduling (the caller's thread
    is left as it is)."""
    import threading

    from ssi_bridge.base.realtime import normal_this_thread

    out = []

    def run() -> None:
        normal_this_thread()
        out.append(job())

    t = threading.Thread(target=run)
    t.start()
    t.join(5.0)
    return out[0]


def test_fifo_meanwhile_raises_the_thread_for_the_block_and_puts_it_back():
    from ssi_bridge.base.realtime import fifo_meanwhile, fifo_this_thread

    def policy() -> tuple[int, int]:
        return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority

    def raised_then_back() -> tuple:
        with fifo_meanwhile(4) as raised:
            inside = policy()
        return raised, inside, policy()

    permitted = fifo_permitted(4)
    raised, inside, after = _in_a_thread(raised_then_back)
    assert raised == permitted
    assert inside == ((os.SCHED_FIFO, 4) if permitted else (os.SCHED_OTHER, 0))
    assert after == (os.SCHED_OTHER, 0)

    def zero() -> tuple:
        with fifo_meanwhile(0) as raised:
            return raised, policy()

    assert _in_a_thread(zero) == (False, (os.SCHED_OTHER, 0))
    if not permitted:
        return

    def higher_already() -> tuple:
        fifo_this_thread(6)
        with fifo_meanwhile(4) as raised:
            inside = policy()
        return raised, inside, policy()

    # a thread at a higher FIFO priority already is neither lowered nor changed after
    assert _in_a_thread(higher_already) == (False, (os.SCHED_FIFO, 6), (os.SCHED_FIFO, 6))

    def higher_already_reset_on_fork() -> tuple:
        # sched(7): SCHED_RESET_ON_FORK is reported OR-ed into the policy
        flag = os.SCHED_RESET_ON_FORK
        os.sched_setscheduler(0, os.SCHED_FIFO | flag, os.sched_param(6))
        with fifo_meanwhile(4) as raised:
            inside = policy()
        return raised, inside, policy()

    flagged = os.SCHED_FIFO | os.SCHED_RESET_ON_FORK
    assert _in_a_thread(higher_already_reset_on_fork) == (False, (flagged, 6), (flagged, 6))
