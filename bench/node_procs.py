"""The node benchmark's processes: an isolated DDS domain, how each child is scheduled and
stopped, and the CPU time of a process tree.

Every process started here is stopped by its PID (:func:`stop`) and dies with the benchmark
(:func:`die_with_parent`): a killed run leaves nothing behind. The subscriber runs SCHED_FIFO
:data:`SUBSCRIBER_PRIORITY` (3, below the node's default ``cycle_priority`` 5), as the
real-time consumer of a robot (a ros2_control loop) would: a normally scheduled subscriber
that falls behind for tens of ms (starved by the node's and the station's real-time threads
waking 2-3 kHz) adds its own backlog to every publisher's latency. Where SCHED_FIFO is not
permitted it runs normally; :func:`subscriber_scheduling` says which, for the notes.
"""

from __future__ import annotations

import ctypes
import functools
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

from benchlib import cpu_seconds

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "test"))
from support.ros_process import dds_env  # noqa: E402  (the node tests' isolated DDS domain)

_prctl = ctypes.CDLL(None, use_errno=True).prctl  # resolved before any fork
PR_SET_PDEATHSIG = 1
#: the process that imported this module first: the benchmark (or a publisher it started)
_BENCH_PID = os.getpid()

#: SCHED_FIFO priority of the subscriber process (0: normal scheduling)
SUBSCRIBER_PRIORITY = 3


def domain_id() -> int:
    """A ROS_DOMAIN_ID for this run (1..100), drawn from the PID and the time."""
    return random.Random(os.getpid() * 104729 + time.time_ns()).randint(1, 100)


@functools.cache
def subscriber_scheduling() -> str:
    """How the subscriber is scheduled, for the notes."""
    from ssi_bridge.base.realtime import fifo_permitted

    if fifo_permitted(SUBSCRIBER_PRIORITY):
        return f"subscriber SCHED_FIFO {SUBSCRIBER_PRIORITY}"
    return "subscriber normally scheduled (SCHED_FIFO not permitted)"


def real_time_subscriber() -> None:
    """preexec_fn of the subscriber: as die_with_parent, then SCHED_FIFO (every thread
    rclpy starts inherits it), or normal scheduling where that is not permitted."""
    die_with_parent()
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(SUBSCRIBER_PRIORITY))
    except OSError:
        pass


def die_with_parent() -> None:
    """preexec_fn of every process started here: SIGKILLed when this benchmark dies (a killed
    run leaves no publisher behind); SIGINT back to default (a background job of a
    non-interactive shell starts with it ignored) so that stop's SIGINT is handled."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    _prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != _BENCH_PID:
        os._exit(1)  # the benchmark died before prctl took effect


def stop(proc: subprocess.Popen, timeout: float = 8.0) -> None:
    """SIGINT, then SIGKILL after ``timeout``; only this PID."""
    if proc.poll() is not None:
        return
    try:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)
    except ProcessLookupError:
        pass


def tail(path: Path, n: int = 1500) -> str:
    """The last ``n`` characters of a log file ("" where it cannot be read)."""
    try:
        return path.read_text(errors="replace")[-n:]
    except OSError:
        return ""


def burners(n: int) -> list[subprocess.Popen]:
    """``n`` CPU-burning processes (the caller kills them by PID)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"],
                             start_new_session=True) for _ in range(n)]


def descendants(pid: int) -> list[int]:
    """The PIDs of ``pid``'s child processes and theirs (the node's station child)."""
    found: list[int] = []
    todo = [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").glob("*/children"):
            try:
                kids = [int(k) for k in task.read_text().split()]
            except OSError:
                continue
            found += kids
            todo += kids
    return found


def cpu_of(pids: list[int]) -> float:
    """utime + stime (s) of ``pids`` together; a process that has ended counts 0."""
    total = 0.0
    for pid in pids:
        try:
            total += cpu_seconds(pid)
        except OSError:
            pass
    return total


__all__ = ["PR_SET_PDEATHSIG", "SUBSCRIBER_PRIORITY", "burners", "cpu_of", "dds_env",
           "descendants", "die_with_parent", "domain_id", "real_time_subscriber", "stop",
           "subscriber_scheduling", "tail"]
