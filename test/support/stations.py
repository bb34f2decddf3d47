"""The ``station`` program (the simulated station as a process of its own, as a real station
would be) started, awaited and stopped by a test, and the station child of a running node
found in /proc."""

from __future__ import annotations

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
