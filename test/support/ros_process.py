"""A ROS process of the installed package, the plumbing without fixtures: where the installed
executables are, a running node process and its log, the environment of an isolated DDS
domain. test/ros/conftest.py builds its fixtures on these; helpers of several test modules
(:mod:`support.stations`, :mod:`support.lifecycle`) use them directly."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from ament_index_python.packages import PackageNotFoundError, get_package_prefix


def installed_executable(name: str) -> Path:
    """``lib/ssi_bridge/<name>`` of the ssi_bridge the environment has sourced, found the way
    ``ros2 run`` finds it (the ament index): this repository's install/ under `make test`,
    the workspace's install/ under `colcon test`."""
    try:
        prefix = Path(get_package_prefix("ssi_bridge"))
    except PackageNotFoundError:
        pytest.fail("ssi_bridge is not installed in the sourced environment: run `make setup` "
                    "and `source scripts/env.sh` (make test does both), or source a workspace's "
                    "install/setup.bash")
    exe = prefix / "lib" / "ssi_bridge" / name
    if not exe.exists():
        pytest.fail(f"{exe} missing: rebuild (make setup, or colcon build)")
    return exe


@dataclass
class NodeProcess:
    """A running ssi_bridge_node subprocess and the DDS domain it lives in."""

    proc: subprocess.Popen
    domain_id: int
    namespace: str
    log_path: Path
    name: str = "ssi_bridge"
    env: dict[str, str] = field(default_factory=dict)

    def topic(self, relative: str) -> str:
        """Resolve ``~/x`` and ``x`` the way the node does."""
        ns = self.namespace.rstrip("/")
        if relative.startswith("~/"):
            return f"{ns}/{self.name}/{relative[2:]}"
        if relative.startswith("/"):
            return relative
        return f"{ns}/{relative}"

    def log(self) -> str:
        """Everything the node printed so far."""
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def wait_for_log(self, text: str, timeout: float = 60.0) -> None:
        """Readiness from the node's own log (no DDS discovery needed): wait for ``text``."""
        deadline = time.monotonic() + timeout
        while text not in self.log():
            if self.proc.poll() is not None:
                pytest.fail(f"node exited {self.proc.returncode} before {text!r}:\n{self.log()}")
            if time.monotonic() > deadline:
                pytest.fail(f"no {text!r} within {timeout} s:\n{self.log()[-3000:]}")
            time.sleep(0.005)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        """Stop the process (SIGINT, then SIGKILL after ``timeout``); returns the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        return self.proc.returncode


def dds_env(domain_id: int) -> dict[str, str]:
    """The environment of an isolated DDS domain on this host."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)
    env["PYTHONUNBUFFERED"] = "1"
    return env
