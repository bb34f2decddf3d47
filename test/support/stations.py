"""The ``station`` program (the simulated station as a process of its own, as a real station
would be) started, awaited and stopped by a test, and the station child of a running node
found in /proc."""

from __future__ import annotations

import math

import signal
import subprocess
from pathlib import Path
from typing import Any

import yaml

from support.ros_process import installed_executable


def start_station(tmp_path: Path, params: dict, *extra: str) -> subprocess.Popen:
    """Start the installed ``station`` on ``params`` (written to ``tmp_path/station.yaml``);
    its stdout is a pipe, read by :func:`ready`."""
    pfile = tmp_path / "station.yaml"
    pfile.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return subprocess.Popen([str(installed_executable("station")), "--params-file", str(pfile), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)


def ready(proc: subprocess.Popen) -> str:
    """Wait for the station's ``station ready`` line and return it (fails the test on any
    other first line, with the station's stderr)."""
    line = proc.stdout.readline().decode()
    assert line.startswith("station ready"), (line, proc.stderr.read().decode()[-2000:])
    return line


def started_station(tmp_path: Path, params: dict, *args: str) -> subprocess.Popen:
    """The ``station`` program on ``params``, once it said it is ready."""
    proc = start_station(tmp_path, params, *args)
    ready(proc)
    return proc


def stop_station(proc: subprocess.Popen) -> None:
    """Stop the station as a user does (SIGINT), SIGKILL after 10 s."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def children(pid: int) -> list[int]:
    """Child processes of ``pid`` (forked by any of its threads)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


def station_of(node: Any) -> int:
    """The PID of the one station child of a running node (a ``NodeProcess``)."""
    kids = [k for k in children(node.proc.pid)
            if b"ssi_bridge.sim.program" in Path(f"/proc/{k}/cmdline").read_bytes()]
    assert len(kids) == 1, f"expected one station child of the node, got {kids}"
    return kids[0]


def gone(pid: int) -> bool:
    """True once ``pid`` has ended (a zombie waits only for its reaper)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return True
    return state in ("Z", "X")


def assert_own_motion(msgs: list, motion: dict[str, tuple[float, float]], step: float,
                      rate: float, elapsed: float) -> None:
    """The joints of several stations publish each its own station's motion.

    :param msgs: the JointState messages received, in order
    :param motion: per joint, in the configured order, (velocity in rev/s, start in rev)
    :param step: one count of the joints' encoders (rad)
    :param rate: the publish rate (Hz)
    :param elapsed: seconds since the simulated stations started (an upper bound)

    A message holding every joint is most of them (a joint whose sample was not latched at a
    stamp is left out of that message). Velocity: the constant shaft speed, bound as for one
    station (docs/node.md): one count over a window of at least 3.5 periods (a cycle less
    than half a period late runs at once, CycleThread) plus SYNC-stamp timing noise.
    Position: start + velocity x the time since the station started.
    """
    full = [m for m in msgs if list(m.name) == list(motion)]
    assert len(full) >= 0.8 * len(msgs), "the joints of both stations are published together"
    last = full[-1]
    for i, (joint, (velocity, start)) in enumerate(motion.items()):
        truth = 2 * math.pi * velocity
        bound = step / (3.5 / rate) + 0.01 * abs(truth)
        speeds = [m.velocity[i] for m in full[-30:]]
        worst = max(speeds, key=lambda v: abs(v - truth))
        assert abs(worst - truth) <= bound, (joint, truth, bound, worst, speeds)
        expected = 2 * math.pi * start
        assert abs(last.position[i] - expected) <= 2 * math.pi * abs(velocity) * elapsed + 0.01, \
            (joint, last.position[i], expected)
