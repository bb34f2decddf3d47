"""base/realtime.py: the station child is raised from outside while its threads start others."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from ssi_bridge.base.realtime import fifo_permitted, raise_priority, thread_policies

#: a process whose threads keep starting threads (as a booting station starts its timers and
#: listeners): each thread starts one successor and ends, so a thread that was normal when it
#: started its successor hands normal scheduling on unless the raise catches the successor too
SPAWNER = """
import threading, time
def chain():
    time.sleep(0.0002)
    threading.Thread(target=chain, daemon=True).start()
for _ in range(8):
    threading.Thread(target=chain, daemon=True).start()
print("up", flush=True)
time.sleep(60)
"""


@pytest.mark.skipif(not fifo_permitted(7),
                    reason="SCHED_FIFO not permitted here (no CAP_SYS_NICE)")
def test_raise_priority_reaches_threads_started_while_it_runs():
    for _ in range(20):
        proc = subprocess.Popen([sys.executable, "-c", SPAWNER], stdout=subprocess.PIPE)
        try:
            assert proc.stdout is not None and proc.stdout.readline() == b"up\n"
            assert raise_priority(proc.pid, 7)
            for _ in range(20):  # the chains go on: every thread they start stays FIFO 7
                assert thread_policies(proc.pid) == {(os.SCHED_FIFO, 7)}
                time.sleep(0.002)
        finally:
            proc.kill()
            proc.wait()


def _without_fifo_rights() -> None:
    """preexec: no CAP_SYS_NICE after exec (root drops it from its bounding set), rtprio 0."""
    import ctypes
    import resource

    pr_capbset_drop, cap_sys_nice = 24, 23
    ctypes.CDLL(None).prctl(pr_capbset_drop, cap_sys_nice, 0, 0, 0)  # fails harmlessly: no root
    resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))


def test_raise_priority_says_when_not_permitted():
    """Without the right, False (the node then logs its INFO line) and the process is untouched;
    fifo_permitted says so beforehand, and its probe leaves no thread of the caller raised."""
    script = ("import subprocess, os\n"
              "from ssi_bridge.base.realtime import fifo_permitted, raise_priority, "
              "thread_policies\n"
              "p = subprocess.Popen(['sleep', '30'])\n"
              "print(raise_priority(p.pid, 7), os.sched_getscheduler(p.pid) == os.SCHED_OTHER,\n"
              "      fifo_permitted(7), thread_policies(os.getpid()) == {(os.SCHED_OTHER, 0)})\n"
              "p.kill()\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         preexec_fn=_without_fifo_rights, timeout=30)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "True", "False", "True"]


def test_fifo_permitted_leaves_every_thread_as_it_was():
    before = thread_policies(os.getpid())
    fifo_permitted(7)
    assert thread_policies(os.getpid()) == before  # the probe thread has ended, nothing raised
