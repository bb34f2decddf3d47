"""Real-time scheduling for the threads that keep the bus's time (Linux; ROS-free).

A bus master's cycle is a hard schedule: a SYNC that goes out late is a sample latched late,
and a TPDO handled late misses its cycle. On a busy robot computer a normally scheduled thread
waits behind whatever else is runnable, so, as a ros2_control hardware loop does, the node's
cycle thread and the master's receive thread ask for SCHED_FIFO, and the simulated station
(hardware, which never waits for a CPU) runs at a higher one. They are idle but for the
cycle's work, so they take little from anything else. Without the right to it (no
CAP_SYS_NICE, no rtprio limit) everything runs normally and the caller says so once.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import threading
from collections.abc import Iterator

#: prctl(2) option: name the calling thread (shown by top -H, ps -L, /proc/<pid>/task/*/comm)
PR_SET_NAME = 15
#: the kernel keeps 15 bytes of a thread name
THREAD_NAME_BYTES = 15
_LIBC = ctypes.CDLL(None, use_errno=True)
#: sched(7): a flag OR-ed into the policy sched_getscheduler reports
SCHED_RESET_ON_FORK = getattr(os, "SCHED_RESET_ON_FORK", 0x40000000)

logger = logging.getLogger(__name__)


def name_this_thread(name: str) -> None:
    """Give the calling thread its kernel name (Python 3.12 names only its own object)."""
    _LIBC.prctl(PR_SET_NAME, name.encode()[:THREAD_NAME_BYTES], 0, 0, 0)


def fifo_this_thread(priority: int) -> bool:
    """Put the calling thread on SCHED_FIFO ``priority`` (0: leave it); False when refused."""
    if priority <= 0:
        return True
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError:  # EPERM without the right, EINVAL outside the policy's range
        return False
    return True


def fifo_permitted(priority: int = 1) -> bool:
    """Whether this process may use SCHED_FIFO ``priority`` (CAP_SYS_NICE, or an rtprio limit
    that high), for itself or a child: tried in a short-lived thread, so no thread that goes
    on running changes its scheduling."""
    granted: list[bool] = []
    probe = threading.Thread(target=lambda: granted.append(fifo_this_thread(priority)),
                             name="fifo_probe")
    probe.start()
    probe.join()
    return bool(granted) and granted[0]


def _schedules(pid: int) -> dict[int, tuple[int, int]] | None:
    """Thread id -> (scheduling policy, priority) of every thread of process ``pid`` (None: no
    such process); a thread that ends while they are read is left out."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return None
    found = {}
    for task in tasks:
        tid = int(task)
        try:
            found[tid] = (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
        except OSError:
            pass  # that thread ended meanwhile
    return found


def thread_policies(pid: int) -> set[tuple[int, int]]:
    """(scheduling policy, priority) of every thread of process ``pid`` (empty: no such
    process)."""
    return set((_schedules(pid) or {}).values())


def run_this_thread_at(name: str, priority: int) -> tuple[str, bool]:
    """Name the calling thread and put it on SCHED_FIFO ``priority`` (0: normal scheduling).

    :param name: the thread's kernel name (what ``top -H`` shows)
    :returns: (its scheduling as :func:`scheduling_of_this_thread` says it, whether the
        request held)
    """
    name_this_thread(name)
    granted = fifo_this_thread(priority)
    return scheduling_of_this_thread(), granted


def normal_this_thread() -> None:
    """Put the calling thread back on normal scheduling: a thread started by a SCHED_FIFO one
    inherits its policy, which a slow clean-up job must not keep."""
    if os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


@contextlib.contextmanager
def fifo_meanwhile(priority: int) -> Iterator[bool]:
    """The calling thread on SCHED_FIFO ``priority`` for the ``with`` block, then back on the
    scheduling it had (yields whether it was raised: not for ``priority`` <= 0, a thread at
    that FIFO priority or higher already, or without the right to it).

    For a normally scheduled thread's short burst of work that a real-time thread may wait
    for (it holds Python's lock meanwhile): a busy machine does not preempt it midway.
    """
    if priority <= 0:
        yield False
        return
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    # the policy may carry SCHED_RESET_ON_FORK, which restoring it keeps
    if (policy & ~SCHED_RESET_ON_FORK) in (os.SCHED_FIFO, os.SCHED_RR) \
            and param.sched_priority >= priority:
        yield False
        return
    raised = fifo_this_thread(priority)
    try:
        yield raised
    finally:
        if raised:
            try:
                os.sched_setscheduler(0, policy, param)
            except OSError as err:  # a policy that cannot be set back (SCHED_DEADLINE)
                normal_this_thread()  # never left real-time by a short burst
                logger.warning("thread %s: its scheduling (policy %d) could not be set back "
                               "after a real-time burst (%s); it runs normally now",
                               threading.current_thread().name, policy, err)


def scheduling_of_this_thread() -> str:
    """The calling thread's policy and priority as a reader of diagnostics expects them."""
    policy = os.sched_getscheduler(0)
    if policy == os.SCHED_FIFO:
        return f"SCHED_FIFO {os.sched_getparam(0).sched_priority}"
    if policy == os.SCHED_RR:
        return f"SCHED_RR {os.sched_getparam(0).sched_priority}"
    return "normal"


def pin_process(cpus: tuple[int, ...]) -> None:
    """Pin every thread of this process (DDS, bus notifiers, cycle) to ``cpus``.

    ``sched_setaffinity(0)`` moves only the calling thread on Linux; threads started later
    inherit from their creator, so the existing ones are moved one by one.
    """
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setaffinity(int(tid), cpus)
        except (ProcessLookupError, PermissionError):
            pass  # a thread that just ended
